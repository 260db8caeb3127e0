//! One registration attempt against a model and its verification: the stages and
//! iteration cap each kind of attempt gets, the checks it must pass, and the
//! screening of relocalisation guesses. Plain functions of a model and the settings,
//! so the tracker and the relocalisation thread ([`crate::relocalise_worker`]) run the
//! same code.

use opengs_geometry::nalgebra::Point3;
use opengs_geometry::Pose;
use opengs_gicp::{
    coarse_estimate, register_coarse_to_fine, register_global, Cloud, CoarseToFine, FeatureCloud,
    Registration, RegistrationConfig,
};

use crate::ambiguity::{choose, describe_settled, restarts, surface_fitness, Scored};
use crate::model::TrackingModel;
use crate::motion::MAX_EXTRAPOLATION_S;
use crate::verify::{verify, verify_visibility, MotionPrior, Rejection, VerifyConfig};
use crate::visibility::check_visibility;
use crate::{DepthFrame, TrackerConfig};

/// What a registration is for: its stages, iteration cap and checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Attempt {
    /// The fine registration from the prediction (most frames).
    Fast,
    /// A turn about the camera centre, then the fine registration, from the prediction:
    /// when the fast answer failed or slid more than `fast_path_offset` from the prediction.
    Turned,
    /// Coarse-to-fine, after a gap or a failed fast attempt.
    Wide,
    /// A fine restart near a wide search's answer.
    Polish,
    /// The fine registration from a screened relocalisation guess (stricter checks).
    Relocalise,
    /// The fine registration from a global registration's hypothesis (its own checks).
    Global,
}

/// A registration that passed (or failed) verification.
pub(crate) type Verified = Result<Registration, String>;

/// A relocalised pose and how it was found (for the log: which start, how it was settled).
pub(crate) struct Found {
    pub registration: Registration,
    pub how: String,
}

/// The checks a registration must pass: relocalisation's stricter ones when no motion
/// prior vouches for the answer, as after a gap beyond the motion model's horizon (scene 2
/// along fr2_desk with noise, in the pipeline: a frame after a 1.9 s gap passed tracking's
/// checks 33–39 cm from the truth, the whole run's ATE 1.7–2.0 cm instead of 0.4–0.5).
fn checks_for<'c>(
    kind: Attempt,
    prior: Option<&MotionPrior>,
    config: &'c TrackerConfig,
) -> &'c VerifyConfig {
    let unpredicted = prior.is_none_or(|p| p.seconds > MAX_EXTRAPOLATION_S);
    match kind {
        Attempt::Relocalise => &config.relocalise.verify,
        Attempt::Global => &config.relocalise.global_verify,
        _ if unpredicted => &config.relocalise.verify,
        _ => &config.verify,
    }
}

/// Registration of `kind` from `guess`, then verification: the statistics, the motion
/// prior, and what the frame sees of the model ([`crate::visibility`]).
pub(crate) fn register_verified(
    model: &TrackingModel,
    c: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    guess: &Pose,
    kind: Attempt,
    prior: Option<&MotionPrior>,
) -> Verified {
    // The exception paths are capped: a slow frame drops the next ones, whose gap
    // calls the wide search again. The fast attempt registers every point from the start: a
    // first pass on a source thinned to 3–6 cm voxels cut its full-size iterations (median 7 →
    // 2–4) but not its time (scene 2 along fr2_desk with noise: p50 29.7–35.6 → 25.8–34.1 ms,
    // within the machine's spread, and 6–8 → 8–9 wide searches).
    let (schedule, iterations) = match kind {
        Attempt::Fast => (CoarseToFine::fine_only(), c.fast_iterations),
        Attempt::Turned => (c.turned.clone(), c.fast_iterations),
        Attempt::Wide => (c.coarse_to_fine.clone(), c.wide_iterations),
        Attempt::Polish => (CoarseToFine::fine_only(), c.polish_iterations),
        Attempt::Relocalise | Attempt::Global => {
            (CoarseToFine::fine_only(), c.relocalise.fine_iterations)
        }
    };
    // An attempt from the prediction stops as soon as it has slid (see `landing`)
    // instead of sliding on to its iteration cap (fr2_desk with noise, two runs each:
    // the slowest frame of scenes 1, 3, 4 and 5 69-140 -> 49-86 ms).
    let (leash_metres, leash_radians) = match kind {
        Attempt::Fast => (c.fast_path_offset, c.fast_path_turn),
        Attempt::Turned => (c.fast_path_offset, f64::INFINITY),
        _ => (f64::INFINITY, f64::INFINITY),
    };
    let fine = RegistrationConfig {
        max_iterations: iterations,
        leash_metres,
        leash_radians,
        ..c.registration.clone()
    };
    let r = register_coarse_to_fine(cloud, model.target(), guess, &fine, &schedule)
        .map_err(|e| e.to_string())?;
    let checks = checks_for(kind, prior, c);
    verify(&r, prior, checks).map_err(|e: Rejection| e.to_string())?;
    let seen = check_visibility(
        model.target().coarse().points(),
        &r.transform,
        frame,
        &checks.visibility_margin,
    );
    verify_visibility(&seen, checks).map_err(|e| e.to_string())?;
    Ok(r)
}

