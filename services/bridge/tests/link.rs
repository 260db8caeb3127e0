//! Two bridges on one machine, each over its own iceoryx2 domain (nothing shared but a Zenoh
//! link on loopback): messages cross both ways; a participant without the credentials gets
//! nothing and puts nothing into the run; garbage from the link is refused; a bridge started
//! before the other, or killed and restarted, connects when it can.
#![cfg(feature = "zenoh")]

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use opengs_ipc_schema::service::{RENDERS, SEGMENTS};
use opengs_ipc_schema::{
    now_ns, to_wire, LabelCompleteness, MessageKind, RenderHeader, SegmentLabel, SegmentsHeader,
    Stamp,
};
use opengs_runtime::iceoryx2::prelude::Node;
use opengs_runtime::{Inlet, Ipc, Outlet, RunContext};
use zenoh::Wait;

struct Bridge(Child);

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn bridge(run_id: &str, args: &[&str], log: &Path) -> Bridge {
    let log = std::fs::File::create(log).expect("log");
    Bridge(
        Command::new(env!("CARGO_BIN_EXE_opengs-bridge"))
            .args(["--run-id", run_id, "--link", "shared-run"])
            .args(args)
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("log"))
            .stderr(log)
            .spawn()
            .expect("bridge starts"),
    )
}

/// This test's own ends of the two hosts' services: a node in each iceoryx2 domain.
struct Hosts {
    ctx_a: RunContext,
    ctx_b: RunContext,
    node_a: Node<Ipc>,
    node_b: Node<Ipc>,
}

impl Hosts {
    fn new(run_a: &str, run_b: &str) -> Self {
        let ctx_a = RunContext::new(run_a).expect("ctx a");
        let ctx_b = RunContext::new(run_b).expect("ctx b");
        Self {
            node_a: ctx_a.node("test_a").expect("node a"),
            node_b: ctx_b.node("test_b").expect("node b"),
            ctx_a,
            ctx_b,
        }
    }

    /// A publisher of segmentations on A and a subscriber on B.
    fn segments_a_to_b(&self) -> (Outlet<SegmentsHeader>, Inlet<SegmentsHeader>) {
        (
            Outlet::new(&self.ctx_a, &self.node_a, &SEGMENTS, 4096).expect("out"),
            Inlet::new(&self.ctx_b, &self.node_b, &SEGMENTS).expect("in"),
        )
    }
}

/// A port free now (the kernel's choice), for a bridge to listen on.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

fn send_segments(out: &Outlet<SegmentsHeader>, seq: u64) {
    let labels = [SegmentLabel::new(3, 0.9, Some("chair"), 0.7)];
    let map = vec![3u32; 8 * 6];
    let h = SegmentsHeader::new(
        Stamp::new(MessageKind::Segments, seq, 0, now_ns()),
        8,
        6,
        1,
        0,
    );
    out.send(h, |h, buf| h.encode(&map, &labels, buf))
        .expect("send");
}

fn send_render(out: &Outlet<RenderHeader>, seq: u64) {
    let labels = [LabelCompleteness {
        label: 3,
        visible: 4,
        total: 5,
    }];
    let map = vec![3u32; 8 * 6];
    let h = RenderHeader::new(Stamp::new(MessageKind::Render, seq, 0, now_ns()), 8, 6, 1);
    out.send(h, |h, buf| h.encode(&map, &labels, buf))
        .expect("send");
}

/// Seqs that reach `inlet` while `send(seq)` goes on for `for_at_most` (or until `enough`).
fn carried(
    mut send: impl FnMut(u64),
    receive: impl Fn() -> Vec<u64>,
    for_at_most: Duration,
    enough: usize,
) -> Vec<u64> {
    let started = Instant::now();
    let mut got = Vec::new();
    let mut seq = 0;
    while started.elapsed() < for_at_most && got.len() < enough {
        send(seq);
        seq += 1;
        std::thread::sleep(Duration::from_millis(50));
        got.extend(receive());
    }
    got
}

fn drain<H: std::fmt::Debug + opengs_runtime::iceoryx2::prelude::ZeroCopySend + 'static>(
    inlet: &Inlet<H>,
    seq: impl Fn(&H) -> u64,
) -> Vec<u64> {
    let mut out = Vec::new();
    while let Ok(Some(s)) = inlet.receive() {
        out.push(seq(s.user_header()));
    }
    out
}

