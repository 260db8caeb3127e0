//! Property-based fuzz targets (stable Rust, seeded RNG) for every message decoder.
//!
//! Each target decodes random headers over random payloads and mutations of messages made
//! by the encoders. Properties: `decode` never panics or hangs; when it returns `Ok`, the
//! payload has the layout the header implies and every view lies inside it, in order.
//!
//! Quick size (20,000 inputs a target) in `cargo test`; full size:
//! `OPENGS_FUZZ_CASES=1000000 cargo test --release -p opengs-ipc-schema --test fuzz -- --nocapture`.
//! A failure names its seed: `OPENGS_FUZZ_SEED=<seed> OPENGS_FUZZ_CASES=1` replays it.

use opengs_ipc_schema::*;
use rand::Rng;

#[path = "support/fuzz_driver.rs"]
mod fuzz_driver;
use fuzz_driver::{fuzz, pick, R};

const U32_EDGES: [u32; 22] = [
    0,
    1,
    2,
    5,
    6,
    7,
    100,
    8191,
    8192,
    8193,
    65_535,
    65_536,
    1200 * 680,
    1200 * 680 + 1,
    1 << 20,
    (1 << 20) + 1,
    20_000_000,
    20_000_001,
    1 << 26,
    1 << 31,
    u32::MAX - 1,
    u32::MAX,
];

fn any_u32(rng: &mut R) -> u32 {
    match rng.gen_range(0..6) {
        0 => rng.gen(),
        1 => rng.gen_range(0..16),
        2 => 1 << rng.gen_range(0..32),
        3 => pick(rng, &U32_EDGES)
            .wrapping_add(rng.gen_range(0..3))
            .wrapping_sub(1),
        _ => pick(rng, &U32_EDGES),
    }
}

fn any_u64(rng: &mut R) -> u64 {
    match rng.gen_range(0..6) {
        0 => rng.gen(),
        1 => rng.gen_range(0..64),
        2 => 1 << rng.gen_range(0..64),
        3 => u64::MAX - rng.gen_range(0..3),
        4 => (1 << 20) + rng.gen_range(0..3) - 1,
        _ => any_u32(rng) as u64,
    }
}

const F64_EDGES: [f64; 17] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    1e-3,
    525.0,
    5000.0,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MIN_POSITIVE,
    1e-310,
    f64::MAX,
    f64::MIN,
    f64::EPSILON,
    -f64::NAN,
];

fn any_f64(rng: &mut R) -> f64 {
    match rng.gen_range(0..4) {
        0 => f64::from_bits(rng.gen()),
        1 => rng.gen_range(-10.0..10.0),
        _ => pick(rng, &F64_EDGES),
    }
}

fn any_f32(rng: &mut R) -> f32 {
    match rng.gen_range(0..5) {
        0 => f32::from_bits(rng.gen()),
        1 => rng.gen_range(-10.0..10.0),
        2 => pick(
            rng,
            &[f32::MAX, f32::MIN_POSITIVE, 1e-40, 1.0000001, 0.9999999],
        ),
        _ => any_f64(rng) as f32,
    }
}

/// A plausible image side most of the time, any u32 otherwise.
fn dim(rng: &mut R) -> u32 {
    if rng.gen_bool(0.7) {
        rng.gen_range(1..=12)
    } else {
        any_u32(rng)
    }
}

/// A small count most of the time, any u32 otherwise.
fn count(rng: &mut R) -> u32 {
    if rng.gen_bool(0.6) {
        rng.gen_range(0..8)
    } else {
        any_u32(rng)
    }
}

fn finite(rng: &mut R) -> f64 {
    rng.gen_range(-100.0..100.0)
}

fn positive(rng: &mut R) -> f64 {
    rng.gen_range(0.01..1000.0)
}

// ---- Payloads ----

/// A payload in an 8-byte-aligned buffer, starting `off` bytes in (misaligned when `off > 0`).
struct Payload {
    buf: Vec<u64>,
    off: usize,
    len: usize,
}

impl Payload {
    fn new(len: usize) -> Self {
        Self {
            buf: aligned_buffer(len + 8),
            off: 0,
            len,
        }
    }

    fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u64, u8>(&self.buf)[self.off..self.off + self.len]
    }

    fn bytes_mut(&mut self) -> &mut [u8] {
        &mut bytemuck::cast_slice_mut::<u64, u8>(&mut self.buf)[self.off..self.off + self.len]
    }

    /// Keeps the first bytes and offset; new bytes are random.
    fn resize(&mut self, len: usize, rng: &mut R) {
        let old = self.bytes().to_vec();
        let mut new = Payload::new(len);
        new.off = self.off;
        let keep = old.len().min(len);
        new.bytes_mut()[..keep].copy_from_slice(&old[..keep]);
        fill(rng, &mut new.bytes_mut()[keep..]);
        *self = new;
    }

    fn set_offset(&mut self, off: usize) {
        let old = self.bytes().to_vec();
        self.off = off;
        self.bytes_mut().copy_from_slice(&old);
    }
}

/// Random content: bytes, zeros, small u32 words (valid indices and counts), or f32 words.
fn fill(rng: &mut R, bytes: &mut [u8]) {
    match rng.gen_range(0..4) {
        0 => rng.fill(bytes),
        1 => bytes.fill(0),
        2 => {
            for w in bytes.chunks_mut(4) {
                let v: u32 = if rng.gen_bool(0.8) {
                    rng.gen_range(0..16)
                } else {
                    any_u32(rng)
                };
                w.copy_from_slice(&v.to_ne_bytes()[..w.len()]);
            }
        }
        _ => {
            for w in bytes.chunks_mut(4) {
                let v = any_f32(rng);
                w.copy_from_slice(&v.to_ne_bytes()[..w.len()]);
            }
        }
    }
}

