//! The optional Rerun viewer stage of `opengs run` (`opengs-viewer`, crate services/viewer):
//! its command-line flags (`--rerun FILE.rrd`, `--rerun-connect ADDR`), which the run flattens
//! into its own and hands on to the stage unchanged; the check, before anything starts, that
//! the binary was built (it is behind the `opengs-viewer/rerun` cargo feature); and the stage
//! the supervisor starts beside the deploy file's when a flag is given. The viewer is a sink:
//! optional, never restarted, niced onto idle CPU time, so its failure never stops or slows
//! the pipeline.

use std::path::{Path, PathBuf};

use crate::deploy::{stage_names, DeployFile, Scheduler, StageRole, StageSpec};

/// The viewer stage's executable.
pub const VIEWER_BINARY: &str = "opengs-viewer";

/// How to build the viewer stage; quoted when it is missing.
pub const BUILD_HINT: &str =
    "cargo build --release --workspace --bins --features opengs-viewer/rerun";

/// The Rerun viewer's default gRPC port (`rerun` listens there).
pub const DEFAULT_RERUN_PORT: u16 = 9876;

/// Seconds a ready viewer may stay silent before the watchdog takes it for hung: it runs on
/// idle CPU time, which a busy machine can withhold for a while.
const VIEWER_WATCHDOG_S: f64 = 60.0;

/// Where the run's Rerun recording goes. Either flag starts the viewer stage; both may be
/// given (the file and a live viewer get the same data).
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
pub struct ViewerArgs {
    /// Record the run for Rerun into FILE (`rerun FILE.rrd` opens it): camera poses and
    /// frustums, RGB and depth, label maps, the trackable map, per-stage latency. Starts the
    /// viewer stage (build it with `--features opengs-viewer/rerun`).
    #[arg(long, value_name = "FILE.rrd")]
    pub rerun: Option<PathBuf>,
    /// Stream the run to a Rerun viewer at ADDR, e.g. `rerun+http://laptop:9876/proxy`
    /// (`HOST` or `HOST:PORT` is short for that). Starts the viewer stage.
    #[arg(long, value_name = "ADDR", value_parser = connect_url)]
    pub rerun_connect: Option<String>,
}

impl ViewerArgs {
    /// Whether the run starts the viewer stage.
    pub fn enabled(&self) -> bool {
        self.rerun.is_some() || self.rerun_connect.is_some()
    }

    /// The flags as the viewer stage parses them back.
    pub fn to_args(&self) -> Vec<String> {
        let mut a = Vec::new();
        if let Some(file) = &self.rerun {
            a.extend(["--rerun".to_string(), file.display().to_string()]);
        }
        if let Some(url) = &self.rerun_connect {
            a.extend(["--rerun-connect".to_string(), url.clone()]);
        }
        a
    }

    /// Refuses a run that asks for the viewer when it cannot start, before any stage does:
    /// the binary missing (built without the feature), or the recording's directory missing.
    pub fn check_ready(&self) -> anyhow::Result<()> {
        if !self.enabled() {
            return Ok(());
        }
        let exe_dir = std::env::current_exe()
            .ok()
            .and_then(|e| e.parent().map(Path::to_path_buf));
        let path = std::env::var_os("PATH");
        if find_binary(VIEWER_BINARY, exe_dir.as_deref(), path.as_deref()).is_none() {
            let beside = exe_dir
                .as_deref()
                .map_or_else(|| "opengs".to_string(), |d| d.display().to_string());
            anyhow::bail!(
                "--rerun / --rerun-connect need the viewer stage, but {VIEWER_BINARY} is neither \
                 in {beside} nor on PATH: this build has no Rerun support. Build it with\n  \
                 {BUILD_HINT}\n(add `--features opengs-perception/onnx` as usual for the ONNX \
                 segmenters)"
            );
        }
        if let Some(file) = &self.rerun {
            if file.as_os_str().is_empty() || file.is_dir() {
                anyhow::bail!("--rerun {}: give a file name (.rrd)", file.display());
            }
            let dir = match file.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            if !dir.is_dir() {
                anyhow::bail!(
                    "--rerun {}: directory {} does not exist",
                    file.display(),
                    dir.display()
                );
            }
        }
        Ok(())
    }
}

/// The stage that runs the viewer. Started first (it subscribes before anything is
/// published) and so stopped last; optional and never restarted (a restart would overwrite
/// the recording), on idle CPU time so the tracker's wake-ups never wait for it.
pub fn viewer_stage() -> StageSpec {
    StageSpec {
        name: stage_names::VIEWER.to_string(),
        binary: VIEWER_BINARY.to_string(),
        args: Vec::new(),
        role: StageRole::Worker,
        cpus: Vec::new(),
        nice: 10,
        scheduler: Scheduler::Idle,
        restart_limit: 0,
        dataset: false,
        kind: None,
        kinds: Default::default(),
        finish_timeout_s: 0.0,
        watchdog_s: VIEWER_WATCHDOG_S,
        optional: true,
        replicas: 1,
        host: None,
        link: false,
    }
}

