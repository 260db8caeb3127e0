//! The tracking step: registration of a frame from the constant-velocity prediction and
//! its verification (docs/METHOD.md §7). A plain function of a model, the settings and a
//! motion model, so the tracker and the relocalisation thread, tracking a relocalised pose
//! on over lost frames ([`crate::relocalise_worker`]), run the same code.

use opengs_geometry::Pose;
use opengs_gicp::{Cloud, Registration};

use crate::ambiguity::restarts;
use crate::attempt::{register_verified, Attempt, Verified};
use crate::model::TrackingModel;
use crate::verify::MotionPrior;
use crate::{ConstantVelocity, DepthFrame, TrackerConfig};

/// Where a registration from the prediction landed, by its offset from the prediction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Landing {
    /// The answer.
    Near,
    /// Slid a little: the turned attempt runs too, and the better fitness wins.
    Doubtful,
    /// Maybe a neighbouring minimum: the wide search decides.
    Slid,
}

/// The fine attempt's slides: more than `fast_path_offset`, or a turn of more than
/// `fast_path_turn` (fr2_desk, scene 4 with noise: a frame after a gap landed 0.8 cm and
/// 6.4° from the prediction, 3.8° wrong, and its keyframe's ghost of the scene made
/// relocalisation fail for 29 frames); doubtful beyond `fast_path_sure` (scene 1: an
/// answer 2.47 cm out was 2.6 cm wrong, the turned one right at a higher fitness). The
/// turned attempt exists to turn, so only its position counts.
fn landing(offset: &Pose, kind: Attempt, config: &TrackerConfig) -> Landing {
    let metres = offset.translation.vector.norm();
    let fast = kind == Attempt::Fast;
    if metres > config.fast_path_offset || (fast && offset.rotation.angle() > config.fast_path_turn)
    {
        Landing::Slid
    } else if fast && metres > config.fast_path_sure {
        Landing::Doubtful
    } else {
        Landing::Near
    }
}

/// Tracking. The fine registration from the prediction, when it verifies near the
/// prediction, is the answer; when it (and the turned attempt) verified but slid from a
/// prediction with a velocity, it is polished by restarts; after a gap (or when both
/// fail, or slid from a prediction without one) coarse-to-fine also runs from
/// the prediction (and from the last verified pose when that finds nothing), the
/// verified answer with the best fitness is polished, and the best of those is kept.
/// Returns the verified registration (or why none verified) and why the wide search ran,
/// if it did; `motion` is not changed.
pub(crate) fn register(
    model: &TrackingModel,
    config: &TrackerConfig,
    motion: &ConstantVelocity,
    frame: &DepthFrame,
    cloud: &Cloud,
    gap: bool,
) -> (Verified, Option<String>) {
    let timestamp = frame.timestamp;
    let Some((last, t_last)) = motion.last() else {
        return (Err("no verified pose yet".into()), None);
    };
    let predicted = motion.predict(timestamp).unwrap_or(last);
    // Without a velocity (the frame after the first, after a relocalisation or a
    // restart) the prediction is the last pose, and a slide is the camera's motion.
    let moving = motion.has_velocity();
    let prior = MotionPrior {
        predicted,
        seconds: timestamp - t_last,
    };
    // After a gap the wide search from the prediction also covers the fine search's
    // basin (fr2_desk with noise, scenes 1 and 3, the same three gap frames: 46–116 ms
    // with a fine attempt first, 42–64 ms without; position error within 0.02 cm).
    let mut tries = match gap {
        true => vec![],
        false => vec![(predicted, Attempt::Fast), (predicted, Attempt::Turned)],
    };
    let first_wide = tries.len();
    tries.push((predicted, Attempt::Wide));
    if predicted != last {
        tries.push((last, Attempt::Wide));
    }
    let mut best: Option<Registration> = None;
    // Whether `best` was registered with every point (the fine attempt's answer).
    let mut best_is_full = false;
    let mut attempt: Verified = Err("no registration tried".into());
    let mut wide: Option<String> = None;
    // Made when the wide search starts (most frames never need it).
    let mut thin: Option<Cloud> = None;
    // Whether a wide registration verified (the one from the prediction usually does).
    let mut wide_verified = false;
    // A fine answer that slid a little: the turned attempt decides.
    let mut doubtful: Option<Registration> = None;
    // A verified answer that slid from a moving prediction: the restarts around it
    // decide, with no coarse-to-fine from the prediction, which the fine attempts started
    // from already (fr2_desk's gap region with noise, scenes 1–6, three runs each: the
    // worst row's p99 45.2–46.1 → 40.1–41.5 ms, position error within the run-to-run
    // spread).
    let mut slid_verified = false;
    for (k, &(start, kind)) in tries.iter().enumerate() {
        // Both wide starts end in one basin (scene 1 along fr2_desk with noise: fitness
        // within 0.001 in 22 of 22 searches); the polish below looks around it anyway.
        if k == first_wide + 1 && wide_verified {
            break;
        }
        if k == first_wide {
            wide = Some(match (&best, gap) {
                (_, true) => "a gap before the frame".to_string(),
                (Some(r), false) => format!(
                    "the registration slid {:.1} cm from the prediction",
                    (predicted.inverse() * r.transform)
                        .translation
                        .vector
                        .norm()
                        * 100.0
                ),
                (None, false) => match &attempt {
                    Err(why) => why.clone(),
                    Ok(_) => String::new(),
                },
            });
            if !gap && best.is_some() && moving {
                slid_verified = true;
                break;
            }
        }
        let full = matches!(kind, Attempt::Fast | Attempt::Turned);
        let source = match full {
            true => cloud,
            false => thin.get_or_insert_with(|| cloud.voxel_subsample(config.wide_source_voxel)),
        };
        // Between consecutive frames, a verified registration that lands near the
        // prediction is the answer; one that slid farther may sit in a neighbouring
        // minimum. (Trusting one that slid but kept the previous frame's fitness, or
        // that the turned start confirmed, took answers 4.7–9.5 cm off on fr2_desk
        // with noise, scenes 1 and 3.)
        let res = register_verified(model, config, frame, source, &start, kind, Some(&prior));
        let landed = |r: &Registration| {
            full.then(|| landing(&(predicted.inverse() * r.transform), kind, config))
        };
        match res {
            Ok(r) if landed(&r) == Some(Landing::Doubtful) => doubtful = Some(r),
            Ok(r) if landed(&r) == Some(Landing::Near) => {
                best = Some(match doubtful.take() {
                    Some(d) if d.fitness > r.fitness => d,
                    _ => r,
                });
                break;
            }
            Ok(r) => {
                wide_verified |= !full;
                if best.as_ref().is_none_or(|b| r.fitness > b.fitness) {
                    best = Some(r);
                    best_is_full = full;
                }
            }
            Err(why) => attempt = Err(why),
        }
        if kind == Attempt::Turned {
            if let Some(d) = doubtful.take() {
                best = Some(d);
                best_is_full = true;
                break;
            }
        }
    }
    if let (Some(found), true) = (&best, thin.is_some() || slid_verified) {
        let restarts = cloud.voxel_subsample(config.restart_source_voxel);
        // A restart that beats the answer is refined with every point (its verified
        // thinned answer if that fails); so is a wide answer that none beats.
        let winner = polish(model, config, frame, &restarts, found, &prior);
        if winner.is_some() || !best_is_full {
            let from = winner.unwrap_or_else(|| found.clone());
            best = Some(
                register_verified(
                    model,
                    config,
                    frame,
                    cloud,
                    &from.transform,
                    Attempt::Polish,
                    Some(&prior),
                )
                .unwrap_or(from),
            );
        }
    }
    if let Some(r) = best {
        attempt = Ok(r);
    }
    (attempt, wide)
}

