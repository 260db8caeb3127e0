//! CPU-feature dispatch for every SIMD kernel of this crate (rasterizer, row log, top-K
//! selection, backward pass, SSIM blur): one level type, detected once per process, read
//! once per call on the calling thread and passed down to the workers. Tests cap the level
//! on their own thread ([`cap_level`]) so every level the CPU has is run, the portable one
//! included, on any machine.

use std::sync::OnceLock;

/// The instruction set a kernel is compiled for. Ordered: a CPU that runs a level runs every
/// level below it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SimdLevel {
    Portable,
    /// AVX2 + F16C + POPCNT.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512 F/BW/VL on top of [`SimdLevel::Avx2`].
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

thread_local! {
    /// A test's cap on this thread's level (`None`: the detected level).
    static CAP: std::cell::Cell<Option<SimdLevel>> = const { std::cell::Cell::new(None) };
}

impl SimdLevel {
    /// The best level this CPU supports.
    pub fn detected() -> Self {
        static DETECTED: OnceLock<SimdLevel> = OnceLock::new();
        *DETECTED.get_or_init(detect)
    }

    /// The level kernels called from this thread use: the detected one, or lower where a
    /// test capped it.
    pub fn current() -> Self {
        let detected = Self::detected();
        CAP.with(|c| c.get())
            .map_or(detected, |cap| cap.min(detected))
    }

    /// Every level this CPU runs, lowest first.
    pub fn available() -> Vec<Self> {
        let all = [
            SimdLevel::Portable,
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2,
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx512,
        ];
        all.into_iter().filter(|&l| l <= Self::detected()).collect()
    }
}

/// Caps (or with `None` uncaps) the level of kernels called from this thread; for tests
/// and benchmarks that compare levels. Results of the rasterizer are bit-identical across
/// levels; the backward pass and SSIM agree to rounding.
pub fn cap_level(cap: Option<SimdLevel>) {
    CAP.with(|c| c.set(cap));
}

fn detect() -> SimdLevel {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        let avx2 = has!("avx2") && has!("f16c") && has!("popcnt");
        if avx2 && has!("avx512f") && has!("avx512bw") && has!("avx512vl") {
            return SimdLevel::Avx512;
        }
        if avx2 {
            return SimdLevel::Avx2;
        }
    }
    SimdLevel::Portable
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cap_lowers_this_threads_level_only() {
        let levels = SimdLevel::available();
        assert_eq!(levels[0], SimdLevel::Portable);
        assert_eq!(levels.last(), Some(&SimdLevel::detected()));
        cap_level(Some(SimdLevel::Portable));
        assert_eq!(SimdLevel::current(), SimdLevel::Portable);
        let other = std::thread::spawn(SimdLevel::current)
            .join()
            .expect("thread");
        assert_eq!(other, SimdLevel::detected());
        cap_level(None);
        assert_eq!(SimdLevel::current(), SimdLevel::detected());
    }
}
