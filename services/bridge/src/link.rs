//! What a bridge carries and how its Zenoh session is set up, checked before anything opens:
//! which services go out (`--export`, from this host's iceoryx2 to Zenoh) and which come in
//! (`--import`), the key of each (`opengs/<link>/<service>`: the run id both hosts were
//! given), where the session listens and connects, and who may join.
//!
//! Nobody else gets in: the session listens only on the endpoints given (loopback when none
//! is), multicast and gossip scouting are off (a peer joins only by connecting to a named
//! endpoint), and with `--credentials` only the users listed there may connect (Zenoh's
//! user-password authentication); listening beyond loopback without it is refused.

use std::path::PathBuf;

use opengs_ipc_schema::service;
use opengs_ipc_schema::ServiceSpec;

/// Options of the bridge stage.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct LinkArgs {
    /// The run id the hosts share: keys are `opengs/<LINK>/<service>` (default: this host's
    /// `--run-id`).
    #[arg(long)]
    pub link: Option<String>,
    /// A service to send from this host to the others (repeatable): frames, poses, keyframes,
    /// segments, renders, consensus, map_target, telemetry.
    #[arg(long, value_parser = service_names())]
    pub export: Vec<String>,
    /// A service to take from the other hosts and publish here (repeatable; same names).
    #[arg(long, value_parser = service_names())]
    pub import: Vec<String>,
    /// Zenoh endpoint to listen on (repeatable), e.g. tcp/127.0.0.1:7447. Default: that one
    /// when nothing is to be connected to; none otherwise.
    #[arg(long)]
    pub listen: Vec<String>,
    /// Zenoh endpoint of another host's bridge to connect to (repeatable), e.g.
    /// tcp/10.0.0.2:7447. Retried until it answers, and again whenever the link drops.
    #[arg(long)]
    pub connect: Vec<String>,
    /// User name this bridge presents to the bridges it connects to.
    #[arg(long, requires = "password_file")]
    pub user: Option<String>,
    /// File holding this bridge's password (first line).
    #[arg(long, requires = "user")]
    pub password_file: Option<PathBuf>,
    /// Who may connect to this bridge: a file of `user:password` lines (Zenoh's dictionary
    /// file). Required to listen beyond loopback.
    #[arg(long)]
    pub credentials: Option<PathBuf>,
    /// Report ready only once another host subscribes to every exported service, so the run
    /// starts when the other side is there (on the main host: its first keyframes would
    /// otherwise go nowhere). The stage's `startup_timeout_s` bounds the wait.
    #[arg(long)]
    pub wait_for_peer: bool,
    /// TLS (for `tls/HOST:PORT` endpoints: the link encrypted): the certificate of the
    /// authority that signed the other side's certificate.
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
    /// TLS: this bridge's certificate (PEM), signed by an authority the other side trusts;
    /// required to listen on a tls/ endpoint.
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// TLS: the private key of --tls-cert (PEM).
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// TLS: both sides show a certificate signed by an authority the other trusts (mutual
    /// TLS; give it to the bridges at both ends, each with --tls-cert and --tls-key); enough,
    /// without --credentials, to listen beyond loopback.
    #[arg(long, requires = "tls_cert")]
    pub tls_mutual: bool,
}

/// The services a bridge can carry (the control services stay on their host).
pub const BRIDGEABLE: [ServiceSpec; 8] = [
    service::FRAMES,
    service::POSES,
    service::KEYFRAMES,
    service::SEGMENTS,
    service::RENDERS,
    service::CONSENSUS,
    service::MAP_TARGET,
    service::TELEMETRY,
];

fn service_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(BRIDGEABLE.map(|s| s.name))
}

/// The endpoint a bridge listens on when none is given.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// The checked plan of one bridge.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    pub key_prefix: String,
    pub export: Vec<ServiceSpec>,
    pub import: Vec<ServiceSpec>,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    /// (user, password) presented when connecting.
    pub login: Option<(String, String)>,
    pub credentials: Option<PathBuf>,
    pub wait_for_peer: bool,
    pub tls: Option<Tls>,
}

/// The TLS side of a link (files checked to exist).
#[derive(Debug, Clone, PartialEq)]
pub struct Tls {
    pub ca: PathBuf,
    /// This side's certificate and key.
    pub identity: Option<(PathBuf, PathBuf)>,
    pub mutual: bool,
}

