//! The tracker's own queue of frames that arrived while it was busy.
//!
//! The frames service buffers 8 frames per subscriber (0.27 s at 30 Hz) and then drops the
//! oldest, as a camera does. One slow frame, or a CPU the other stages keep busy, held the
//! tracker longer than that on a slower machine, and a frame went without a pose (CI:
//! tracker p99 300 ms, one frame of 150 dropped). So between two frames the tracker copies
//! whatever waits in the service into this queue (1.5 MB at 640×480: 0.15 ms median here,
//! zeroing included, against a 12-15 ms tracked frame) and works through it in order; a frame is dropped only when the tracker
//! is more than [`FrameBacklog::limit`] frames behind.

use std::collections::VecDeque;

use opengs_ipc_schema::FrameHeader;

/// Frames waiting at most: 2 s at 30 Hz (about 92 MB at 640×480, held only while behind).
pub const BACKLOG_FRAMES: usize = 60;

/// A frame copied out of shared memory, its payload 8-byte aligned like the service's.
#[derive(Debug)]
pub struct QueuedFrame {
    pub header: FrameHeader,
    words: Vec<u64>,
    len: usize,
}

impl QueuedFrame {
    pub fn payload(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.words)[..self.len]
    }
}

/// Frames in arrival order, the oldest dropped beyond the limit.
#[derive(Debug)]
pub struct FrameBacklog {
    waiting: VecDeque<QueuedFrame>,
    /// Buffers of frames already tracked, reused so a copy does not fault in fresh pages.
    spare: Vec<Vec<u64>>,
    limit: usize,
}

impl FrameBacklog {
    pub fn new(limit: usize) -> Self {
        Self {
            waiting: VecDeque::new(),
            spare: Vec::new(),
            limit: limit.max(1),
        }
    }

    pub fn limit(&self) -> usize {
        self.limit
    }

    pub fn len(&self) -> usize {
        self.waiting.len()
    }

    pub fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Copies a frame in; returns the header of the oldest frame if it had to go.
    pub fn push(&mut self, header: &FrameHeader, payload: &[u8]) -> Option<FrameHeader> {
        let dropped = match self.waiting.len() >= self.limit {
            true => self.waiting.pop_front().map(|old| {
                self.spare.push(old.words);
                old.header
            }),
            false => None,
        };
        let mut words = self.spare.pop().unwrap_or_default();
        words.clear();
        words.resize(payload.len().div_ceil(8), 0);
        bytemuck::cast_slice_mut::<u64, u8>(&mut words)[..payload.len()].copy_from_slice(payload);
        self.waiting.push_back(QueuedFrame {
            header: *header,
            words,
            len: payload.len(),
        });
        dropped
    }

    /// The oldest waiting frame.
    pub fn pop(&mut self) -> Option<QueuedFrame> {
        self.waiting.pop_front()
    }

    /// Gives a tracked frame's buffer back for the next copy.
    pub fn recycle(&mut self, frame: QueuedFrame) {
        if self.spare.len() < 2 {
            self.spare.push(frame.words);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(seq: u64) -> FrameHeader {
        let mut h = FrameHeader::default();
        h.stamp.seq = seq;
        h
    }

    #[test]
    fn frames_come_out_in_order_with_their_bytes_and_aligned() {
        let mut backlog = FrameBacklog::new(4);
        for seq in 0..3u64 {
            let payload: Vec<u8> = (0..13).map(|i| (i as u64 * 7 + seq) as u8).collect();
            assert!(backlog.push(&header(seq), &payload).is_none());
        }
        assert_eq!(backlog.len(), 3);
        for seq in 0..3u64 {
            let f = backlog.pop().expect("a frame");
            assert_eq!(f.header.stamp.seq, seq);
            assert_eq!(f.payload().len(), 13);
            assert_eq!(f.payload()[5], (35 + seq) as u8);
            assert_eq!(f.payload().as_ptr() as usize % 8, 0);
            backlog.recycle(f);
        }
        assert!(backlog.pop().is_none());
    }

    #[test]
    fn beyond_the_limit_the_oldest_frame_goes() {
        let mut backlog = FrameBacklog::new(2);
        assert!(backlog.push(&header(0), &[1, 2]).is_none());
        assert!(backlog.push(&header(1), &[3, 4]).is_none());
        let dropped = backlog.push(&header(2), &[5]).expect("one dropped");
        assert_eq!(dropped.stamp.seq, 0);
        let next = backlog.pop().expect("frame 1");
        assert_eq!((next.header.stamp.seq, next.payload()), (1, &[3u8, 4][..]));
        let last = backlog.pop().expect("frame 2");
        // A reused buffer carries nothing of the frame before it.
        assert_eq!((last.header.stamp.seq, last.payload()), (2, &[5u8][..]));
    }
}
