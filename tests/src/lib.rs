//! Support for the end-to-end tests in `tests/tests/`: locating the built
//! binaries, and the frame checksum the probe process and the tests share.

use std::path::PathBuf;

/// FNV-1a over a frame's planes: cheap, and any flipped byte changes it.
pub fn frame_checksum(depth: &[u16], rgb: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |b: u8| {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    };
    for d in depth {
        for b in d.to_le_bytes() {
            eat(b);
        }
    }
    for &b in rgb {
        eat(b);
    }
    h
}

/// A workspace binary in the same target directory as the running test.
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_default();
    // Test executables live in target/<profile>/deps; binaries one level up.
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .map(PathBuf::from)
        .unwrap_or_default();
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built; run `cargo build --release --workspace --bins` (the README test command does)",
        path.display()
    );
    path
}