impl Link {
    /// Checks `args` for the bridge of the local run `run_id`.
    pub fn plan(run_id: &str, args: &LinkArgs) -> Result<Self, String> {
        let link = args.link.as_deref().unwrap_or(run_id);
        if link.is_empty()
            || !link
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(format!(
                "--link '{link}': a run id of letters, digits, '-' and '_'"
            ));
        }
        let spec = |name: &String| {
            BRIDGEABLE
                .iter()
                .find(|s| s.name == name)
                .copied()
                .ok_or_else(|| format!("'{name}' is not a service a bridge carries"))
        };
        let export = args
            .export
            .iter()
            .map(spec)
            .collect::<Result<Vec<_>, _>>()?;
        let import = args
            .import
            .iter()
            .map(spec)
            .collect::<Result<Vec<_>, _>>()?;
        if export.is_empty() && import.is_empty() {
            return Err("nothing to carry: give --export or --import SERVICE".into());
        }
        if let Some(both) = export.iter().find(|s| import.contains(s)) {
            return Err(format!(
                "'{}' both exported and imported: it would come back to where it left",
                both.name
            ));
        }
        let mut listen = args.listen.clone();
        if listen.is_empty() && args.connect.is_empty() {
            listen.push(DEFAULT_LISTEN.to_string());
        }
        for e in listen.iter().chain(&args.connect) {
            check_endpoint(e)?;
        }
        let tls = Self::plan_tls(args, &listen)?;
        if let Some(open) = listen.iter().find(|e| !is_loopback(e)) {
            if args.credentials.is_none() && !args.tls_mutual {
                return Err(format!(
                    "--listen {open} is reachable from other machines: give --credentials \
                     FILE (user:password lines) or --tls-mutual to say who may connect"
                ));
            }
        }
        let login = match (&args.user, &args.password_file) {
            (Some(user), Some(file)) => {
                let text = std::fs::read_to_string(file)
                    .map_err(|e| format!("--password-file {}: {e}", file.display()))?;
                let password = text.lines().next().unwrap_or("").trim().to_string();
                if password.is_empty() {
                    return Err(format!("--password-file {}: empty", file.display()));
                }
                Some((user.clone(), password))
            }
            _ => None,
        };
        if let Some(file) = &args.credentials {
            let text = std::fs::read_to_string(file)
                .map_err(|e| format!("--credentials {}: {e}", file.display()))?;
            if !text.lines().any(|l| l.split_once(':').is_some()) {
                return Err(format!(
                    "--credentials {}: no `user:password` line",
                    file.display()
                ));
            }
        }
        Ok(Self {
            key_prefix: format!("opengs/{link}"),
            export,
            import,
            listen,
            connect: args.connect.clone(),
            login,
            credentials: args.credentials.clone(),
            wait_for_peer: args.wait_for_peer,
            tls,
        })
    }

    /// The TLS files, checked against the endpoints that need them.
    fn plan_tls(args: &LinkArgs, listen: &[String]) -> Result<Option<Tls>, String> {
        let is_tls = |e: &String| e.starts_with("tls/");
        let uses_tls = listen.iter().chain(&args.connect).any(is_tls);
        let given = args.tls_ca.is_some() || args.tls_cert.is_some() || args.tls_mutual;
        if !uses_tls {
            return match given {
                true => Err("--tls-*: no tls/ endpoint to use them on".into()),
                false => Ok(None),
            };
        }
        let ca = args
            .tls_ca
            .clone()
            .ok_or("a tls/ endpoint needs --tls-ca FILE (who signed the other side)")?;
        let identity = args.tls_cert.clone().zip(args.tls_key.clone());
        if listen.iter().any(is_tls) && identity.is_none() {
            return Err("listening on a tls/ endpoint needs --tls-cert and --tls-key".into());
        }
        let files = std::iter::once(&ca).chain(identity.iter().flat_map(|(c, k)| [c, k]));
        for f in files {
            if !f.is_file() {
                return Err(format!("{}: no such file", f.display()));
            }
        }
        Ok(Some(Tls {
            ca,
            identity,
            mutual: args.tls_mutual,
        }))
    }

    /// The Zenoh key of `service` on this link.
    pub fn key(&self, service: &ServiceSpec) -> String {
        format!("{}/{}", self.key_prefix, service.name)
    }

    /// The Zenoh session configuration (JSON5, which JSON is).
    pub fn zenoh_config(&self) -> serde_json::Value {
        let mut config = serde_json::json!({
            "mode": "peer",
            "listen": { "endpoints": self.listen },
            "connect": {
                "endpoints": self.connect,
                // Keep trying (-1: no time limit): the other host may start later.
                "timeout_ms": -1,
                "exit_on_failure": false,
                "retry": { "period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2 },
            },
            "scouting": {
                "multicast": { "enabled": false },
                "gossip": { "enabled": false },
            },
        });
        let mut usrpwd = serde_json::Map::new();
        if let Some((user, password)) = &self.login {
            usrpwd.insert("user".into(), user.clone().into());
            usrpwd.insert("password".into(), password.clone().into());
        }
        if let Some(file) = &self.credentials {
            usrpwd.insert("dictionary_file".into(), file.display().to_string().into());
        }
        if !usrpwd.is_empty() {
            config["transport"]["auth"] = serde_json::json!({ "usrpwd": usrpwd });
        }
        if let Some(tls) = &self.tls {
            let path = |p: &PathBuf| serde_json::Value::from(p.display().to_string());
            let mut t = serde_json::json!({
                "root_ca_certificate": path(&tls.ca),
                "enable_mtls": tls.mutual,
            });
            if let Some((cert, key)) = &tls.identity {
                for side in ["listen", "connect"] {
                    t[format!("{side}_certificate")] = path(cert);
                    t[format!("{side}_private_key")] = path(key);
                }
            }
            config["transport"]["link"] = serde_json::json!({ "tls": t });
        }
        config
    }
}