/// Bytes of `n` elements of `size` bytes, padded to the schema's 8-byte alignment.
fn sec(n: u128, size: u128) -> u128 {
    (n * size).div_ceil(ALIGN as u128) * ALIGN as u128
}

/// A layout computed in u128 (headers' counts overflow usize products), if it fits.
fn fits(len: u128) -> Option<usize> {
    usize::try_from(len).ok()
}

/// Pixels of an image side by side.
fn pixels(w: u32, h: u32) -> u128 {
    w as u128 * h as u128
}

/// Payloads implied by a header larger than this are not built (random mode).
const MAX_BUILT: usize = 1 << 20;

/// Asserts that views lie inside the payload, one after another.
struct Sections<'p> {
    start: usize,
    end: usize,
    pos: usize,
    _payload: &'p [u8],
}

impl<'p> Sections<'p> {
    fn new(payload: &'p [u8]) -> Self {
        let start = payload.as_ptr() as usize;
        Self {
            start,
            end: start + payload.len(),
            pos: start,
            _payload: payload,
        }
    }

    fn next<T>(&mut self, s: &[T]) {
        if s.is_empty() {
            return;
        }
        let a = s.as_ptr() as usize;
        let b = a + std::mem::size_of_val(s);
        assert!(
            a >= self.pos && b <= self.end,
            "view {:#x}..{:#x} outside payload {:#x}..{:#x} or overlapping the previous",
            a - self.start,
            b - self.start,
            self.pos - self.start,
            self.end - self.start
        );
        self.pos = b;
    }
}

fn check_stamp(s: &Stamp, kind: MessageKind, payload: &[u8]) {
    assert_eq!(s.version, SCHEMA_VERSION);
    assert_eq!(s.kind, kind as u32);
    assert_eq!(s.payload_len, payload.len() as u64);
}

/// A random stamp: mostly the right version, kind and length, so decoding goes deeper.
fn random_stamp(rng: &mut R, kind: MessageKind, len: usize) -> Stamp {
    let mut s = Stamp::new(kind, rng.gen(), rng.gen(), rng.gen());
    s.payload_len = len as u64;
    if rng.gen_bool(0.1) {
        s.version = any_u32(rng);
    }
    if rng.gen_bool(0.1) {
        s.kind = if rng.gen_bool(0.5) {
            rng.gen_range(0..12)
        } else {
            any_u32(rng)
        };
    }
    if rng.gen_bool(0.1) {
        s.payload_len = any_u64(rng);
    }
    s
}

fn mutate_stamp(rng: &mut R, s: &mut Stamp) {
    match rng.gen_range(0..4) {
        0 => s.version = any_u32(rng),
        1 => s.kind = any_u32(rng) % 12,
        2 => s.payload_len = any_u64(rng),
        _ => s.seq = any_u64(rng),
    }
}

// ---- One message type per target ----

trait Target {
    type H: Copy + Stamped;
    const KIND: MessageKind;
    /// A header with every field random (the stamp's length is `len`).
    fn random(rng: &mut R) -> Self::H;
    /// Sets one field other than the stamp to a random value.
    fn mutate(rng: &mut R, h: &mut Self::H);
    /// Payload length the header implies, by the schema's documented layout.
    fn layout(h: &Self::H) -> Option<usize>;
    /// A valid message from the encoder (checked to round-trip).
    fn valid(rng: &mut R) -> (Self::H, Payload);
    /// Decodes; on `Ok`, asserts the properties. Returns whether it was accepted.
    fn check(h: &Self::H, p: &[u8]) -> bool;
}

/// One input of target `T`: a random or encoded message, mutated 0–4 times, decoded.
fn case<T: Target>(rng: &mut R) -> bool {
    let random = rng.gen_bool(0.35);
    let (mut h, mut p) = if random {
        let mut h = T::random(rng);
        let len = match T::layout(&h) {
            Some(len) if len <= MAX_BUILT && rng.gen_bool(0.7) => len,
            _ => rng.gen_range(0..256),
        };
        let mut p = Payload::new(len);
        fill(rng, p.bytes_mut());
        *h.stamp_mut() = random_stamp(rng, T::KIND, len);
        if rng.gen_bool(0.05) {
            p.set_offset(rng.gen_range(1..8));
        }
        (h, p)
    } else {
        T::valid(rng)
    };
    let mutations = if random { 0 } else { rng.gen_range(0..=4) };
    for _ in 0..mutations {
        match rng.gen_range(0..12) {
            0..=2 => T::mutate(rng, &mut h),
            3 => mutate_stamp(rng, h.stamp_mut()),
            4 | 5 if p.len > 0 => {
                let i = rng.gen_range(0..p.len);
                p.bytes_mut()[i] ^= 1 << rng.gen_range(0..8);
            }
            6 if p.len >= 4 => {
                let i = rng.gen_range(0..p.len / 4) * 4;
                let v = any_u32(rng);
                p.bytes_mut()[i..i + 4].copy_from_slice(&v.to_ne_bytes());
            }
            7 => {
                let len = rng.gen_range(0..=p.len);
                p.resize(len, rng);
                h.stamp_mut().payload_len = len as u64;
            }
            8 => {
                let len = p.len + rng.gen_range(1..64);
                p.resize(len, rng);
                h.stamp_mut().payload_len = len as u64;
            }
            // Change a field and give the payload the length it then implies.
            9 => {
                T::mutate(rng, &mut h);
                if let Some(len) = T::layout(&h).filter(|&l| l <= MAX_BUILT) {
                    p.resize(len, rng);
                    h.stamp_mut().payload_len = len as u64;
                }
            }
            10 => p.set_offset(rng.gen_range(0..8)),
            _ => h.stamp_mut().payload_len = p.len as u64,
        }
    }
    let ok = T::check(&h, p.bytes());
    if mutations == 0 && !random {
        assert!(ok, "an encoded message was refused");
    }
    ok
}

