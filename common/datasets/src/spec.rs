//! Which dataset to open: parsed from `synthetic`, `tum:DIR`, `replica:DIR`.

use std::path::PathBuf;
use std::str::FromStr;

use crate::replica::ReplicaOptions;
use crate::synthetic::SyntheticOptions;
use crate::tum::TumOptions;
use crate::DatasetError;

#[derive(Debug, Clone, PartialEq, Default)]
pub enum DatasetKind {
    #[default]
    Synthetic,
    Tum(PathBuf),
    Replica(PathBuf),
}

impl FromStr for DatasetKind {
    type Err = DatasetError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        let dir = |rest: &str, kind: &str| {
            if rest.is_empty() {
                Err(DatasetError::Spec(format!(
                    "dataset '{s}': missing directory, write {kind}:DIR"
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
                Ok(Self::Tum(dir(rest, "tum")?))
            }
            Some((kind, rest)) if kind.eq_ignore_ascii_case("replica") => {
                Ok(Self::Replica(dir(rest, "replica")?))
            }
            _ => Err(DatasetError::Spec(format!(
                "unknown dataset '{s}': expected 'synthetic', 'tum:DIR' or 'replica:DIR'"
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
        let kind = DatasetKind::Tum("a/b".into());
        assert_eq!(kind.to_string().parse::<DatasetKind>().ok(), Some(kind));
    }

    #[test]
    fn helpful_errors() {
        let e = "kitti:/x"
            .parse::<DatasetKind>()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("tum:DIR") && e.contains("kitti"), "{e}");
        let e = "tum:"
            .parse::<DatasetKind>()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("missing directory"), "{e}");
    }
}