/// The coarse stages from a relocalisation guess, and a look at what the frame would
/// see of the model from there: most guesses are far off, and end here for a few
/// milliseconds instead of a full registration. `None` when the estimate is hopeless.
fn screen_guess(
    model: &TrackingModel,
    config: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    guess: &Pose,
) -> Option<Pose> {
    let checks = &config.relocalise.verify;
    let estimate = coarse_estimate(
        cloud,
        model.target(),
        guess,
        &config.registration,
        &config.coarse_to_fine,
    );
    let seen = check_visibility(
        model.target().coarse().points(),
        &estimate,
        frame,
        &checks.visibility_margin,
    );
    (seen.violation_ratio() <= config.relocalise.screen_violation).then_some(estimate)
}

/// Relocalisation guesses, each screened, then registered and verified without a motion
/// prior: the first that verifies; failing that, with `viewpoints` (where the keyframes
/// were taken), the hypotheses of global registration ([`try_global`]); or why the last
/// one failed. With `viewpoints` (from a spell's second attempt on) an answer is settled
/// ([`settle`]) before it is taken.
pub(crate) fn try_guesses(
    model: &TrackingModel,
    config: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    guesses: &[Pose],
    viewpoints: Option<&[Point3<f64>]>,
) -> Result<Found, String> {
    let mut last_failure = String::from("no relocalisation guesses");
    for guess in guesses {
        let Some(start) = screen_guess(model, config, frame, cloud, guess) else {
            last_failure = "the coarse alignment sees through the model".into();
            continue;
        };
        let found = register_verified(
            model,
            config,
            frame,
            cloud,
            &start,
            Attempt::Relocalise,
            None,
        );
        // The spell's first attempt (the last verified pose, most often one frame after a
        // gap) is taken as it is; later ones may have landed anywhere.
        let found = found.and_then(|registration| {
            let d = guess.inverse() * registration.transform;
            let how = format!(
                "a guess {:.1} cm and {:.1}° away",
                d.translation.vector.norm() * 100.0,
                d.rotation.angle().to_degrees()
            );
            match viewpoints {
                Some(_) => settle(
                    model,
                    config,
                    frame,
                    cloud,
                    registration,
                    Attempt::Relocalise,
                )
                .map(|(registration, settled)| Found {
                    registration,
                    how: format!("{how}, {settled}"),
                }),
                None => Ok(Found { registration, how }),
            }
        });
        match found {
            Ok(found) => return Ok(found),
            Err(why) => last_failure = why,
        }
    }
    match viewpoints {
        Some(v) => try_global(model, config, frame, cloud, v)
            .map_err(|why| format!("{last_failure}; global registration: {why}")),
        None => Err(last_failure),
    }
}

/// Global registration of the frame against the model; each hypothesis registered
/// finely from where it lies and from its coarse alignment (half the view unmapped, one
/// of the two often stops a few centimetres off: scene 5 after the teleport, 3.6 cm at
/// fitness 0.66 against 0.08 cm at 0.68), then verified: the verified result with the
/// best fitness.
fn try_global(
    model: &TrackingModel,
    config: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    viewpoints: &[Point3<f64>],
) -> Result<Found, String> {
    let global = &config.relocalise.global;
    let target = model.features(viewpoints, global);
    let source = FeatureCloud::new(cloud, |_| Point3::origin(), global);
    let hypotheses = register_global(&source, target, global);
    let mut best: Option<Registration> = None;
    let mut last_failure = String::from("no hypothesis");
    for h in &hypotheses {
        let coarse = coarse_estimate(
            cloud,
            model.target(),
            &h.transform,
            &config.registration,
            &config.coarse_to_fine,
        );
        for start in [h.transform, coarse] {
            match register_verified(model, config, frame, cloud, &start, Attempt::Global, None) {
                Ok(r) if best.as_ref().is_none_or(|b| r.fitness > b.fitness) => best = Some(r),
                Ok(_) => {}
                Err(why) => last_failure = why,
            }
        }
    }
    let count = hypotheses.len();
    match best {
        Some(r) => settle(model, config, frame, cloud, r, Attempt::Global).map(
            |(registration, settled)| Found {
                registration,
                how: format!(
                    "global registration ({count} hypothes{}), {settled}",
                    if count == 1 { "is" } else { "es" }
                ),
            },
        ),
        None => Err(last_failure),
    }
}

