//! The consensus results the mapper applied since its last checkpoint
//! (`mapper_consensus/` in the run directory), so a restarted mapper labels again what its
//! checkpoint lacks. The consensus answers each keyframe once: without this journal the
//! Gaussians a restarted mapper maps again for the keyframes after its checkpoint stay
//! unlabelled wherever no later keyframe's consensus sees them.
//!
//! One file per result, `<seq>.bin`: the [`ConsensusHeader`]'s bytes, then its payload, as
//! the consensus sent them (a temp file renamed, so a kill never leaves half a result). A
//! result is forgotten once a checkpoint holds it; the directory holds the few results of
//! the last second or so, not the run's.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use opengs_ipc_schema::{aligned_buffer, ConsensusHeader};

/// One journalled result, validated by [`ConsensusHeader::decode`] as it was read.
#[derive(Debug, Clone)]
pub struct JournalConsensus {
    pub header: ConsensusHeader,
    /// The payload in words: decoding wants it aligned to [`opengs_ipc_schema::ALIGN`].
    words: Vec<u64>,
    len: usize,
}

impl JournalConsensus {
    pub fn seq(&self) -> u64 {
        self.header.stamp.seq
    }

    pub fn payload(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.words)[..self.len]
    }
}

/// Writes and forgets the mapper's journalled consensus results.
#[derive(Debug, Clone)]
pub struct ConsensusJournal {
    dir: PathBuf,
}

fn result_path(dir: &Path, seq: u64) -> PathBuf {
    dir.join(format!("{seq}.bin"))
}

fn seq_of(path: &Path) -> Option<u64> {
    let name = path.file_name()?.to_str()?;
    name.strip_suffix(".bin")?.parse().ok()
}

impl ConsensusJournal {
    /// The journal in `dir` (created when missing).
    pub fn start(dir: &Path) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        Ok(Self {
            dir: dir.to_path_buf(),
        })
    }

    /// Journals a result as it is applied. Written on the mapper's thread: about 1.2 MB at
    /// 640×480 into the page cache, once per keyframe, against a render of 100 ms for it.
    pub fn append(&self, header: &ConsensusHeader, payload: &[u8]) -> std::io::Result<()> {
        let path = result_path(&self.dir, header.stamp.seq);
        let tmp = path.with_extension("bin.tmp");
        let mut bytes = Vec::with_capacity(size_of::<ConsensusHeader>() + payload.len());
        bytes.extend_from_slice(bytemuck::bytes_of(header));
        bytes.extend_from_slice(payload);
        std::fs::write(&tmp, &bytes)?;
        std::fs::rename(&tmp, &path)
    }

    /// Forgets the results a checkpoint now holds (after that checkpoint is written).
    pub fn forget(&self, held: &BTreeSet<u64>) {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return;
        };
        for path in entries.flatten().map(|e| e.path()) {
            if seq_of(&path).is_some_and(|s| held.contains(&s)) {
                if let Err(e) = std::fs::remove_file(&path) {
                    tracing::debug!("{}: {e}", path.display());
                }
            }
        }
    }
}

/// The journal's results, by seq (the order the consensus answers in, bar segmenter replicas
/// finishing out of order). One that cannot be read or does not decode is left out with a
/// warning: the journal helps a restart, it never stops one. No journal: none.
pub fn read_consensus_journal(dir: &Path) -> Vec<JournalConsensus> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Vec::new(),
        Err(e) => {
            tracing::warn!("{}: {e}; no consensus results restored", dir.display());
            return Vec::new();
        }
    };
    let mut paths: Vec<(u64, PathBuf)> = entries
        .flatten()
        .map(|e| e.path())
        .filter_map(|p| seq_of(&p).map(|s| (s, p)))
        .collect();
    paths.sort();
    paths
        .into_iter()
        .filter_map(|(seq, path)| match read_result(&path, seq) {
            Ok(r) => Some(r),
            Err(e) => {
                tracing::warn!("{}: {e}; consensus result left out", path.display());
                None
            }
        })
        .collect()
}

fn read_result(path: &Path, seq: u64) -> anyhow::Result<JournalConsensus> {
    let bytes = std::fs::read(path)?;
    let n = size_of::<ConsensusHeader>();
    anyhow::ensure!(
        bytes.len() >= n,
        "{} bytes, shorter than a header",
        bytes.len()
    );
    let header: ConsensusHeader = bytemuck::pod_read_unaligned(&bytes[..n]);
    let len = bytes.len() - n;
    let mut words = aligned_buffer(len);
    bytemuck::cast_slice_mut::<u64, u8>(&mut words)[..len].copy_from_slice(&bytes[n..]);
    let result = JournalConsensus { header, words, len };
    header.decode(result.payload())?;
    anyhow::ensure!(
        header.stamp.seq == seq,
        "holds keyframe #{}, named #{seq}",
        header.stamp.seq
    );
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_ipc_schema::{
        as_uninit_mut, ConsensusResult, MessageKind, PixelRun, PruneRun, Stamp,
    };

    /// A result as the consensus would send it: header and payload.
    fn result(seq: u64, label: u32) -> (ConsensusHeader, Vec<u64>) {
        let label_map = vec![label; 4 * 3];
        let relabels = [PixelRun {
            from: 2,
            to: label,
            offset: 0,
            count: 2,
            scope: PixelRun::SCOPE_PIXELS,
        }];
        let prunes = [PruneRun {
            label,
            offset: 1,
            count: 1,
        }];
        let parts = ConsensusResult {
            label_map: &label_map,
            mapping: &[[2, label]],
            relabels: &relabels,
            prunes: &prunes,
            pixels: &[3, 7],
        };
        let stamp = Stamp::new(MessageKind::Consensus, seq, 0, 0);
        let header = ConsensusHeader::new(stamp, 4, 3, 0.05, &parts);
        let mut words = aligned_buffer(header.payload_len());
        let bytes = &mut bytemuck::cast_slice_mut::<u64, u8>(&mut words)[..header.payload_len()];
        header.encode(&parts, as_uninit_mut(bytes)).expect("encode");
        (header, words)
    }

    #[test]
    fn results_come_back_whole_by_seq_and_checkpointed_ones_are_forgotten() {
        let dir = tempfile::tempdir().expect("tmp");
        let journal = ConsensusJournal::start(&dir.path().join("c")).expect("journal");
        for (seq, label) in [(40, 9), (10, 7), (30, 8)] {
            let (header, words) = result(seq, label);
            let payload = &bytemuck::cast_slice(&words)[..header.payload_len()];
            journal.append(&header, payload).expect("append");
        }
        // A torn file (a kill mid-write leaves only a .tmp, but a disk can do worse).
        std::fs::write(dir.path().join("c/50.bin"), [1u8, 2, 3]).expect("torn");
        let back = read_consensus_journal(&dir.path().join("c"));
        assert_eq!(
            back.iter().map(|r| r.seq()).collect::<Vec<_>>(),
            [10, 30, 40]
        );
        let view = back[2].header.decode(back[2].payload()).expect("decode");
        assert_eq!(view.result.label_map, [9; 12]);
        assert_eq!(view.result.pixels, [3, 7]);
        assert_eq!(view.result.relabels[0].to, 9);
        assert_eq!(view.header.counter_prune_scale, 0.05);

        journal.forget(&BTreeSet::from([10, 30]));
        let left = read_consensus_journal(&dir.path().join("c"));
        assert_eq!(left.iter().map(|r| r.seq()).collect::<Vec<_>>(), [40]);
        assert!(read_consensus_journal(&dir.path().join("none")).is_empty());
    }
}
