//! Calibration from a recording: two sensors' synchronized frames of a drive, including sensors
//! that never see the same thing at the same time (a unit at the front bumper and one at the
//! tailgate, narrow-field solid-state units).
//!
//! [`calibrate_sequence`] runs four stages:
//!
//! 1. **Odometry** of each sensor from its own frames ([`crate::odometry`]), side by side.
//! 2. **Hand-eye** ([`hand_eye`](fn@hand_eye)): the extrinsic from the pairs of synchronized
//!    motions over a few strides (`A_k X = X B_k`); no common view needed. On flat ground it
//!    leaves the height unobserved, and odometry noise leaves it a tenth of a degree and a few
//!    centimetres off.
//! 3. **Map alignment** ([`align`]): the target's frames, placed by the reference's poses and the
//!    extrinsic, aligned to the map the reference built of the same streets; this brings it to
//!    centimetres and takes the height from the ground both sensors saw.
//! 4. **Gates**: the result is refused, with a kind, when the vehicle hardly moved or never
//!    turned ([`FailureKind::Unobservable`]), when the map alignment leaves a direction
//!    unobserved (no ground in the target's view: the height; [`FailureKind::Unobservable`]),
//!    when too little of what the target saw was in the reference's map, or when the map
//!    alignment moved the hand-eye estimate farther than hand-eye can be wrong
//!    ([`FailureKind::NoAgreement`]).
//!
//! The single-frame methods ([`crate::calib::calibrate`]) need a common view in one frame and
//! refuse such rigs; this is the method for them.

pub mod align;
pub mod hand_eye;

pub use align::{align_to_map, AlignOptions, MapAlignment};
pub use hand_eye::{hand_eye, HandEye, HandEyeOptions, MotionPair};

use nalgebra::{Isometry3, Matrix6, Point3, Vector3};

use super::{Stopwatch, Timings};
use crate::error::{Error, FailureKind, Result};
use crate::icp::weakest_directions;
use crate::odometry::{odometry, Odometry, OdometryOptions};

/// Fewest synchronized frames of a drive.
pub const MIN_FRAMES: usize = 10;
/// Shortest path (metres) the reference sensor must travel: less is a standing vehicle.
pub const MIN_PATH: f64 = 5.0;
/// Smallest share of the map alignment's translation (or rotation) information a direction
/// must have: below it the shared views leave the direction unobserved (the ground missing
/// from a sensor's view leaves the height at about 1e-4).
pub const MIN_ALIGNMENT_SHARE: f64 = 1e-2;
/// Smallest share of the target's samples that must find the reference's map.
pub const MIN_FITNESS: f64 = 0.2;
/// Largest rotation (radians) by which the map alignment may move the hand-eye estimate: 2
/// degrees, about ten times what hand-eye is off by on the simulated drives.
pub const MAX_ROTATION_CHANGE: f64 = 0.035;
/// Largest translation (metres, across the hand-eye's unobserved direction) by which the map
/// alignment may move the hand-eye estimate: about five times what hand-eye is off by.
pub const MAX_TRANSLATION_CHANGE: f64 = 0.3;

/// A least-constrained direction and its share of the information.
type Weakest = (Vector3<f64>, f64);

/// Options of [`calibrate_sequence`].
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceOptions {
    /// Odometry of both sensors.
    pub odometry: OdometryOptions,
    /// Hand-eye calibration.
    pub hand_eye: HandEyeOptions,
    /// Map alignment.
    pub align: AlignOptions,
    /// Frame strides of the motion pairs. Default `[5, 10, 20]` (half a second to two seconds at
    /// 10 Hz: long enough for turns to rotate, short enough for little drift).
    pub strides: Vec<usize>,
}

impl Default for SequenceOptions {
    fn default() -> Self {
        SequenceOptions {
            odometry: OdometryOptions::default(),
            hand_eye: HandEyeOptions::default(),
            align: AlignOptions::default(),
            strides: vec![5, 10, 20],
        }
    }
}

/// What [`calibrate_sequence`] returned.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceCalibration {
    /// The calibrated `reference_from_target`.
    pub reference_from_target: Isometry3<f64>,
    /// The hand-eye estimate the map alignment started from.
    pub hand_eye: HandEye,
    /// The map alignment.
    pub alignment: MapAlignment,
    /// The reference sensor's odometry (`world_from_reference` per frame, the world its first
    /// frame).
    pub reference_odometry: Odometry,
    /// The target sensor's odometry (its own world: its first frame).
    pub target_odometry: Odometry,
    /// Covariance of the result's tangent `[rho; phi]` from the map alignment (metres,
    /// radians): the spread of its residuals over its information. It counts only the
    /// alignment's noise, not the odometry's error between the two sensors' views, so it is a
    /// lower bound.
    pub covariance: Option<Matrix6<f64>>,
    /// The least-constrained translation direction of the map alignment (reference frame) and
    /// its share of the information.
    pub weakest_translation: (Vector3<f64>, f64),
    /// The least-constrained rotation axis of the map alignment and its share.
    pub weakest_rotation: (Vector3<f64>, f64),
    /// Stage timings: `odometry`, `hand_eye`, `align`.
    pub timings: Timings,
}