/// Subscribes each of `sessions` to the run's segmentations; the channel gets one `()` per
/// segmentation any of them receives (keep the subscribers).
fn listen_to_segments(
    sessions: &[&zenoh::Session],
) -> (
    std::sync::mpsc::Receiver<()>,
    Vec<zenoh::pubsub::Subscriber<()>>,
) {
    let (tx, rx) = std::sync::mpsc::channel();
    let subs = sessions
        .iter()
        .map(|s| {
            let tx = tx.clone();
            s.declare_subscriber("opengs/shared-run/segments")
                .callback(move |_| {
                    let _ = tx.send(());
                })
                .wait()
                .expect("subscriber")
        })
        .collect();
    (rx, subs)
}

/// A Zenoh participant of its own, connecting to `endpoint` with `login` (or none).
fn intruder(endpoint: &str, login: Option<(&str, &str)>) -> zenoh::Session {
    let mut config = serde_json::json!({
        "mode": "peer",
        "connect": { "endpoints": [endpoint] },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    if let Some((user, password)) = login {
        config["transport"] =
            serde_json::json!({ "auth": { "usrpwd": { "user": user, "password": password } } });
    }
    let config = zenoh::Config::from_json5(&config.to_string()).expect("config");
    zenoh::open(config)
        .wait()
        .expect("a session opens, connected or not")
}

#[test]
fn only_credentialed_hosts_exchange_messages_and_the_link_survives_a_restart() {
    let dir = tempfile::tempdir().expect("tmp");
    let creds = dir.path().join("credentials.txt");
    std::fs::write(&creds, "hostb:right-password\n").expect("creds");
    let pw = dir.path().join("pw");
    std::fs::write(&pw, "right-password\n").expect("pw");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (run_a, run_b) = (
        format!("ta{}", std::process::id()),
        format!("tb{}", std::process::id()),
    );
    // Host A sends segmentations and takes renders; host B the other way round. B starts
    // first: it keeps trying until A listens.
    let b_args = [
        "--import",
        "segments",
        "--export",
        "renders",
        "--connect",
        &endpoint,
        "--user",
        "hostb",
        "--password-file",
        pw.to_str().expect("utf-8"),
    ];
    let b = bridge(&run_b, &b_args, &dir.path().join("b.log"));
    std::thread::sleep(Duration::from_millis(700));
    let _a = bridge(
        &run_a,
        &[
            "--export",
            "segments",
            "--import",
            "renders",
            "--listen",
            &endpoint,
            "--credentials",
            creds.to_str().expect("utf-8"),
        ],
        &dir.path().join("a.log"),
    );

    let hosts = Hosts::new(&run_a, &run_b);
    let (seg_out, seg_in) = hosts.segments_a_to_b();
    let ren_out =
        Outlet::<RenderHeader>::new(&hosts.ctx_b, &hosts.node_b, &RENDERS, 4096).expect("out");
    let ren_in = Inlet::<RenderHeader>::new(&hosts.ctx_a, &hosts.node_a, &RENDERS).expect("in");
    let seg_seq = |h: &SegmentsHeader| h.stamp.seq;
    let ren_seq = |h: &RenderHeader| h.stamp.seq;

    // A → B and B → A, each message validated and published on the other domain.
    let got = carried(
        |s| send_segments(&seg_out, s),
        || drain(&seg_in, seg_seq),
        Duration::from_secs(20),
        5,
    );
    let logs = || {
        ["a.log", "b.log"].map(|f| std::fs::read_to_string(dir.path().join(f)).unwrap_or_default())
    };
    assert!(
        got.len() >= 5,
        "segments A → B: {got:?}; logs: {:?}",
        logs()
    );
    assert!(got.windows(2).all(|w| w[0] < w[1]), "in order: {got:?}");
    let got = carried(
        |s| send_render(&ren_out, s),
        || drain(&ren_in, ren_seq),
        Duration::from_secs(20),
        5,
    );
    assert!(got.len() >= 5, "renders B → A: {got:?}");

    // Wrong password, no password: they cannot subscribe to the run's segmentations ...
    let wrong = intruder(&endpoint, Some(("hostb", "guess")));
    let none = intruder(&endpoint, None);
    let (rx, _subs) = listen_to_segments(&[&wrong, &none]);
    // ... nor put renders into it, valid ones included.
    let mut render = Vec::new();
    {
        let labels = [LabelCompleteness {
            label: 1,
            visible: 1,
            total: 1,
        }];
        let map = vec![1u32; 8 * 6];
        let h = RenderHeader::new(Stamp::new(MessageKind::Render, 9999, 0, now_ns()), 8, 6, 1);
        let mut payload = vec![0u8; h.payload_len()];
        h.encode(
            &map,
            &labels,
            opengs_ipc_schema::as_uninit_mut(&mut payload),
        )
        .expect("encode");
        render.extend(to_wire(&h, &payload));
    }
    let started = Instant::now();
    let mut seq = 1000;
    while started.elapsed() < Duration::from_secs(3) {
        send_segments(&seg_out, seq);
        seq += 1;
        for s in [&wrong, &none] {
            s.put("opengs/shared-run/renders", render.clone())
                .wait()
                .expect("put");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        rx.try_recv().is_err(),
        "an outsider received the run's segmentations"
    );
    let sneaked = drain(&ren_in, ren_seq);
    assert!(
        !sneaked.contains(&9999),
        "an outsider's render got into the run"
    );
    // B (with the credentials) still gets them.
    assert!(!drain(&seg_in, seg_seq).is_empty());

    // Garbage from a credentialed peer is refused at the bridge, never published.
    let insider = intruder(&endpoint, Some(("hostb", "right-password")));
    std::thread::sleep(Duration::from_secs(1));
    let mut bad = render.clone();
    bad.truncate(bad.len() - 8);
    insider
        .put("opengs/shared-run/renders", bad)
        .wait()
        .expect("put");
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        drain(&ren_in, ren_seq).is_empty(),
        "a truncated render was published"
    );
    let log_a = std::fs::read_to_string(dir.path().join("a.log")).expect("a log");
    assert!(
        log_a.contains("renders from the link rejected"),
        "A says what it refused: {log_a}"
    );
    drop(insider);

    // B's bridge dies and comes back: the link resumes.
    drop(b);
    let _b = bridge(&run_b, &b_args, &dir.path().join("b2.log"));
    drain(&seg_in, seg_seq);
    let got = carried(
        |s| send_segments(&seg_out, 5000 + s),
        || drain(&seg_in, seg_seq),
        Duration::from_secs(20),
        3,
    );
    assert!(got.len() >= 3, "segments after B's restart: {got:?}");
}

/// `openssl` makes a CA and certificates signed by it (for localhost / 127.0.0.1); `None`
/// when there is no `openssl` on this machine.
fn certificates(dir: &Path, ca: &str, names: &[&str]) -> Option<()> {
    let openssl = |args: &[&str]| {
        Command::new("openssl")
            .args(args)
            .current_dir(dir)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .ok()
            .filter(|s| s.success())
    };
    let ec = [
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
    ];
    let (ca_pem, ca_key) = (format!("{ca}.pem"), format!("{ca}.key"));
    openssl(
        &[
            &["req", "-x509"][..],
            &ec,
            &["-keyout", &ca_key, "-out", &ca_pem, "-days", "2"],
            &[
                "-subj",
                "/CN=opengs test CA",
                "-addext",
                "basicConstraints=critical,CA:TRUE",
                "-addext",
                "keyUsage=critical,keyCertSign",
            ],
        ]
        .concat(),
    )?;
    let ext = dir.join("leaf.ext");
    std::fs::write(
        &ext,
        "basicConstraints=CA:FALSE\nkeyUsage=digitalSignature\n\
         extendedKeyUsage=serverAuth,clientAuth\nsubjectAltName=DNS:localhost,IP:127.0.0.1\n",
    )
    .ok()?;
    for name in names {
        let (key, csr, pem) = (
            format!("{name}.key"),
            format!("{name}.csr"),
            format!("{name}.pem"),
        );
        openssl(
            &[
                &["req"][..],
                &ec,
                &["-keyout", &key, "-out", &csr, "-subj", "/CN=localhost"],
            ]
            .concat(),
        )?;
        openssl(&[
            "x509",
            "-req",
            "-in",
            &csr,
            "-CA",
            &ca_pem,
            "-CAkey",
            &ca_key,
            "-CAcreateserial",
            "-out",
            &pem,
            "-days",
            "2",
            "-extfile",
            ext.to_str()?,
        ])?;
    }
    Some(())
}

/// A participant connecting over TLS, trusting `ca`, showing `identity` (cert, key) if any.
fn tls_intruder(endpoint: &str, ca: &Path, identity: Option<(&Path, &Path)>) -> zenoh::Session {
    let mut tls = serde_json::json!({ "root_ca_certificate": ca.display().to_string() });
    if let Some((cert, key)) = identity {
        tls["enable_mtls"] = true.into();
        tls["connect_certificate"] = cert.display().to_string().into();
        tls["connect_private_key"] = key.display().to_string().into();
    }
    let config = serde_json::json!({
        "mode": "peer",
        "connect": { "endpoints": [endpoint] },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
        "transport": { "link": { "tls": tls } },
    });
    let config = zenoh::Config::from_json5(&config.to_string()).expect("config");
    zenoh::open(config)
        .wait()
        .expect("a session opens, connected or not")
}

#[test]
fn over_tls_only_hosts_with_a_certificate_of_the_run_get_in() {
    let dir = tempfile::tempdir().expect("tmp");
    if certificates(dir.path(), "ca", &["a", "b"]).is_none()
        || certificates(dir.path(), "other_ca", &["stranger"]).is_none()
    {
        eprintln!("skipped: no openssl to make test certificates");
        return;
    }
    let f = |n: &str| dir.path().join(n);
    let s = |n: &str| f(n).display().to_string();
    let port = free_port();
    let endpoint = format!("tls/127.0.0.1:{port}");
    let (run_a, run_b) = (
        format!("la{}", std::process::id()),
        format!("lb{}", std::process::id()),
    );
    let _a = bridge(
        &run_a,
        &[
            "--export",
            "segments",
            "--listen",
            &endpoint,
            "--tls-ca",
            &s("ca.pem"),
            "--tls-cert",
            &s("a.pem"),
            "--tls-key",
            &s("a.key"),
            "--tls-mutual",
        ],
        &f("a.log"),
    );
    let _b = bridge(
        &run_b,
        &[
            "--import",
            "segments",
            "--connect",
            &endpoint,
            "--tls-ca",
            &s("ca.pem"),
            "--tls-cert",
            &s("b.pem"),
            "--tls-key",
            &s("b.key"),
            "--tls-mutual",
        ],
        &f("b.log"),
    );
    let hosts = Hosts::new(&run_a, &run_b);
    let (seg_out, seg_in) = hosts.segments_a_to_b();
    let seg_seq = |h: &SegmentsHeader| h.stamp.seq;
    let got = carried(
        |q| send_segments(&seg_out, q),
        || drain(&seg_in, seg_seq),
        Duration::from_secs(20),
        5,
    );
    let logs = || ["a.log", "b.log"].map(|n| std::fs::read_to_string(f(n)).unwrap_or_default());
    assert!(
        got.len() >= 5,
        "segments over TLS: {got:?}; logs {:?}",
        logs()
    );

    // Plain TCP to the TLS port, a certificate from another authority, no certificate at all.
    let plain = intruder(&format!("tcp/127.0.0.1:{port}"), None);
    let stranger = tls_intruder(
        &endpoint,
        &f("ca.pem"),
        Some((&f("stranger.pem"), &f("stranger.key"))),
    );
    let anonymous = tls_intruder(&endpoint, &f("ca.pem"), None);
    let (rx, _subs) = listen_to_segments(&[&plain, &stranger, &anonymous]);
    let started = Instant::now();
    let mut seq = 1000;
    while started.elapsed() < Duration::from_secs(3) {
        send_segments(&seg_out, seq);
        seq += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        rx.try_recv().is_err(),
        "a participant without a certificate of the run got in"
    );
    assert!(
        !drain(&seg_in, seg_seq).is_empty(),
        "b, with its certificate, still receives"
    );
}