struct Frame;
impl Target for Frame {
    type H = FrameHeader;
    const KIND: MessageKind = MessageKind::Frame;

    fn random(rng: &mut R) -> FrameHeader {
        FrameHeader {
            stamp: Stamp::default(),
            width: dim(rng),
            height: dim(rng),
            depth_scale: if rng.gen_bool(0.7) {
                5000.0
            } else {
                any_f32(rng)
            },
            flags: if rng.gen_bool(0.8) {
                rng.gen_range(0..4)
            } else {
                any_u32(rng)
            },
            intrinsics: std::array::from_fn(|_| {
                if rng.gen_bool(0.8) {
                    positive(rng)
                } else {
                    any_f64(rng)
                }
            }),
            gt_pose: std::array::from_fn(|_| {
                if rng.gen_bool(0.9) {
                    finite(rng)
                } else {
                    any_f64(rng)
                }
            }),
            frame_index: rng.gen(),
        }
    }

    fn mutate(rng: &mut R, h: &mut FrameHeader) {
        match rng.gen_range(0..7) {
            0 => h.width = any_u32(rng),
            1 => h.height = any_u32(rng),
            2 => h.depth_scale = any_f32(rng),
            3 => h.flags = any_u32(rng) % 8,
            4 => h.intrinsics[rng.gen_range(0..4)] = any_f64(rng),
            5 => h.gt_pose[rng.gen_range(0..7)] = any_f64(rng),
            _ => h.frame_index = any_u64(rng),
        }
    }

    fn layout(h: &FrameHeader) -> Option<usize> {
        let n = pixels(h.width, h.height);
        let labels = if h.has_labels() { sec(n, 2) } else { 0 };
        fits(sec(n, 2) + labels + sec(3 * n, 1))
    }

    fn valid(rng: &mut R) -> (FrameHeader, Payload) {
        let (w, hh) = (rng.gen_range(1..=12u32), rng.gen_range(1..=12u32));
        let n = (w * hh) as usize;
        let depth: Vec<u16> = (0..n).map(|_| rng.gen()).collect();
        let labels: Option<Vec<u16>> = rng
            .gen_bool(0.5)
            .then(|| (0..n).map(|_| rng.gen()).collect());
        let rgb: Vec<u8> = (0..3 * n).map(|_| rng.gen()).collect();
        let gt = rng
            .gen_bool(0.5)
            .then(|| std::array::from_fn(|_| finite(rng)));
        let h = FrameHeader::new(
            Stamp::new(MessageKind::Frame, rng.gen(), rng.gen(), rng.gen()),
            w,
            hh,
            rng.gen_range(1.0..10_000.0),
            [positive(rng), positive(rng), finite(rng), finite(rng)],
            gt,
            labels.is_some(),
            rng.gen(),
        );
        let mut p = Payload::new(h.payload_len());
        let parts = FrameParts {
            depth: &depth,
            labels: labels.as_deref(),
            rgb: &rgb,
        };
        h.encode(&parts, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!(
            (v.depth, v.labels, v.rgb),
            (&depth[..], labels.as_deref(), &rgb[..])
        );
        (h, p)
    }

    fn check(h: &FrameHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(
            (1..=MAX_IMAGE_SIDE).contains(&h.width) && (1..=MAX_IMAGE_SIDE).contains(&h.height)
        );
        let n = h.pixels();
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        assert_eq!(v.depth.len(), n);
        assert_eq!(v.labels.map(<[u16]>::len), h.has_labels().then_some(n));
        assert_eq!(v.rgb.len(), 3 * n);
        assert!(h.depth_scale.is_finite() && h.depth_scale > 0.0);
        assert!(h.intrinsics.iter().all(|v| v.is_finite()));
        assert!(!h.has_gt() || h.gt_pose.iter().all(|v| v.is_finite()));
        let mut s = Sections::new(p);
        s.next(v.depth);
        s.next(v.labels.unwrap_or(&[]));
        s.next(v.rgb);
        true
    }
}

struct Keyframe;
impl Target for Keyframe {
    type H = KeyframeHeader;
    const KIND: MessageKind = MessageKind::Keyframe;

    fn random(rng: &mut R) -> KeyframeHeader {
        KeyframeHeader {
            stamp: Stamp::default(),
            pose: std::array::from_fn(|_| {
                if rng.gen_bool(0.9) {
                    finite(rng)
                } else {
                    any_f64(rng)
                }
            }),
            intrinsics: std::array::from_fn(|_| {
                if rng.gen_bool(0.9) {
                    positive(rng)
                } else {
                    any_f64(rng)
                }
            }),
            width: dim(rng),
            height: dim(rng),
            depth_scale: if rng.gen_bool(0.7) {
                5000.0
            } else {
                any_f32(rng)
            },
            point_count: count(rng),
            flags: if rng.gen_bool(0.8) {
                rng.gen_range(0..2)
            } else {
                any_u32(rng)
            },
            _reserved: any_u32(rng),
            frame_index: rng.gen(),
        }
    }

    fn mutate(rng: &mut R, h: &mut KeyframeHeader) {
        match rng.gen_range(0..8) {
            0 => h.width = any_u32(rng),
            1 => h.height = any_u32(rng),
            2 => h.depth_scale = any_f32(rng),
            3 => h.flags = any_u32(rng) % 4,
            4 => h.intrinsics[rng.gen_range(0..4)] = any_f64(rng),
            5 => h.pose[rng.gen_range(0..7)] = any_f64(rng),
            6 => h.point_count = any_u32(rng),
            _ => h._reserved = any_u32(rng),
        }
    }

