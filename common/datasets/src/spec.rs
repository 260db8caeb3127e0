//! Which dataset to open: parsed from `synthetic`, `tum:DIR`, `replica:DIR`,
//! `rosbag2:PATH`.

use std::path::PathBuf;
use std::str::FromStr;

use crate::replica::ReplicaOptions;
use crate::rosbag2::Rosbag2Options;
use crate::synthetic::SyntheticOptions;
use crate::tum::TumOptions;
use crate::DatasetError;

#[derive(Debug, Clone, PartialEq, Default)]
pub enum DatasetKind {
    #[default]
    Synthetic,
    Tum(PathBuf),
    Replica(PathBuf),
    /// A ROS 2 bag: its directory (metadata.yaml + .mcap files) or one .mcap file.
    Rosbag2(PathBuf),
}

impl FromStr for DatasetKind {
    type Err = DatasetError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        let dir = |rest: &str, kind: &str, what: &str| {
            if rest.is_empty() {
                Err(DatasetError::Spec(format!(
                    "dataset '{s}': missing {}, write {kind}:{what}",
                    if what == "DIR" { "directory" } else { "path" }
                )))
            } else {
                Ok(PathBuf::from(rest))
            }
        };
        if s.eq_ignore_ascii_case("synthetic") {
            return Ok(Self::Synthetic);
        }
        match s.split_once(':') {
            Some((kind, rest)) if kind.eq_ignore_ascii_case("tum") => {
                Ok(Self::Tum(dir(rest, "tum", "DIR")?))
            }
            Some((kind, rest)) if kind.eq_ignore_ascii_case("replica") => {
                Ok(Self::Replica(dir(rest, "replica", "DIR")?))
            }
            Some((kind, rest)) if kind.eq_ignore_ascii_case("rosbag2") => {
                Ok(Self::Rosbag2(dir(rest, "rosbag2", "PATH")?))
            }
            _ => Err(DatasetError::Spec(format!(
                "unknown dataset '{s}': expected 'synthetic', 'tum:DIR', 'replica:DIR' or \
                 'rosbag2:PATH' (a ROS 2 bag directory or .mcap file)"
            ))),
        }
    }
}

impl std::fmt::Display for DatasetKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Synthetic => write!(f, "synthetic"),
            Self::Tum(d) => write!(f, "tum:{}", d.display()),
            Self::Replica(d) => write!(f, "replica:{}", d.display()),
            Self::Rosbag2(p) => write!(f, "rosbag2:{}", p.display()),
        }
    }
}

/// A dataset plus the options of every reader (only the matching one is used).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DatasetSpec {
    pub kind: DatasetKind,
    /// Use at most this many frames.
    pub max_frames: Option<usize>,
    pub synthetic: SyntheticOptions,
    pub tum: TumOptions,
    pub replica: ReplicaOptions,
    pub rosbag2: Rosbag2Options,
}

impl DatasetSpec {
    pub fn new(kind: DatasetKind) -> Self {
        Self {
            kind,
            ..Self::default()
        }
    }

    pub fn with_max_frames(mut self, n: Option<usize>) -> Self {
        self.max_frames = n;
        self
    }
}

impl FromStr for DatasetSpec {
    type Err = DatasetError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(Self::new(s.parse()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_kinds() {
        assert_eq!(
            "synthetic".parse::<DatasetKind>().ok(),
            Some(DatasetKind::Synthetic)
        );
        assert_eq!(
            "tum:/data/rgbd_dataset_freiburg1_desk"
                .parse::<DatasetKind>()
                .ok(),
            Some(DatasetKind::Tum("/data/rgbd_dataset_freiburg1_desk".into()))
        );
        assert_eq!(
            "replica:room0".parse::<DatasetKind>().ok(),
            Some(DatasetKind::Replica("room0".into()))
        );
        assert_eq!(
            "rosbag2:/bags/run_1".parse::<DatasetKind>().ok(),
            Some(DatasetKind::Rosbag2("/bags/run_1".into()))
        );
        for kind in [
            DatasetKind::Tum("a/b".into()),
            DatasetKind::Rosbag2("c/d_0.mcap".into()),
        ] {
            assert_eq!(kind.to_string().parse::<DatasetKind>().ok(), Some(kind));
        }
    }

    #[test]
    fn helpful_errors() {
        let e = "kitti:/x"
            .parse::<DatasetKind>()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("tum:DIR") && e.contains("rosbag2:PATH") && e.contains("kitti"),
            "{e}"
        );
        let e = "tum:"
            .parse::<DatasetKind>()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("missing directory"), "{e}");
        let e = "rosbag2:"
            .parse::<DatasetKind>()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("missing path") && e.contains("rosbag2:PATH"),
            "{e}"
        );
    }
}