/// `tcp/HOST:PORT` (or `tls/`, `udp/`, `quic/`): what Zenoh can parse, checked here so the
/// error names the flag.
fn check_endpoint(e: &str) -> Result<(), String> {
    let (proto, addr) = e.split_once('/').ok_or_else(|| {
        format!("endpoint '{e}': expected PROTOCOL/HOST:PORT, e.g. {DEFAULT_LISTEN}")
    })?;
    if !["tcp", "tls", "udp", "quic"].contains(&proto) {
        return Err(format!(
            "endpoint '{e}': protocol '{proto}' (tcp, tls, udp or quic)"
        ));
    }
    let port = addr.rsplit_once(':').map(|(_, p)| p);
    if port.is_none_or(|p| p.parse::<u16>().is_err()) {
        return Err(format!("endpoint '{e}': no port"));
    }
    Ok(())
}

fn is_loopback(e: &str) -> bool {
    let addr = e.split_once('/').map_or(e, |(_, a)| a);
    let host = addr.rsplit_once(':').map_or(addr, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(export: &[&str], import: &[&str]) -> LinkArgs {
        LinkArgs {
            export: export.iter().map(|s| s.to_string()).collect(),
            import: import.iter().map(|s| s.to_string()).collect(),
            ..LinkArgs::default()
        }
    }

    #[test]
    fn by_default_a_bridge_listens_on_loopback_only_and_never_scouts() {
        let link = Link::plan("run1", &args(&["keyframes", "renders"], &["segments"])).unwrap();
        assert_eq!(link.listen, [DEFAULT_LISTEN]);
        assert_eq!(link.key(&service::KEYFRAMES), "opengs/run1/keyframes");
        let c = link.zenoh_config();
        assert_eq!(c["scouting"]["multicast"]["enabled"], false);
        assert_eq!(c["scouting"]["gossip"]["enabled"], false);
        assert_eq!(c["listen"]["endpoints"][0], DEFAULT_LISTEN);
        assert!(c.get("transport").is_none(), "no credentials asked for");
    }

    #[test]
    fn listening_beyond_loopback_needs_credentials() {
        let mut a = args(&["keyframes"], &[]);
        a.listen = vec!["tcp/0.0.0.0:7447".into()];
        let err = Link::plan("r", &a).unwrap_err();
        assert!(err.contains("reachable from other machines"), "{err}");
        for ok in ["tcp/127.0.0.1:7447", "tcp/[::1]:7447", "tcp/localhost:9000"] {
            a.listen = vec![ok.into()];
            assert!(Link::plan("r", &a).is_ok(), "{ok}");
        }
        let dir = tempfile::tempdir().unwrap();
        let creds = dir.path().join("credentials.txt");
        std::fs::write(&creds, "hostb:s3cret\n").unwrap();
        a.listen = vec!["tcp/0.0.0.0:7447".into()];
        a.credentials = Some(creds.clone());
        let link = Link::plan("r", &a).unwrap();
        let c = link.zenoh_config();
        assert_eq!(
            c["transport"]["auth"]["usrpwd"]["dictionary_file"],
            creds.display().to_string()
        );
    }

    #[test]
    fn the_login_comes_from_a_file_and_goes_into_the_session() {
        let dir = tempfile::tempdir().unwrap();
        let pw = dir.path().join("pw");
        std::fs::write(&pw, "s3cret\nignored\n").unwrap();
        let mut a = args(&[], &["keyframes"]);
        a.connect = vec!["tcp/10.0.0.2:7447".into()];
        a.user = Some("hostb".into());
        a.password_file = Some(pw.clone());
        let link = Link::plan("r", &a).unwrap();
        assert!(
            link.listen.is_empty(),
            "a connecting bridge listens nowhere unless asked"
        );
        let c = link.zenoh_config();
        assert_eq!(c["transport"]["auth"]["usrpwd"]["user"], "hostb");
        assert_eq!(c["transport"]["auth"]["usrpwd"]["password"], "s3cret");
        std::fs::write(&pw, "\n").unwrap();
        assert!(Link::plan("r", &a).unwrap_err().contains("empty"));
    }

    #[test]
    fn tls_needs_its_files_and_goes_into_the_session() {
        let dir = tempfile::tempdir().unwrap();
        let file = |n: &str| {
            let p = dir.path().join(n);
            std::fs::write(&p, "PEM").unwrap();
            p
        };
        let (ca, cert, key) = (file("ca.pem"), file("a.pem"), file("a.key"));
        let mut a = args(&["segments"], &[]);
        a.listen = vec!["tls/0.0.0.0:7447".into()];
        let refused = |a: &LinkArgs| Link::plan("r", a).unwrap_err();
        assert!(refused(&a).contains("needs --tls-ca"));
        a.tls_ca = Some(ca.clone());
        assert!(refused(&a).contains("needs --tls-cert and --tls-key"));
        a.tls_cert = Some(cert.clone());
        a.tls_key = Some(dir.path().join("missing.key"));
        assert!(refused(&a).contains("missing.key: no such file"));
        a.tls_key = Some(key.clone());
        // Beyond loopback: client certificates (or credentials) say who may connect.
        assert!(refused(&a).contains("reachable from other machines"));
        a.tls_mutual = true;
        let c = Link::plan("r", &a).unwrap().zenoh_config();
        let tls = &c["transport"]["link"]["tls"];
        assert_eq!(tls["root_ca_certificate"], ca.display().to_string());
        assert_eq!(tls["listen_certificate"], cert.display().to_string());
        assert_eq!(tls["connect_private_key"], key.display().to_string());
        assert_eq!(tls["enable_mtls"], true);
        // TLS options with no tls/ endpoint are a mistake, not ignored.
        let mut plain = args(&["segments"], &[]);
        plain.tls_ca = Some(ca);
        assert!(refused(&plain).contains("no tls/ endpoint"));
    }

    #[test]
    fn impossible_plans_are_refused_with_the_reason() {
        let refused = |a: LinkArgs| Link::plan("r", &a).unwrap_err();
        assert!(refused(args(&[], &[])).contains("nothing to carry"));
        assert!(refused(args(&["segments"], &["segments"])).contains("both exported and imported"));
        let mut a = args(&["frames"], &[]);
        a.listen = vec!["127.0.0.1:7447".into()];
        assert!(refused(a.clone()).contains("expected PROTOCOL/HOST:PORT"));
        a.listen = vec!["tcp/127.0.0.1".into()];
        assert!(refused(a.clone()).contains("no port"));
        a.listen = vec!["http/127.0.0.1:80".into()];
        assert!(refused(a.clone()).contains("protocol 'http'"));
        a.listen = vec![];
        a.link = Some("a/b".into());
        assert!(refused(a).contains("--link 'a/b'"));
    }
}