    fn layout(h: &KeyframeHeader) -> Option<usize> {
        let n = pixels(h.width, h.height);
        let p = h.point_count as u128;
        let labels = if h.has_labels() { sec(n, 2) } else { 0 };
        fits(sec(p, 12) + sec(p, 24) + sec(n, 2) + labels + sec(3 * n, 1))
    }

    fn valid(rng: &mut R) -> (KeyframeHeader, Payload) {
        let (w, hh) = (rng.gen_range(1..=12u32), rng.gen_range(1..=12u32));
        let n = (w * hh) as usize;
        let np = rng.gen_range(0..20);
        let points: Vec<[f32; 3]> = (0..np).map(|_| rng.gen()).collect();
        let covariances: Vec<[f32; 6]> = (0..np).map(|_| rng.gen()).collect();
        let depth: Vec<u16> = (0..n).map(|_| rng.gen()).collect();
        let labels: Option<Vec<u16>> = rng
            .gen_bool(0.5)
            .then(|| (0..n).map(|_| rng.gen()).collect());
        let rgb: Vec<u8> = (0..3 * n).map(|_| rng.gen()).collect();
        let h = KeyframeHeader::new(
            Stamp::new(MessageKind::Keyframe, rng.gen(), rng.gen(), rng.gen()),
            std::array::from_fn(|_| finite(rng)),
            [positive(rng), positive(rng), finite(rng), finite(rng)],
            w,
            hh,
            rng.gen_range(1.0..10_000.0),
            np as u32,
            labels.is_some(),
            rng.gen(),
        );
        let mut p = Payload::new(h.payload_len());
        let parts = KeyframeParts {
            points: &points,
            covariances: &covariances,
            depth: &depth,
            labels: labels.as_deref(),
            rgb: &rgb,
        };
        h.encode(&parts, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!(
            (v.points, v.covariances, v.depth, v.labels, v.rgb),
            (
                &points[..],
                &covariances[..],
                &depth[..],
                labels.as_deref(),
                &rgb[..]
            )
        );
        (h, p)
    }

    fn check(h: &KeyframeHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(
            (1..=MAX_IMAGE_SIDE).contains(&h.width) && (1..=MAX_IMAGE_SIDE).contains(&h.height)
        );
        let n = h.width as usize * h.height as usize;
        let np = h.point_count as usize;
        assert!(h.point_count <= 1200 * 680);
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        assert_eq!((v.points.len(), v.covariances.len()), (np, np));
        assert_eq!(v.depth.len(), n);
        assert_eq!(v.labels.map(<[u16]>::len), h.has_labels().then_some(n));
        assert_eq!(v.rgb.len(), 3 * n);
        assert!(h.pose.iter().chain(&h.intrinsics).all(|v| v.is_finite()));
        assert!(h.depth_scale.is_finite() && h.depth_scale > 0.0);
        let mut s = Sections::new(p);
        s.next(v.points);
        s.next(v.covariances);
        s.next(v.depth);
        s.next(v.labels.unwrap_or(&[]));
        s.next(v.rgb);
        true
    }
}

fn random_class(rng: &mut R) -> Option<String> {
    let names = [
        "chair",
        "table",
        "überschrank",
        "椅子",
        "",
        "a-very-long-class-name-that-goes-past-36-bytes",
    ];
    rng.gen_bool(0.7).then(|| pick(rng, &names).to_string())
}

struct Segments;
impl Target for Segments {
    type H = SegmentsHeader;
    const KIND: MessageKind = MessageKind::Segments;

    fn random(rng: &mut R) -> SegmentsHeader {
        SegmentsHeader {
            stamp: Stamp::default(),
            width: dim(rng),
            height: dim(rng),
            label_count: count(rng),
            segmenter: any_u32(rng),
        }
    }

    fn mutate(rng: &mut R, h: &mut SegmentsHeader) {
        match rng.gen_range(0..4) {
            0 => h.width = any_u32(rng),
            1 => h.height = any_u32(rng),
            2 => h.label_count = any_u32(rng),
            _ => h.segmenter = any_u32(rng),
        }
    }

    fn layout(h: &SegmentsHeader) -> Option<usize> {
        let label = std::mem::size_of::<SegmentLabel>() as u128;
        fits(sec(pixels(h.width, h.height), 4) + sec(h.label_count as u128, label))
    }

    fn valid(rng: &mut R) -> (SegmentsHeader, Payload) {
        let (w, hh) = (rng.gen_range(1..=12u32), rng.gen_range(1..=12u32));
        let n = (w * hh) as usize;
        let nl = rng.gen_range(0..8);
        let label_map: Vec<u32> = (0..n).map(|_| rng.gen_range(0..nl as u32 + 2)).collect();
        let labels: Vec<SegmentLabel> = (0..nl)
            .map(|i| {
                let class = random_class(rng);
                SegmentLabel::new(i as u32, rng.gen(), class.as_deref(), rng.gen())
            })
            .collect();
        let h = SegmentsHeader::new(
            Stamp::new(MessageKind::Segments, rng.gen(), rng.gen(), rng.gen()),
            w,
            hh,
            nl as u32,
            rng.gen_range(0..4),
        );
        let mut p = Payload::new(h.payload_len());
        h.encode(&label_map, &labels, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!((v.label_map, v.labels), (&label_map[..], &labels[..]));
        (h, p)
    }

    fn check(h: &SegmentsHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(
            (1..=MAX_IMAGE_SIDE).contains(&h.width) && (1..=MAX_IMAGE_SIDE).contains(&h.height)
        );
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        assert_eq!(v.label_map.len(), h.width as usize * h.height as usize);
        assert_eq!(v.labels.len(), h.label_count as usize);
        for l in v.labels {
            assert!(l.confidence.is_finite() && l.score.is_finite());
            let _ = l.class();
        }
        let mut s = Sections::new(p);
        s.next(v.label_map);
        s.next(v.labels);
        true
    }
}

struct Render;
impl Target for Render {
    type H = RenderHeader;
    const KIND: MessageKind = MessageKind::Render;

