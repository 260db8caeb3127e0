//! A small multiplicative hasher for integer label keys (SipHash is needlessly slow here and
//! the keys come from our own pipeline, so hash flooding is no concern).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// FxHash-style: rotate, xor, multiply by a large odd constant.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct LabelHasher {
    hash: u64,
}

impl LabelHasher {
    fn add(&mut self, word: u64) {
        self.hash = (self.hash.rotate_left(5) ^ word).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

impl Hasher for LabelHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.add(u64::from(b));
        }
    }

    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }

    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }

    fn finish(&self) -> u64 {
        self.hash
    }
}

/// Hash map keyed by labels or label pairs.
pub(crate) type LabelMap<K, V> = HashMap<K, V, BuildHasherDefault<LabelHasher>>;