/// The stages a run starts, in order: the viewer first when `viewer` asks for it (unless
/// the deploy file has its own), then the deploy file's.
pub fn stages_to_start(deploy: &DeployFile, viewer: &ViewerArgs) -> Vec<StageSpec> {
    let own = deploy.stages.iter().any(|s| s.name == stage_names::VIEWER);
    let extra = (viewer.enabled() && !own).then(viewer_stage);
    extra
        .into_iter()
        .chain(deploy.stages.iter().cloned())
        .collect()
}

/// `name` beside `exe_dir` (or one level up, where cargo puts binaries beside test
/// executables), else on `path` (a `PATH` value): where the supervisor would find it.
pub fn find_binary(
    name: &str,
    exe_dir: Option<&Path>,
    path: Option<&std::ffi::OsStr>,
) -> Option<PathBuf> {
    let beside = exe_dir
        .into_iter()
        .flat_map(|d| [Some(d.to_path_buf()), d.parent().map(Path::to_path_buf)])
        .flatten();
    let on_path = path
        .map(|p| std::env::split_paths(p).collect::<Vec<_>>())
        .unwrap_or_default();
    beside
        .chain(on_path)
        .map(|d| d.join(name))
        .find(|c| c.is_file())
}

/// A Rerun gRPC proxy address: `rerun+http://HOST:PORT/proxy` (also `rerun+https://`,
/// `rerun://`); `HOST` or `HOST:PORT` alone is short for the `rerun+http://` form (default
/// port 9876), and a URL without a path gets `/proxy`.
pub fn connect_url(s: &str) -> Result<String, String> {
    let s = s.trim();
    let bad = || {
        format!(
            "'{s}' is not a Rerun viewer address: give rerun+http://HOST:PORT/proxy, or HOST[:PORT] \
             (port {DEFAULT_RERUN_PORT} by default)"
        )
    };
    let (scheme, rest) = match s.split_once("://") {
        Some((scheme @ ("rerun" | "rerun+http" | "rerun+https"), rest)) => (scheme, rest),
        Some(_) => return Err(bad()),
        None => ("rerun+http", s),
    };
    let (authority, path) = match rest.split_once('/') {
        Some((a, p)) => (a, p.trim_end_matches('/')),
        None => (rest, ""),
    };
    if !(path.is_empty() || path == "proxy") {
        return Err(bad());
    }
    let (host, port) = match authority.rsplit_once(':') {
        // An IPv6 literal in brackets has colons of its own.
        Some((h, p)) if !p.contains(']') => (h, Some(p)),
        _ => (authority, None),
    };
    let host_ok = !host.is_empty()
        && host
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-._[]:".contains(c));
    if !host_ok {
        return Err(bad());
    }
    let port = match port {
        Some(p) => p.parse::<u16>().ok().filter(|&p| p > 0).ok_or_else(bad)?,
        None => DEFAULT_RERUN_PORT,
    };
    Ok(format!("{scheme}://{host}:{port}/proxy"))
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        viewer: ViewerArgs,
    }

    fn parse(args: &[&str]) -> Result<ViewerArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("opengs").chain(args.iter().copied())).map(|c| c.viewer)
    }

    #[test]
    fn the_stage_reads_back_the_flags_the_run_sets() {
        let none = parse(&[]).expect("no flags");
        assert!(!none.enabled());
        assert!(none.to_args().is_empty());
        let both = parse(&["--rerun", "/tmp/x y.rrd", "--rerun-connect", "laptop"]).expect("both");
        assert!(both.enabled());
        assert_eq!(
            both.rerun_connect.as_deref(),
            Some("rerun+http://laptop:9876/proxy")
        );
        let args: Vec<String> = both.to_args();
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_eq!(parse(&refs).expect("round trip"), both);
        let file_only = parse(&["--rerun", "run.rrd"]).expect("file");
        assert!(file_only.enabled());
        assert_eq!(file_only.to_args(), ["--rerun", "run.rrd"]);
    }

    #[test]
    fn connect_addresses_are_completed_or_refused() {
        for (given, want) in [
            (
                "rerun+http://10.0.0.5:9876/proxy",
                "rerun+http://10.0.0.5:9876/proxy",
            ),
            ("rerun+http://laptop:9000", "rerun+http://laptop:9000/proxy"),
            (
                "rerun+https://viewer.lan/proxy/",
                "rerun+https://viewer.lan:9876/proxy",
            ),
            ("rerun://host:1234/proxy", "rerun://host:1234/proxy"),
            ("laptop.local:9877", "rerun+http://laptop.local:9877/proxy"),
            ("192.168.1.20", "rerun+http://192.168.1.20:9876/proxy"),
            ("[::1]:9876", "rerun+http://[::1]:9876/proxy"),
        ] {
            assert_eq!(connect_url(given).as_deref(), Ok(want), "{given}");
        }
        for bad in [
            "",
            "http://laptop:9876/proxy",
            "rerun+http://laptop:99999/proxy",
            "rerun+http://laptop:0/proxy",
            "rerun+http://laptop:9876/other",
            "laptop:port",
            "lap top",
            "rerun+http:///proxy",
        ] {
            let err = connect_url(bad).expect_err(bad);
            assert!(err.contains("rerun+http://HOST:PORT/proxy"), "{err}");
        }
        let err = parse(&["--rerun-connect", "ftp://x"]).expect_err("refused while parsing");
        assert!(err.to_string().contains("--rerun-connect"), "{err}");
    }

    #[test]
    fn the_binary_is_found_beside_opengs_one_level_up_or_on_path() {
        let dir = tempfile::tempdir().expect("tmp");
        let release = dir.path().join("release");
        let deps = release.join("deps");
        let bin = dir.path().join("bin");
        for d in [&deps, &bin] {
            std::fs::create_dir_all(d).expect("mkdir");
        }
        let path = std::env::join_paths([&bin]).expect("PATH");
        assert_eq!(
            find_binary(VIEWER_BINARY, Some(&release), Some(&path)),
            None
        );
        std::fs::write(bin.join(VIEWER_BINARY), b"").expect("write");
        assert_eq!(
            find_binary(VIEWER_BINARY, Some(&release), Some(&path)),
            Some(bin.join(VIEWER_BINARY))
        );
        std::fs::write(release.join(VIEWER_BINARY), b"").expect("write");
        assert_eq!(
            find_binary(VIEWER_BINARY, Some(&deps), None),
            Some(release.join(VIEWER_BINARY))
        );
        assert_eq!(
            find_binary(VIEWER_BINARY, Some(&release), Some(&path)),
            Some(release.join(VIEWER_BINARY))
        );
        // A directory of that name is not the binary.
        let other = dir.path().join("other");
        std::fs::create_dir_all(other.join(VIEWER_BINARY)).expect("mkdir");
        assert_eq!(find_binary(VIEWER_BINARY, Some(&other), None), None);
    }

    #[test]
    fn a_missing_binary_or_directory_is_refused_with_how_to_build_it() {
        // Unit tests run from target/*/deps: the viewer is there only in a feature build.
        let args = ViewerArgs {
            rerun: Some(PathBuf::from("/nonexistent-dir/run.rrd")),
            rerun_connect: None,
        };
        let exe_dir = std::env::current_exe()
            .ok()
            .and_then(|e| e.parent().map(Path::to_path_buf));
        let path = std::env::var_os("PATH");
        let err = args.check_ready().expect_err("refused").to_string();
        if find_binary(VIEWER_BINARY, exe_dir.as_deref(), path.as_deref()).is_none() {
            assert!(err.contains(BUILD_HINT), "{err}");
        } else {
            assert!(err.contains("/nonexistent-dir does not exist"), "{err}");
        }
        assert!(ViewerArgs::default().check_ready().is_ok());
    }

    #[test]
    fn the_viewer_stage_comes_first_and_only_when_asked_for() {
        let deploy = DeployFile::load(Path::new("desktop")).expect("built in");
        let plain = stages_to_start(&deploy, &ViewerArgs::default());
        assert_eq!(plain, deploy.stages);
        let asked = ViewerArgs {
            rerun: Some(PathBuf::from("x.rrd")),
            rerun_connect: None,
        };
        let with = stages_to_start(&deploy, &asked);
        assert_eq!(with.len(), deploy.stages.len() + 1);
        assert_eq!(with[0], viewer_stage());
        assert!(with[0].optional && with[0].restart_limit == 0);
        assert_eq!(with[0].scheduler, Scheduler::Idle);
        assert_eq!(&with[1..], deploy.stages.as_slice());
        // A deploy file that declares its own viewer keeps it, once.
        let mut own = deploy.clone();
        own.stages.insert(0, viewer_stage());
        own.stages[0].nice = 3;
        assert_eq!(stages_to_start(&own, &asked), own.stages);
    }
}