/// A relocalised pose settled ([`crate::ambiguity`]): fine restarts a step either way
/// along its two weakest translations, every verified result scored by the share of the
/// frame lying on the model's surfaces; the best and how it won, or `Err` when the view
/// does not choose.
fn settle(
    model: &TrackingModel,
    config: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    found: Registration,
    kind: Attempt,
) -> Result<(Registration, String), String> {
    let settling = &config.relocalise.settle;
    if settling.step <= 0.0 {
        return Ok((found, "not settled".into()));
    }
    let target = model.target().fine();
    let reach = config.registration.max_correspondence_distance;
    let score = |pose: &Pose| surface_fitness(target, cloud, pose, reach, settling.tolerance);
    let starts = restarts(&found.transform, &found.hessian, settling.step);
    let mut results = vec![found];
    for start in starts {
        if let Ok(r) = register_verified(model, config, frame, cloud, &start, kind, None) {
            results.push(r);
        }
    }
    let scored: Vec<Scored> = results
        .iter()
        .map(|r| Scored {
            pose: r.transform,
            score: score(&r.transform),
        })
        .collect();
    match choose(&scored, settling) {
        Some(Ok(best)) => {
            let how = describe_settled(&scored, best, settling);
            Ok((results.swap_remove(best), how))
        }
        Some(Err(why)) => Err(why),
        None => Err("no result to settle".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelBuilder;
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion};
    use opengs_gicp::synthetic::{tum_camera, RoomScene, DEPTH_UNITS_PER_METRE};
    use opengs_gicp::Regularization;
    use opengs_gicp::{estimate_covariances_on_grid, regularize, sample_depth_grid};

    /// The view from the origin (looking along +z, y down) of `scene`: the frame's depth,
    /// its cloud, and a model made of that same cloud.
    fn view(scene: &RoomScene) -> (Vec<u16>, Cloud, TrackingModel) {
        let c = TrackerConfig::tum();
        let k = tum_camera();
        let depth = scene.render_depth(&k, &Pose::identity(), DEPTH_UNITS_PER_METRE);
        let samples =
            sample_depth_grid(&depth, DEPTH_UNITS_PER_METRE, &k, c.stride, c.max_depth).unwrap();
        let raw =
            estimate_covariances_on_grid(&samples, c.neighbours, Regularization::None).unwrap();
        let cloud = Cloud {
            covariances: raw
                .iter()
                .map(|m| regularize(m, c.regularization))
                .collect(),
            points: samples.points,
        };
        let mut builder = ModelBuilder::inline(c.coarse_to_fine.coarse_voxel);
        builder.add_keyframe(0, cloud.clone());
        let model = builder.finished().pop().unwrap().unwrap();
        (depth, cloud, model)
    }

    /// Registration from 2 cm along x off the truth, then settled.
    fn settled_from_aside(scene: &RoomScene) -> Verified {
        let c = TrackerConfig::tum();
        let k = tum_camera();
        let (depth, cloud, model) = view(scene);
        let frame = DepthFrame {
            depth: &depth,
            depth_scale: DEPTH_UNITS_PER_METRE,
            intrinsics: &k,
            timestamp: 0.0,
        };
        let aside = Pose::from_parts(
            Translation3::new(0.02, 0.0, 0.0),
            UnitQuaternion::identity(),
        );
        let found = register_verified(&model, &c, &frame, &cloud, &aside, Attempt::Global, None)?;
        settle(&model, &c, &frame, &cloud, found, Attempt::Global).map(|(r, _)| r)
    }

    #[test]
    fn a_pose_the_view_leaves_free_to_slide_is_refused_a_fixed_one_settles() {
        // A room 100 m wide: the back wall, floor and ceiling leave x free.
        let hall = RoomScene {
            room_min: [-50.0, -1.3, -1.0].into(),
            room_max: [50.0, 1.2, 4.0].into(),
            cuboids: Vec::new(),
            spheres: Vec::new(),
        };
        let why = settled_from_aside(&hall).unwrap_err();
        assert!(why.contains("does not fix the pose"), "{why}");
        // The furnished room: the restarts come back, the truth is found.
        let r = settled_from_aside(&RoomScene::default()).unwrap();
        let off = r.transform.translation.vector.norm();
        assert!(off < 0.002, "{:.2} cm off", off * 100.0);
    }

    #[test]
    fn a_frame_beyond_the_motion_horizon_is_checked_as_a_relocalisation() {
        let c = TrackerConfig::tum();
        let after = |seconds| MotionPrior {
            predicted: Pose::identity(),
            seconds,
        };
        let strict = &c.relocalise.verify;
        assert!(strict.min_fitness > c.verify.min_fitness);
        assert!(strict.max_violation < c.verify.max_violation);
        assert_eq!(checks_for(Attempt::Wide, Some(&after(0.2)), &c), &c.verify);
        assert_eq!(
            checks_for(Attempt::Fast, Some(&after(0.033)), &c),
            &c.verify
        );
        assert_eq!(checks_for(Attempt::Wide, Some(&after(1.9)), &c), strict);
        assert_eq!(checks_for(Attempt::Polish, Some(&after(1.9)), &c), strict);
        assert_eq!(checks_for(Attempt::Relocalise, None, &c), strict);
        assert_eq!(
            checks_for(Attempt::Global, None, &c),
            &c.relocalise.global_verify
        );
    }
}