/// Restarts of the fine registration a step away from an answer (a wide search's, or a
/// verified one that slid) either way
/// along its two least constrained translations ([`restarts`]; the six camera
/// axis directions found the same answers, 15 ms slower per wide search on fr2_desk with
/// noise), and one from the answer itself, all with the same `cloud` so that
/// their fitness compares; the verified restart with the best fitness, if it is not the
/// answer's own. Wide searches on boxy scenes end in minima a few centimetres off
/// (fr2_desk, scene 1, after its 1.8 s gap: 3.6 cm off at fitness 0.975; two of six
/// camera-axis restarts reached the truth at 0.993).
fn polish(
    model: &TrackingModel,
    config: &TrackerConfig,
    frame: &DepthFrame,
    cloud: &Cloud,
    found: &Registration,
    prior: &MotionPrior,
) -> Option<Registration> {
    let step = config.restart_step;
    if step <= 0.0 {
        return None;
    }
    let base = found.transform;
    let own = register_verified(
        model,
        config,
        frame,
        cloud,
        &base,
        Attempt::Polish,
        Some(prior),
    )
    .map_or(f64::NEG_INFINITY, |r| r.fitness);
    let mut best: Option<Registration> = None;
    for start in restarts(&base, &found.hessian, step) {
        if let Ok(r) = register_verified(
            model,
            config,
            frame,
            cloud,
            &start,
            Attempt::Polish,
            Some(prior),
        ) {
            let to_beat = best.as_ref().map_or(own, |b| b.fitness);
            if r.fitness > to_beat {
                best = Some(r);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn a_fine_answer_that_turned_or_slid_is_not_taken_as_it_is() {
        let c = TrackerConfig::tum();
        let at = |cm: f64, degrees: f64| {
            Pose::from_parts(
                Translation3::new(cm / 100.0, 0.0, 0.0),
                UnitQuaternion::from_scaled_axis(Vector3::y() * degrees.to_radians()),
            )
        };
        assert_eq!(landing(&at(1.0, 2.0), Attempt::Fast, &c), Landing::Near);
        assert_eq!(landing(&at(2.0, 0.5), Attempt::Fast, &c), Landing::Doubtful);
        assert_eq!(landing(&at(3.0, 0.5), Attempt::Fast, &c), Landing::Slid);
        // fr2_desk, scene 4 with noise: 0.8 cm and 6.4° from the prediction, 3.8° wrong.
        assert_eq!(landing(&at(0.8, 6.4), Attempt::Fast, &c), Landing::Slid);
        // Turning is what the turned attempt is for; its position still counts.
        assert_eq!(landing(&at(0.8, 6.4), Attempt::Turned, &c), Landing::Near);
        assert_eq!(landing(&at(2.0, 0.5), Attempt::Turned, &c), Landing::Near);
        assert_eq!(landing(&at(3.0, 0.5), Attempt::Turned, &c), Landing::Slid);
    }
}
