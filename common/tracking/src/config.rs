use opengs_gicp::{CoarseToFine, RegistrationConfig, Regularization, DEFAULT_NEIGHBOURS};

use crate::{RelocaliseConfig, VerifyConfig};

/// Tracker settings; defaults are docs/METHOD.md §7's TUM-size values.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// Depth sampling stride in pixels (5 TUM-size, 10 Replica-size).
    pub stride: usize,
    /// Neighbours per covariance (10).
    pub neighbours: usize,
    /// How registration regularises covariances, the frame's and the map's: small_gicp's
    /// thin disc (`Plane`). Under depth noise the kept ellipse is rounder, its in-plane pull
    /// slides the fine registration along weakly constrained directions for many ~1 mm
    /// steps; the disc converges in fewer iterations (docs/METHOD.md §7).
    pub regularization: Regularization,
    /// The shape keyframe covariances carry to the mapper, which seeds its Gaussians with it
    /// (GS-ICP SLAM's shared covariances): the ellipse keeps an edge's elongation that a
    /// disc loses (half a dB of PSNR on the scene suite).
    pub keyframe_shape: Regularization,
    /// The fine registration (docs/METHOD.md §7) …
    pub registration: RegistrationConfig,
    /// … and the wide stages run before it.
    pub coarse_to_fine: CoarseToFine,
    /// After a gap longer than this (s) between frames, the coarse-to-fine search runs
    /// even when the fine registration from the prediction verifies (a quarter second
    /// is 7 dropped frames at 30 Hz: fr2_desk's gaps of 1.7–2.2 s move the camera 26–39 cm).
    pub wide_search_after_s: f64,
    /// When the fine registration from the prediction slides farther than
    /// `fast_path_offset`, the same from the prediction turned about the camera centre
    /// first ([`CoarseToFine::turn_first`]; fr2_desk's gap region, scenes 1–6, fine
    /// registration alone: 33 of 34 wide searches on clean frames and about half of 91
    /// with noise were answers that slid 4–9 cm from a prediction whose rotation was 1–2°
    /// off). Not first on every frame: that cost every frame 1–2 ms (median 9.4 → 11.2 ms
    /// clean) for no fewer wide searches (66 against 63 with noise).
    pub turned: CoarseToFine,
    /// A registration from the prediction that lands farther than this (m) from it
    /// takes the wide search too (fr2_desk, scene 1: 90 % land within 7 mm clean and 14 mm
    /// with noise; a slide into the neighbouring minimum moved 4 cm).
    pub fast_path_offset: f64,
    /// … or, the fine attempt, turned farther than this (rad) from it (on fr2_desk's truth
    /// with the velocity over 0.1 s, right answers turn up to 3.3° from the prediction).
    pub fast_path_turn: f64,
    /// A fine answer farther than this (m) from the prediction, though within
    /// `fast_path_offset`, is compared with the turned one; the better fitness wins.
    pub fast_path_sure: f64,
    /// Fine iterations from the prediction (fr2_desk with noise, scenes 1, 3, 5: 1194 of
    /// 1197 converged within 29; the 3 others slid on to the cap of 64, 90 ms each, far
    /// from the prediction).
    pub fast_iterations: usize,
    /// A wide search's answer is polished by fine restarts this far (m) along each camera
    /// axis (0: none).
    pub restart_step: f64,
    /// Fine iterations of a wide search's registrations and of a polishing restart.
    pub wide_iterations: usize,
    pub polish_iterations: usize,
    /// The wide search's registrations use a source thinned to one point per voxel of this
    /// side (m; 0: every point); only the winner is refined with every point. They are
    /// exploratory, and at full size they cost a gap frame 200+ ms.
    pub wide_source_voxel: f64,
    /// The polishing restarts register a source thinned further, to one point per voxel of
    /// this side (m): they only choose a basin, and the winner is refined with every point.
    /// 10 cm (about 1000 points at 2 m) against 6 cm (about 2900): the same position error
    /// on fr2_desk's gap region, scenes 1–6 clean (within 0.001 cm) and with noise (within
    /// the run-to-run spread), the median wide-search frame 3–6 ms faster clean.
    pub restart_source_voxel: f64,
    /// What a registration must satisfy to be trusted.
    pub verify: VerifyConfig,
    pub relocalise: RelocaliseConfig,
    /// A frame whose overlap with the target drops below this is a tracking keyframe (0.81 TUM, 0.7 Replica).
    pub keyframe_overlap: f64,
    /// A mapping keyframe at least every this many frames (10).
    pub keyframe_every: u64,
    /// Depth beyond this (m) is ignored.
    pub max_depth: f64,
    /// Samples farther than this (m) weigh less in registration, as depth⁻⁴ (their noise
    /// grows with depth², [`crate::depth_scale`]), down to their weight at
    /// `depth_weight_until`; 0: all the same. Chosen on scene 2 along fr2_desk with noise
    /// (1 m against 1.5 and 2 m; depth⁻⁴ against depth⁻²), shown on the other rows
    /// (`README.md`, issue 17).
    pub depth_weight_from: f64,
    /// Beyond this depth (m) the weight falls no further: far walls still fix what a near
    /// plane leaves free. Without it (falling as depth⁻⁴ to 5 m), scene 2's fr2_desk path
    /// clean, tracker alone: a frame after a 1.9 s gap 16.7 cm off, two 2 cm off, position
    /// error 0.845 cm (0.016 unweighted); with 2 m, 0.073 cm.
    pub depth_weight_until: f64,
    /// Fewer valid samples than this and the frame is lost.
    pub min_points: usize,
    /// A start stands once this many frames after it are verified (a third of a second at
    /// 30 Hz); until then a lost frame starts tracking again ([`crate::FrameTracker::keep_start`]):
    /// a few views are a map a camera that moved on rarely comes back to. What the frames
    /// since the start saw is held back from the map meanwhile, so the fewer the better
    /// (`opengs bench slam --quick`, scene 1's loop, a second held: PSNR 17.9–19.1 against
    /// 19.7–20.2 dB, mIoU 88.8–90.6 against 92.9–93.4).
    pub start_stands_after: u64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self::tum()
    }
}

impl TrackerConfig {
    pub fn tum() -> Self {
        Self {
            stride: 5,
            neighbours: DEFAULT_NEIGHBOURS,
            regularization: Regularization::Plane,
            keyframe_shape: Regularization::NormalizedEllipse,
            registration: RegistrationConfig::tum(),
            coarse_to_fine: CoarseToFine::default(),
            wide_search_after_s: 0.25,
            restart_step: 0.03,
            wide_iterations: 30,
            polish_iterations: 10,
            wide_source_voxel: 0.03,
            restart_source_voxel: 0.1,
            turned: CoarseToFine::turn_first(),
            fast_path_offset: 0.025,
            fast_path_turn: 4f64.to_radians(),
            fast_path_sure: 0.015,
            fast_iterations: 30,
            verify: VerifyConfig::default(),
            relocalise: RelocaliseConfig::default(),
            keyframe_overlap: 0.81,
            keyframe_every: 10,
            max_depth: 5.0,
            depth_weight_from: 1.0,
            depth_weight_until: 2.0,
            min_points: 200,
            start_stands_after: 10,
        }
    }

    pub fn replica() -> Self {
        Self {
            stride: 10,
            registration: RegistrationConfig::replica(),
            keyframe_overlap: 0.7,
            ..Self::tum()
        }
    }

    /// TUM-size settings below 1000 px wide, Replica-size above.
    pub fn for_width(width: u32) -> Self {
        if width >= 1000 {
            Self::replica()
        } else {
            Self::tum()
        }
    }
}