    fn random(rng: &mut R) -> RenderHeader {
        RenderHeader {
            stamp: Stamp::default(),
            width: dim(rng),
            height: dim(rng),
            label_count: count(rng),
            _reserved: any_u32(rng),
        }
    }

    fn mutate(rng: &mut R, h: &mut RenderHeader) {
        match rng.gen_range(0..4) {
            0 => h.width = any_u32(rng),
            1 => h.height = any_u32(rng),
            2 => h.label_count = any_u32(rng),
            _ => h._reserved = any_u32(rng),
        }
    }

    fn layout(h: &RenderHeader) -> Option<usize> {
        fits(sec(pixels(h.width, h.height), 4) + sec(h.label_count as u128, 12))
    }

    fn valid(rng: &mut R) -> (RenderHeader, Payload) {
        let (w, hh) = (rng.gen_range(1..=12u32), rng.gen_range(1..=12u32));
        let n = (w * hh) as usize;
        let nl = rng.gen_range(0..8);
        let label_map: Vec<u32> = (0..n).map(|_| rng.gen_range(0..10)).collect();
        let labels: Vec<LabelCompleteness> = (0..nl)
            .map(|i| {
                let total = rng.gen_range(0..1000);
                LabelCompleteness {
                    label: i as u32,
                    visible: rng.gen_range(0..=total),
                    total,
                }
            })
            .collect();
        let h = RenderHeader::new(
            Stamp::new(MessageKind::Render, rng.gen(), rng.gen(), rng.gen()),
            w,
            hh,
            nl as u32,
        );
        let mut p = Payload::new(h.payload_len());
        h.encode(&label_map, &labels, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!((v.label_map, v.labels), (&label_map[..], &labels[..]));
        (h, p)
    }

    fn check(h: &RenderHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(
            (1..=MAX_IMAGE_SIDE).contains(&h.width) && (1..=MAX_IMAGE_SIDE).contains(&h.height)
        );
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        assert_eq!(v.label_map.len(), h.width as usize * h.height as usize);
        assert_eq!(v.labels.len(), h.label_count as usize);
        assert!(v.labels.iter().all(|c| c.visible <= c.total));
        let mut s = Sections::new(p);
        s.next(v.label_map);
        s.next(v.labels);
        true
    }
}

struct Consensus;
impl Target for Consensus {
    type H = ConsensusHeader;
    const KIND: MessageKind = MessageKind::Consensus;

    fn random(rng: &mut R) -> ConsensusHeader {
        ConsensusHeader {
            stamp: Stamp::default(),
            width: dim(rng),
            height: dim(rng),
            mapping_count: count(rng),
            relabel_count: count(rng),
            prune_count: count(rng),
            pixel_count: count(rng),
            counter_prune_scale: if rng.gen_bool(0.8) { 0.1 } else { any_f32(rng) },
            _reserved: any_u32(rng),
        }
    }

    fn mutate(rng: &mut R, h: &mut ConsensusHeader) {
        match rng.gen_range(0..8) {
            0 => h.width = any_u32(rng),
            1 => h.height = any_u32(rng),
            2 => h.mapping_count = any_u32(rng),
            3 => h.relabel_count = any_u32(rng),
            4 => h.prune_count = any_u32(rng),
            5 => h.pixel_count = any_u32(rng),
            6 => h.counter_prune_scale = any_f32(rng),
            _ => h._reserved = any_u32(rng),
        }
    }

    fn layout(h: &ConsensusHeader) -> Option<usize> {
        fits(
            sec(pixels(h.width, h.height), 4)
                + sec(h.mapping_count as u128, 8)
                + sec(h.relabel_count as u128, 20)
                + sec(h.prune_count as u128, 12)
                + sec(h.pixel_count as u128, 4),
        )
    }