/// The motion pairs of the two trajectories at each stride (starting every half stride).
fn motion_pairs(reference: &Odometry, target: &Odometry, strides: &[usize]) -> Vec<MotionPair> {
    let n = reference.poses.len().min(target.poses.len());
    let mut pairs = Vec::new();
    for &s in strides.iter().filter(|&&s| s >= 1 && s < n) {
        for i in (0..n - s).step_by((s / 2).max(1)) {
            let (Some(a0), Some(a1), Some(b0), Some(b1)) = (
                reference.poses.get(i),
                reference.poses.get(i + s),
                target.poses.get(i),
                target.poses.get(i + s),
            ) else {
                continue;
            };
            pairs.push(MotionPair {
                reference: a0.inverse() * a1,
                target: b0.inverse() * b1,
            });
        }
    }
    pairs
}

fn check_frames(reference: &[Vec<Point3<f64>>], target: &[Vec<Point3<f64>>]) -> Result<()> {
    if reference.len() != target.len() {
        return Err(Error::InvalidInput(format!(
            "a drive needs the same number of frames from both sensors (frame k of both taken at \
             the same time): got {} reference and {} target frames",
            reference.len(),
            target.len()
        )));
    }
    if reference.len() < MIN_FRAMES {
        return Err(Error::InvalidInput(format!(
            "a drive needs at least {MIN_FRAMES} frames, got {}",
            reference.len()
        )));
    }
    // Before any odometry runs, so a NaN is named as such and not as a lost track.
    for (name, frames) in [("reference", reference), ("target", target)] {
        for (k, frame) in frames.iter().enumerate() {
            crate::error::ensure_finite(
                &format!("{name} frame {k}"),
                frame.iter().flat_map(|p| p.coords.iter()),
            )?;
        }
    }
    Ok(())
}

fn refuse_unobserved(alignment: &MapAlignment) -> Result<(Weakest, Weakest)> {
    let [translation, rotation] = weakest_directions(&alignment.information);
    let (d, share) = translation;
    if share < MIN_ALIGNMENT_SHARE {
        let what = if d.z.abs() > 0.9 {
            "the height (no ground, or no other horizontal surface, seen by both sensors)"
        } else {
            "a horizontal direction"
        };
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the views the two sensors shared leave {what} unobserved: translation along \
                 ({:.2}, {:.2}, {:.2}) in the reference frame has {:.1e} of the information \
                 (at least {MIN_ALIGNMENT_SHARE:.0e} needed)",
                d.x, d.y, d.z, share
            ),
        ));
    }
    if rotation.1 < MIN_ALIGNMENT_SHARE {
        let a = rotation.0;
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the views the two sensors shared leave the rotation about ({:.2}, {:.2}, {:.2}) \
                 unobserved ({:.1e} of the information, at least {MIN_ALIGNMENT_SHARE:.0e} \
                 needed)",
                a.x, a.y, a.z, rotation.1
            ),
        ));
    }
    Ok((translation, rotation))
}

/// How far the map alignment moved the hand-eye estimate: rotation (radians) and translation
/// across the hand-eye's unobserved direction (metres).
fn change(hand_eye: &HandEye, aligned: &Isometry3<f64>) -> (f64, f64) {
    let start = &hand_eye.reference_from_target;
    let rotation = (start.rotation.inverse() * aligned.rotation).angle();
    let mut dt = aligned.translation.vector - start.translation.vector;
    if let Some(u) = hand_eye.unobserved_translation {
        dt -= u * u.dot(&dt);
    }
    (rotation, dt.norm())
}

