//! Which segmenter replica takes which keyframe.
//!
//! Every replica subscribes to every keyframe (publish-subscribe has no work queue), so the
//! replicas agree through the file system: a replica takes keyframe `seq` only if it is the
//! one that creates `segmenter_claims/<seq>` (`O_CREAT | O_EXCL`, atomic on every local file
//! system). The file holds the claimer's pid, so a run directory says afterwards who did what.
//! A replica that dies loses only the keyframe it claimed; nobody else does that one.
//!
//! Files, not shared memory, because this is a handful of operations per keyframe (a
//! keyframe takes 50 ms to seconds to segment) and a file needs neither unsafe code nor
//! cleanup on a crash. The claims are per host: replicas on other hosts need their own.

use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};

/// Claims further back than this many keyframes from the newest are removed (the directory
/// stays small on a long run).
const KEEP_BEHIND: u64 = 1024;
/// Pruning looks at the directory once per this many claims.
const PRUNE_EVERY: u64 = 64;

/// One replica's view of the shared claims directory.
pub struct KeyframeClaims {
    dir: PathBuf,
    owner: String,
    claimed: u64,
}

impl KeyframeClaims {
    /// Opens (creates) the claims directory; `owner` is written into each claim.
    pub fn open(dir: &Path, owner: &str) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            owner: owner.to_string(),
            claimed: 0,
        })
    }

    fn path(&self, seq: u64) -> PathBuf {
        self.dir.join(seq.to_string())
    }

    /// Some replica has taken `seq` already.
    pub fn is_claimed(&self, seq: u64) -> bool {
        self.path(seq).exists()
    }

    /// Takes `seq`: true when this replica got it, false when another one was first.
    pub fn claim(&mut self, seq: u64) -> std::io::Result<bool> {
        let mut file = match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(self.path(seq))
        {
            Ok(f) => f,
            Err(e) if e.kind() == ErrorKind::AlreadyExists => return Ok(false),
            Err(e) => return Err(e),
        };
        // The claim is the file's existence; its text only says who (best effort).
        let _ = writeln!(file, "{}", self.owner);
        self.claimed += 1;
        if self.claimed.is_multiple_of(PRUNE_EVERY) {
            self.prune(seq);
        }
        Ok(true)
    }

    /// Who claimed `seq` (the text its claimer wrote), if anyone did.
    pub fn owner_of(&self, seq: u64) -> Option<String> {
        std::fs::read_to_string(self.path(seq))
            .ok()
            .map(|s| s.trim().to_string())
    }

    /// Removes claims more than [`KEEP_BEHIND`] keyframes older than `newest`. Replicas prune
    /// concurrently: a file another one removed first is no error.
    fn prune(&self, newest: u64) {
        let Some(oldest_kept) = newest.checked_sub(KEEP_BEHIND) else {
            return;
        };
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return;
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            let old = name
                .to_str()
                .and_then(|n| n.parse::<u64>().ok())
                .is_some_and(|seq| seq < oldest_kept);
            if old {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_keyframe_goes_to_exactly_one_of_many_racing_replicas() {
        let dir = tempfile::tempdir().unwrap();
        let claims = dir.path().join("claims");
        // Four replicas (threads standing in for processes) race for the same 200 keyframes.
        let winners: Vec<Vec<u64>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|r| {
                    let claims = claims.clone();
                    s.spawn(move || {
                        let mut c = KeyframeClaims::open(&claims, &format!("replica {r}")).unwrap();
                        (0..200u64).filter(|&seq| c.claim(seq).unwrap()).collect()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let mut all: Vec<u64> = winners.concat();
        all.sort_unstable();
        assert_eq!(
            all,
            (0..200).collect::<Vec<_>>(),
            "each keyframe claimed exactly once"
        );
        let reader = KeyframeClaims::open(&claims, "reader").unwrap();
        for (r, won) in winners.iter().enumerate() {
            for &seq in won {
                assert_eq!(
                    reader.owner_of(seq).as_deref(),
                    Some(&*format!("replica {r}"))
                );
            }
        }
        assert!(reader.is_claimed(199));
        assert!(!reader.is_claimed(200));
    }

    #[test]
    fn old_claims_are_pruned_and_recent_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = KeyframeClaims::open(dir.path(), "1").unwrap();
        // Every 3rd keyframe up to 3 × 1100: pruning ran at claims 64, 128, ..., 1088.
        for seq in (0..1100u64).map(|i| i * 3) {
            assert!(c.claim(seq).unwrap());
        }
        // The last prune ran at the 1088th claim (seq 3261): everything before 3261 - 1024 went.
        let left: Vec<u64> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_str().unwrap().parse().unwrap())
            .collect();
        let oldest = *left.iter().min().unwrap();
        assert_eq!(oldest, (3261 - 1024u64).div_ceil(3) * 3);
        assert_eq!(left.len(), (3297 - oldest as usize) / 3 + 1);
        // Pruned keyframes are far behind any replica's input buffer (16 keyframes).
        assert!(!c.is_claimed(0));
    }
}