    fn valid(rng: &mut R) -> (ConsensusHeader, Payload) {
        let (w, hh) = (rng.gen_range(1..=12u32), rng.gen_range(1..=12u32));
        let n = w * hh;
        let label_map: Vec<u32> = (0..n).map(|_| rng.gen_range(0..10)).collect();
        let mapping: Vec<[u32; 2]> = (0..rng.gen_range(0..6)).map(|_| rng.gen()).collect();
        let px = rng.gen_range(0..=2 * n);
        let pixels: Vec<u32> = (0..px).map(|_| rng.gen_range(0..n)).collect();
        let run = |rng: &mut R| {
            let offset = rng.gen_range(0..=px);
            (offset, rng.gen_range(0..=px - offset))
        };
        let relabels: Vec<PixelRun> = (0..rng.gen_range(0..5))
            .map(|_| {
                let (offset, count) = run(rng);
                PixelRun {
                    from: rng.gen(),
                    to: rng.gen(),
                    offset,
                    count,
                    scope: rng.gen_range(0..=1),
                }
            })
            .collect();
        let prunes: Vec<PruneRun> = (0..rng.gen_range(0..5))
            .map(|_| {
                let (offset, count) = run(rng);
                PruneRun {
                    label: rng.gen(),
                    offset,
                    count,
                }
            })
            .collect();
        let parts = ConsensusResult {
            label_map: &label_map,
            mapping: &mapping,
            relabels: &relabels,
            prunes: &prunes,
            pixels: &pixels,
        };
        let h = ConsensusHeader::new(
            Stamp::new(MessageKind::Consensus, rng.gen(), rng.gen(), rng.gen()),
            w,
            hh,
            rng.gen_range(0.001..10.0),
            &parts,
        );
        let mut p = Payload::new(h.payload_len());
        h.encode(&parts, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip").result;
        assert_eq!(
            (v.label_map, v.mapping, v.relabels, v.prunes, v.pixels),
            (
                &label_map[..],
                &mapping[..],
                &relabels[..],
                &prunes[..],
                &pixels[..]
            )
        );
        (h, p)
    }

    fn check(h: &ConsensusHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(
            (1..=MAX_IMAGE_SIDE).contains(&h.width) && (1..=MAX_IMAGE_SIDE).contains(&h.height)
        );
        assert!(h.counter_prune_scale.is_finite() && h.counter_prune_scale > 0.0);
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        let r = &v.result;
        let n = h.width as usize * h.height as usize;
        assert_eq!(r.label_map.len(), n);
        assert_eq!(r.mapping.len(), h.mapping_count as usize);
        assert_eq!(r.relabels.len(), h.relabel_count as usize);
        assert_eq!(r.prunes.len(), h.prune_count as usize);
        assert_eq!(r.pixels.len(), h.pixel_count as usize);
        // Every run can be sliced out of the pixel list and every pixel indexes the image.
        for (offset, count) in r
            .relabels
            .iter()
            .map(|x| (x.offset, x.count))
            .chain(r.prunes.iter().map(|x| (x.offset, x.count)))
        {
            let run = &r.pixels[offset as usize..offset as usize + count as usize];
            assert!(run.iter().all(|&px| (px as usize) < n));
        }
        assert!(r.pixels.iter().all(|&px| (px as usize) < n));
        assert!(r.relabels.iter().all(|x| x.scope <= PixelRun::SCOPE_REJOIN));
        let mut s = Sections::new(p);
        s.next(r.label_map);
        s.next(r.mapping);
        s.next(r.relabels);
        s.next(r.prunes);
        s.next(r.pixels);
        true
    }
}

struct MapTarget;
impl Target for MapTarget {
    type H = MapTargetHeader;
    const KIND: MessageKind = MessageKind::MapTarget;

    fn random(rng: &mut R) -> MapTargetHeader {
        MapTargetHeader {
            stamp: Stamp::default(),
            count: count(rng),
            map_version: any_u32(rng),
        }
    }

    fn mutate(rng: &mut R, h: &mut MapTargetHeader) {
        match rng.gen_range(0..2) {
            0 => h.count = any_u32(rng),
            _ => h.map_version = any_u32(rng),
        }
    }

    fn layout(h: &MapTargetHeader) -> Option<usize> {
        let n = h.count as u128;
        fits(sec(n, 12) + sec(n, 16) + sec(n, 12))
    }

    fn valid(rng: &mut R) -> (MapTargetHeader, Payload) {
        let n = rng.gen_range(0..40);
        let means: Vec<[f32; 3]> = (0..n).map(|_| rng.gen()).collect();
        let rotations: Vec<[f32; 4]> = (0..n).map(|_| rng.gen()).collect();
        let scales: Vec<[f32; 3]> = (0..n).map(|_| rng.gen()).collect();
        let h = MapTargetHeader::new(
            Stamp::new(MessageKind::MapTarget, rng.gen(), rng.gen(), rng.gen()),
            n as u32,
            rng.gen(),
        );
        let mut p = Payload::new(h.payload_len());
        let parts = MapTargetParts {
            means: &means,
            rotations: &rotations,
            scales: &scales,
        };
        h.encode(&parts, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!(
            (v.means, v.rotations, v.scales),
            (&means[..], &rotations[..], &scales[..])
        );
        (h, p)
    }

    fn check(h: &MapTargetHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(std::ptr::eq(v.header, h));
        assert!(h.count <= 20_000_000);
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        let n = h.count as usize;
        assert_eq!(
            (v.means.len(), v.rotations.len(), v.scales.len()),
            (n, n, n)
        );
        let mut s = Sections::new(p);
        s.next(v.means);
        s.next(v.rotations);
        s.next(v.scales);
        true
    }
}

struct Pose;
impl Target for Pose {
    type H = PoseHeader;
    const KIND: MessageKind = MessageKind::Pose;

    fn random(rng: &mut R) -> PoseHeader {
        PoseHeader {
            stamp: Stamp::default(),
            pose: std::array::from_fn(|_| {
                if rng.gen_bool(0.9) {
                    finite(rng)
                } else {
                    any_f64(rng)
                }
            }),
            gt_pose: std::array::from_fn(|_| {
                if rng.gen_bool(0.9) {
                    finite(rng)
                } else {
                    any_f64(rng)
                }
            }),
            has_gt: count(rng) % 3,
            status: count(rng),
            is_keyframe: count(rng),
            iterations: any_u32(rng),
            inliers: any_u32(rng),
            overlap: if rng.gen_bool(0.7) {
                rng.gen()
            } else {
                any_f32(rng)
            },
        }
    }

    fn mutate(rng: &mut R, h: &mut PoseHeader) {
        match rng.gen_range(0..6) {
            0 => h.pose[rng.gen_range(0..7)] = any_f64(rng),
            1 => h.gt_pose[rng.gen_range(0..7)] = any_f64(rng),
            2 => h.has_gt = any_u32(rng),
            3 => h.status = any_u32(rng),
            4 => h.overlap = any_f32(rng),
            _ => h.inliers = any_u32(rng),
        }
    }

