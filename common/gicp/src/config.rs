/// Which non-linear least-squares solver runs on SE(3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Solver {
    /// Solve `H δ = −b` and take the step.
    #[default]
    GaussNewton,
    /// Solve `(H + λI) δ = −b`; accept steps that lower the error, adapting λ.
    LevenbergMarquardt,
}

/// Registration settings. Defaults are docs/METHOD.md §7's TUM-size values;
/// [`RegistrationConfig::replica`] gives the Replica-size ones.
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationConfig {
    pub solver: Solver,
    /// Correspondences farther apart than this (metres) are ignored: 0.03 TUM, 0.02 Replica.
    pub max_correspondence_distance: f64,
    /// Upper bound on solver iterations (64).
    pub max_iterations: usize,
    /// Stop when the update's rotation is below this (radians, 2e-3) …
    pub rotation_epsilon: f64,
    /// … and its translation below this (metres, 1e-3: the method says 5e-4, docs/METHOD.md §7).
    /// Under depth noise the steps jitter by about a millimetre as correspondences flip, so
    /// this also sets how long a noisy frame iterates; 2e-3 cut the median from 7 to 5 fine
    /// iterations but raised the position error 0.45 → 0.71 cm (scene 1 along fr2_desk with
    /// noise, `opengs bench track`; scene 3: 0.38 → 0.44 cm).
    pub translation_epsilon: f64,
    /// Squared distance (m²) under which a source point counts as overlapping
    /// the target, for the keyframe rule: 1e-3 TUM, 5e-4 Replica.
    pub overlapped_th: f64,
    /// Fewer inlier correspondences than this is an error (3 fix a pose).
    pub min_correspondences: usize,
    /// Levenberg-Marquardt: initial damping λ (1e-3, as small_gicp).
    pub lm_initial_lambda: f64,
    /// Levenberg-Marquardt: λ is multiplied/divided by this (10).
    pub lm_lambda_factor: f64,
    /// Levenberg-Marquardt: attempts per iteration before giving up (10).
    pub lm_max_inner_iterations: usize,
    /// `H` whose smallest/largest eigenvalue ratio is below this is rank-deficient.
    pub degeneracy_ratio: f64,
    /// Turn the source about its own origin only (the camera centre stays): for a start
    /// whose translation is good and whose rotation is not.
    pub rotation_only: bool,
    /// Stop once the estimate has moved farther than this from the start (m, rad; ∞:
    /// never): a caller that rejects such answers anyway need not wait for them to settle.
    pub leash_metres: f64,
    pub leash_radians: f64,
}

impl Default for RegistrationConfig {
    fn default() -> Self {
        Self::tum()
    }
}

impl RegistrationConfig {
    /// TUM-size images (docs/METHOD.md §7). Correspondences up to 2 cm, not GS-ICP SLAM's
    /// 3 cm: under Kinect noise 3 cm pairs a thin object's newly seen face with the face
    /// the model holds 2.5–4 cm behind it, and the frame slides by that much.
    pub fn tum() -> Self {
        Self {
            solver: Solver::GaussNewton,
            max_correspondence_distance: 0.02,
            max_iterations: 64,
            rotation_epsilon: 2e-3,
            translation_epsilon: 1e-3,
            overlapped_th: 1e-3,
            min_correspondences: 3,
            lm_initial_lambda: 1e-3,
            lm_lambda_factor: 10.0,
            lm_max_inner_iterations: 10,
            degeneracy_ratio: 1e-10,
            rotation_only: false,
            leash_metres: f64::INFINITY,
            leash_radians: f64::INFINITY,
        }
    }

    /// Replica-size images (docs/METHOD.md §7).
    pub fn replica() -> Self {
        Self {
            max_correspondence_distance: 0.02,
            overlapped_th: 5e-4,
            ..Self::tum()
        }
    }
}