/// Calibrates `reference_from_target` from a drive: `reference_frames[k]` and
/// `target_frames[k]` are the two sensors' points (each in its own frame) at the same time,
/// frames in time order at a steady rate. See the [module docs](self).
///
/// Errors: [`Error::InvalidInput`] for different frame counts, fewer than [`MIN_FRAMES`]
/// frames, non-finite points, a frame with too few points or bad options;
/// [`Error::Calibration`] with a kind when the drive does not determine the extrinsic (see the
/// module docs).
pub fn calibrate_sequence(
    reference_frames: &[Vec<Point3<f64>>],
    target_frames: &[Vec<Point3<f64>>],
    options: &SequenceOptions,
) -> Result<SequenceCalibration> {
    check_frames(reference_frames, target_frames)?;
    options.odometry.validate()?;
    options.hand_eye.validate()?;
    options.align.validate()?;
    let mut clock = Stopwatch::start();
    let (reference, target) = crate::join(
        || {
            odometry(reference_frames, &options.odometry)
                .map_err(|e| e.context("reference odometry"))
        },
        || odometry(target_frames, &options.odometry).map_err(|e| e.context("target odometry")),
    );
    let (reference, target) = (reference?, target?);
    clock.lap("odometry");
    if reference.distance < MIN_PATH {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the reference sensor travelled {:.2} m over the {} frames (at least {MIN_PATH} m \
                 needed): a standing vehicle's motion determines nothing",
                reference.distance,
                reference_frames.len()
            ),
        ));
    }
    let pairs = motion_pairs(&reference, &target, &options.strides);
    let hand_eye = hand_eye(&pairs, &options.hand_eye)?;
    clock.lap("hand_eye");
    let alignment = align_to_map(
        reference_frames,
        &reference.poses,
        target_frames,
        &hand_eye.reference_from_target,
        &options.align,
    )?;
    clock.lap("align");
    if alignment.fitness < MIN_FITNESS {
        return Err(Error::calibration(
            FailureKind::NoAgreement,
            format!(
                "only {:.0} % of the target's samples lie on the reference's map after the \
                 alignment (at least {:.0} % needed): the sensors shared too little of the drive",
                100.0 * alignment.fitness,
                100.0 * MIN_FITNESS
            ),
        ));
    }
    let (weakest_translation, weakest_rotation) = refuse_unobserved(&alignment)?;
    let (rotation, translation) = change(&hand_eye, &alignment.reference_from_target);
    if rotation > MAX_ROTATION_CHANGE || translation > MAX_TRANSLATION_CHANGE {
        return Err(Error::calibration(
            FailureKind::NoAgreement,
            format!(
                "the map alignment moved the hand-eye estimate by {:.2} degrees and {:.2} m (at \
                 most {:.1} degrees and {MAX_TRANSLATION_CHANGE} m expected): one of the two is \
                 wrong; are the frames synchronized? (a time offset of one frame moves the \
                 alignment by the distance driven in a frame)",
                rotation.to_degrees(),
                translation,
                MAX_ROTATION_CHANGE.to_degrees()
            ),
        ));
    }
    let dof = alignment.correspondences.saturating_sub(6).max(1) as f64;
    let sigma2 = alignment.rmse * alignment.rmse * alignment.correspondences as f64 / dof;
    let covariance = alignment
        .information
        .cholesky()
        .map(|c| c.inverse() * sigma2);
    Ok(SequenceCalibration {
        reference_from_target: alignment.reference_from_target,
        hand_eye,
        alignment,
        reference_odometry: reference,
        target_odometry: target,
        covariance,
        weakest_translation,
        weakest_rotation,
        timings: clock.finish(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(n: usize) -> Vec<Vec<Point3<f64>>> {
        (0..n)
            .map(|_| {
                (0..200)
                    .map(|i| Point3::new(i as f64 * 0.1, (i % 7) as f64, 0.0))
                    .collect()
            })
            .collect()
    }

    #[test]
    fn bad_drives_are_invalid_input() {
        let options = SequenceOptions::default();
        let e = calibrate_sequence(&frames(12), &frames(11), &options).unwrap_err();
        assert!(
            matches!(e, Error::InvalidInput(ref m) if m.contains("same number")),
            "{e}"
        );
        let e = calibrate_sequence(&frames(5), &frames(5), &options).unwrap_err();
        assert!(
            matches!(e, Error::InvalidInput(ref m) if m.contains("at least 10")),
            "{e}"
        );
        let mut nan = frames(12);
        nan[4][3].y = f64::NAN;
        let e = calibrate_sequence(&frames(12), &nan, &options).unwrap_err();
        assert!(
            matches!(e, Error::InvalidInput(ref m) if m.contains("target frame 4")),
            "{e}"
        );
    }

    #[test]
    fn a_standing_vehicle_is_unobservable() {
        // A ground plane and two walls, the same frame twelve times.
        let mut cloud = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let (a, b) = (i as f64 * 0.25 - 7.5, j as f64 * 0.25);
                cloud.push(Point3::new(a, b - 7.5, -1.5));
                cloud.push(Point3::new(a, 6.0, b - 1.5));
                cloud.push(Point3::new(8.0, a, b - 1.5));
            }
        }
        let drive = vec![cloud; 12];
        let e = calibrate_sequence(&drive, &drive, &SequenceOptions::default()).unwrap_err();
        assert_eq!(e.kind(), Some(FailureKind::Unobservable), "{e}");
    }

    #[test]
    fn motion_pairs_cover_each_stride() {
        let poses: Vec<Isometry3<f64>> = (0..30)
            .map(|k| Isometry3::translation(k as f64, 0.0, 0.0))
            .collect();
        let odo = Odometry {
            poses: poses.clone(),
            frames: Vec::new(),
            distance: 29.0,
        };
        let pairs = motion_pairs(&odo, &odo, &[5, 10, 40]);
        // stride 5 starts every 2 frames (0..25), stride 10 every 5 (0..20); 40 > frames.
        assert_eq!(pairs.len(), 13 + 4);
        assert!((pairs[0].reference.translation.vector.x - 5.0).abs() < 1e-12);
    }
}