    fn layout(_: &PoseHeader) -> Option<usize> {
        Some(0)
    }

    fn valid(rng: &mut R) -> (PoseHeader, Payload) {
        let h = PoseHeader {
            stamp: Stamp::new(MessageKind::Pose, rng.gen(), rng.gen(), rng.gen()),
            pose: std::array::from_fn(|_| finite(rng)),
            gt_pose: std::array::from_fn(|_| finite(rng)),
            has_gt: rng.gen_range(0..2),
            status: rng.gen_range(0..6),
            is_keyframe: rng.gen_range(0..2),
            iterations: rng.gen_range(0..50),
            inliers: rng.gen(),
            overlap: rng.gen_range(0.0..=1.0),
        };
        (h, Payload::new(0))
    }

    fn check(h: &PoseHeader, p: &[u8]) -> bool {
        let Ok(status) = h.decode(p) else {
            return false;
        };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(p.is_empty());
        assert_eq!(status as u32, h.status);
        assert!(h.pose.iter().all(|v| v.is_finite()));
        assert!(h.has_gt == 0 || h.gt_pose.iter().all(|v| v.is_finite()));
        assert!((0.0..=1.0).contains(&h.overlap));
        true
    }
}

fn random_stage(rng: &mut R) -> StageName {
    let mut name = [0u8; 16];
    match rng.gen_range(0..5) {
        0 => rng.fill(&mut name[..]),
        1 => {}
        2 => {
            // A multi-byte character cut at the 16-byte boundary: not UTF-8.
            let s = "trackerüüüüü".as_bytes();
            name.copy_from_slice(&s[..16]);
        }
        _ => {
            let s = pick(
                rng,
                &["sensor", "tracker", "mapper", "segmenter", "consensus"],
            );
            name[..s.len()].copy_from_slice(s.as_bytes());
        }
    }
    name
}

struct Telemetry;
impl Target for Telemetry {
    type H = TelemetryHeader;
    const KIND: MessageKind = MessageKind::Telemetry;

    fn random(rng: &mut R) -> TelemetryHeader {
        TelemetryHeader {
            stamp: Stamp::default(),
            stage: random_stage(rng),
            event: count(rng),
            pid: rng.gen(),
            input_sent_ns: any_u64(rng),
            start_ns: any_u64(rng),
            end_ns: any_u64(rng),
            work_done: count(rng),
            work_total: count(rng),
        }
    }

    fn mutate(rng: &mut R, h: &mut TelemetryHeader) {
        match rng.gen_range(0..7) {
            0 => h.stage = random_stage(rng),
            1 => h.event = any_u32(rng) % 8,
            2 => h.input_sent_ns = any_u64(rng),
            3 => h.start_ns = any_u64(rng),
            4 => h.end_ns = any_u64(rng),
            5 => h.work_done = any_u32(rng),
            _ => h.work_total = any_u32(rng),
        }
    }

    fn layout(_: &TelemetryHeader) -> Option<usize> {
        Some(0)
    }

    fn valid(rng: &mut R) -> (TelemetryHeader, Payload) {
        let stage = pick(
            rng,
            &["sensor", "tracker", "mapper", "a-stage-name-past-16-bytes"],
        );
        let h = if rng.gen_bool(0.2) {
            let total = rng.gen_range(0..100);
            TelemetryHeader::progress(stage, rng.gen_range(0..=total), total, rng.gen())
        } else {
            let event = TelemetryEvent::from_u32(rng.gen_range(1..=6)).expect("event");
            let sent = rng.gen_range(0..u64::MAX / 4);
            let start = sent + rng.gen_range(0..u64::MAX / 4);
            let end = start + rng.gen_range(0..u64::MAX / 4);
            let input = Stamp::new(MessageKind::Frame, rng.gen(), rng.gen(), rng.gen());
            TelemetryHeader::new(stage, event, &input, sent, start, end)
        };
        (h, Payload::new(0))
    }

    fn check(h: &TelemetryHeader, p: &[u8]) -> bool {
        let Ok(event) = h.decode(p) else {
            return false;
        };
        check_stamp(&h.stamp, Self::KIND, p);
        assert!(p.is_empty());
        assert_eq!(event as u32, h.event);
        assert!(h.stage[0] != 0 && std::str::from_utf8(&h.stage).is_ok());
        assert_ne!(h.stage_name(), "");
        if event == TelemetryEvent::Processed {
            assert!(h.input_sent_ns <= h.start_ns && h.start_ns <= h.end_ns);
        }
        if event == TelemetryEvent::Progress {
            assert!(h.work_done <= h.work_total);
        }
        true
    }
}

struct Control;
impl Target for Control {
    type H = ControlHeader;
    const KIND: MessageKind = MessageKind::Control;

    fn random(rng: &mut R) -> ControlHeader {
        ControlHeader {
            stamp: Stamp::default(),
            command: if rng.gen_bool(0.7) {
                pick(rng, &[1, 2, 3, 100])
            } else {
                any_u32(rng)
            },
            ok: any_u32(rng),
            request_id: rng.gen(),
            text_len: if rng.gen_bool(0.6) {
                rng.gen_range(0..64)
            } else {
                any_u64(rng)
            },
        }
    }

    fn mutate(rng: &mut R, h: &mut ControlHeader) {
        match rng.gen_range(0..4) {
            0 => h.command = any_u32(rng),
            1 => h.ok = any_u32(rng),
            2 => h.request_id = any_u64(rng),
            _ => {
                h.text_len = match rng.gen_range(0..3) {
                    0 => h.text_len.wrapping_add(1),
                    1 => h.text_len.wrapping_sub(1),
                    _ => any_u64(rng),
                }
            }
        }
    }

    fn layout(h: &ControlHeader) -> Option<usize> {
        fits(sec(h.text_len as u128, 1))
    }

    fn valid(rng: &mut R) -> (ControlHeader, Payload) {
        let pieces = [
            "segmenter",
            " ",
            "prior",
            "{\"ok\":true}",
            "ü",
            "椅子",
            "🦀",
            "\n",
        ];
        let text: String = (0..rng.gen_range(0..12))
            .map(|_| pick(rng, &pieces))
            .collect();
        let command = pick(
            rng,
            &[
                ControlCommand::Status,
                ControlCommand::Stop,
                ControlCommand::Swap,
                ControlCommand::Scale,
                ControlCommand::Reply,
            ],
        );
        let h = ControlHeader::new(command, rng.gen(), rng.gen(), &text);
        let mut p = Payload::new(h.payload_len());
        h.encode(&text, as_uninit_mut(p.bytes_mut()))
            .expect("encode");
        let v = h.decode(p.bytes()).expect("round trip");
        assert_eq!((v.command, v.text), (command, &text[..]));
        (h, p)
    }

    fn check(h: &ControlHeader, p: &[u8]) -> bool {
        let Ok(v) = h.decode(p) else { return false };
        check_stamp(&h.stamp, Self::KIND, p);
        assert_eq!(v.command as u32, h.command);
        assert_eq!(v.ok, h.ok != 0);
        assert_eq!(v.request_id, h.request_id);
        assert_eq!(v.text.len() as u64, h.text_len);
        assert_eq!(p.len(), Self::layout(h).expect("layout"));
        Sections::new(p).next(v.text.as_bytes());
        true
    }
}

/// Found by `fuzz_consensus_decode`: 64·W·H overflowed u32 at 8192×8192 (panic, or bound 0).
#[test]
fn consensus_pixel_bound_of_the_largest_image_does_not_overflow() {
    let parts = ConsensusResult {
        label_map: &[],
        mapping: &[],
        relabels: &[],
        prunes: &[],
        pixels: &[],
    };
    let mut h = ConsensusHeader::new(
        Stamp::new(MessageKind::Consensus, 1, 0, 0),
        MAX_IMAGE_SIDE,
        MAX_IMAGE_SIDE,
        0.1,
        &parts,
    );
    h.pixel_count = 1;
    h.stamp.payload_len = 0;
    // Refused for its (absent) payload, not for its pixel count.
    assert!(matches!(
        h.decode(&[]),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    h.pixel_count = u32::MAX;
    assert!(matches!(
        h.decode(&[]),
        Err(SchemaError::LayoutMismatch { .. })
    ));
}

/// One input of the network link (`from_wire`) carrying target `T`: an encoded message as
/// wire bytes, then bits flipped, bytes overwritten, cut or extended anywhere (header
/// included). `from_wire` never panics, and accepts only what `decode` accepts.
fn wire_case<T: Target>(rng: &mut R) -> bool
where
    T::H: WireMessage,
{
    let (h, p) = T::valid(rng);
    let mut bytes = to_wire(&h, p.bytes());
    for _ in 0..rng.gen_range(0..=4) {
        match rng.gen_range(0..4) {
            0 if !bytes.is_empty() => {
                let i = rng.gen_range(0..bytes.len());
                bytes[i] ^= 1 << rng.gen_range(0..8);
            }
            1 if bytes.len() >= 8 => {
                let i = rng.gen_range(0..bytes.len() / 8) * 8;
                bytes[i..i + 8].copy_from_slice(&any_u64(rng).to_ne_bytes());
            }
            2 => {
                let len = rng.gen_range(0..=bytes.len());
                bytes.truncate(len);
            }
            _ => bytes.extend((0..rng.gen_range(1..64)).map(|_| rng.gen::<u8>())),
        }
    }
    match from_wire::<T::H>(&bytes) {
        Ok(m) => {
            assert!(
                T::check(&m.header, m.payload()),
                "from_wire accepted what decode refuses"
            );
            true
        }
        Err(_) => false,
    }
}

#[test]
fn fuzz_from_wire() {
    fuzz(
        "from_wire (network link), every message kind",
        |rng| match rng.gen_range(0..9) {
            0 => wire_case::<Frame>(rng),
            1 => wire_case::<Keyframe>(rng),
            2 => wire_case::<Segments>(rng),
            3 => wire_case::<Render>(rng),
            4 => wire_case::<Consensus>(rng),
            5 => wire_case::<MapTarget>(rng),
            6 => wire_case::<Pose>(rng),
            7 => wire_case::<Telemetry>(rng),
            _ => wire_case::<Control>(rng),
        },
    );
}

#[test]
fn fuzz_frame_decode() {
    fuzz("FrameHeader::decode", case::<Frame>);
}

#[test]
fn fuzz_keyframe_decode() {
    fuzz("KeyframeHeader::decode", case::<Keyframe>);
}

#[test]
fn fuzz_segments_decode() {
    fuzz("SegmentsHeader::decode", case::<Segments>);
}

#[test]
fn fuzz_render_decode() {
    fuzz("RenderHeader::decode", case::<Render>);
}

#[test]
fn fuzz_consensus_decode() {
    fuzz("ConsensusHeader::decode", case::<Consensus>);
}

#[test]
fn fuzz_map_target_decode() {
    fuzz("MapTargetHeader::decode", case::<MapTarget>);
}

#[test]
fn fuzz_pose_decode() {
    fuzz("PoseHeader::decode", case::<Pose>);
}

#[test]
fn fuzz_telemetry_decode() {
    fuzz("TelemetryHeader::decode", case::<Telemetry>);
}

#[test]
fn fuzz_control_decode() {
    fuzz("ControlHeader::decode", case::<Control>);
}
