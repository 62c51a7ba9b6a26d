//! Step 7 of the [module docs](super): settling the pole pose on the whole scene.

use nalgebra::Isometry3;

use super::choose::MAX_POLE_RMSE;
use super::hypotheses::*;
use super::options::*;
use crate::check::{clearer, CheckReport, PreparedPair, MAX_HELD_CORRECTION};
use crate::error::{Error, FailureKind, Result};
use crate::geometry::pose_error;

/// The scene's re-alignment of the pole pose is kept only within this rotation (radians, 3
/// degrees) ...
pub(super) const SCENE_REFINE_ANGLE: f64 = 3.0 * std::f64::consts::PI / 180.0;
/// ... and this translation (metres) of it, where the poles still fit ([`MAX_POLE_RMSE`]).
pub(super) const SCENE_REFINE_DISTANCE: f64 = 0.2;

/// The final check of the pole pose (`pole_rmse` is its per-pole RMS); when it passes, the pose
/// `level` gives (the height from the ground) is taken if it passes too; when the check refuses
/// it, the check's re-alignment on the whole scene is taken instead if it stays within
/// [`SCENE_REFINE_ANGLE`] and [`SCENE_REFINE_DISTANCE`], the poles of `matches` still lie within
/// [`MAX_POLE_RMSE`] of their axes and it passes the check (cylinder fits only). Returns the
/// settled pose, or the first refusal.
pub(super) fn settle(
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    pose: Isometry3<f64>,
    pole_rmse: Vec<f64>,
    level: impl Fn(&Isometry3<f64>) -> Isometry3<f64>,
    reground: impl Fn(&Isometry3<f64>) -> Option<Isometry3<f64>>,
    options: &PoleOptions,
) -> Result<Settled> {
    // The poles hold the pose only as well as a few hundred tape points can: two near-parallel
    // axes leave the height along them and the tilt loosely held (4-8 cm and up to 1.5 degrees
    // off in 1000 adversarial scenes with 2-3 cm noise), which the check then refuses. The
    // scene's surfaces settle those: when the pole pose fails the check, the check's local
    // re-alignment from it is taken if it stays near it, the poles still lie within
    // MAX_POLE_RMSE of their axes there and it passes the check (the pole-only pose fits the
    // tape's noise too: at the true pose of noisy units the RMS is 2-4 cm, not 1-2). A pole pose
    // that passes is kept: on clean scans it is the more precise (20 simulated scenes: median
    // 2.7 mrad / 1.35 cm against 3.1 mrad / 1.5 cm).
    let pair = PreparedPair::new(clouds.reference, clouds.target, &options.check)?;
    let first = pair.check(&pose)?;
    let settled = match first.refusal().or_else(|| scene_disagrees(&first)) {
        None => {
            // A pole pose that passes gets its height along the poles from the ground (step 6b)
            // when the levelled pose passes too and the poles still fit there. Only then: a pole
            // pose the check refused can sit closer to the ground's height and yet be off
            // across the poles (two tuning scenes, 11 and 20 cm), which the scene's re-alignment
            // below corrects and levelling would not.
            let levelled = level(&pose);
            let kept = Settled {
                pose,
                pole_rmse,
                check: first,
                scene_aligned: false,
            };
            if levelled == pose {
                kept
            } else {
                let rms = per_pole_rms(clouds, matches, options.loss, &levelled)?;
                let fits = rms.iter().all(|r| r.is_finite() && *r <= MAX_POLE_RMSE);
                match pair.check(&levelled)? {
                    c if fits && c.refusal().is_none() => Settled {
                        pose: levelled,
                        pole_rmse: rms,
                        check: c,
                        scene_aligned: false,
                    },
                    _ => kept,
                }
            }
        }
        Some(refused) => {
            // A centroid line's residuals include the pole's thickness (up to 25 cm allowed):
            // they cannot tell whether the poles still fit, and the scene then moved one of 20
            // simulated line-fit results 19 cm along a direction it holds only weakly.
            if options.axis_fit != AxisFit::Cylinder {
                return Err(refused);
            }
            match scene_settled(&pair, clouds, matches, &pose, first.aligned, options)? {
                Some(s) if s.check.failure.is_none() => s,
                _ => return Err(refused),
            }
        }
    };
    // Step 7b: the scene's re-alignment can settle a tilted pose where it is; a second start with
    // the ground's tilt and height is taken when it settles clearly clearer of free space. It is
    // only a second chance: if it cannot be judged, the settled pose stands.
    if options.axis_fit == AxisFit::Cylinder {
        if let Some(start) = reground(&settled.pose) {
            if let Ok(Some(better)) =
                from_ground(&pair, clouds, matches, &pose, &start, &settled, options)
            {
                return Ok(better);
            }
        }
    }
    Ok(settled)
}

/// `aligned`, a re-alignment of the pole pose `pose` on the scene, with its per-pole RMS and its
/// check, when it stays within [`SCENE_REFINE_ANGLE`] and [`SCENE_REFINE_DISTANCE`] of `pose`
/// and every matched pole still lies within [`MAX_POLE_RMSE`] of its axis there; `None`
/// otherwise. Whether the check passes is for the caller to judge.
fn scene_settled(
    pair: &PreparedPair,
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    pose: &Isometry3<f64>,
    aligned: Isometry3<f64>,
    options: &PoleOptions,
) -> Result<Option<Settled>> {
    let (angle, distance) = pose_error(&aligned, pose);
    if angle > SCENE_REFINE_ANGLE || distance > SCENE_REFINE_DISTANCE {
        return Ok(None);
    }
    let rms = per_pole_rms(clouds, matches, options.loss, &aligned)?;
    if !rms.iter().all(|r| r.is_finite() && *r <= MAX_POLE_RMSE) {
        return Ok(None);
    }
    Ok(Some(Settled {
        pose: aligned,
        pole_rmse: rms,
        check: pair.check(&aligned)?,
        scene_aligned: true,
    }))
}

/// The scene's re-alignment from `start` (the ground's tilt and height applied to the settled
/// pose), when [`scene_settled`] keeps it, it passes the check without a counted move beyond
/// [`MAX_HELD_CORRECTION`], and it is [`clearer`] of the other sensor's free space than the
/// settled pose. On pole scene 16022 the settled pose was 0.95 degrees and 13 cm off with 14-15 %
/// of the points in free space; from the ground's start the scene settles 0.05 degrees and 1.4 cm
/// off with 1.1 %.
fn from_ground(
    pair: &PreparedPair,
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    pose: &Isometry3<f64>,
    start: &Isometry3<f64>,
    settled: &Settled,
    options: &PoleOptions,
) -> Result<Option<Settled>> {
    let aligned = pair.aligned(start)?;
    Ok(
        scene_settled(pair, clouds, matches, pose, aligned, options)?.filter(|s| {
            s.check.refusal().is_none()
                && !s.check.moved_beyond_held()
                && clearer(s.check.free_share(), settled.check.free_share())
        }),
    )
}

/// A pole pose that passes the check but that the check's re-alignment on the whole scene moves
/// by more than [`MAX_HELD_CORRECTION`] (a move that counts as evidence) is settled like one the
/// check refuses: the scene holds it elsewhere. Pole scene 10166 (adversarial seeds
/// 10000-10999) came back 10.4 cm and 0.8 degrees off with a clean check, whose re-alignment
/// moved it 10.5 cm; the correct pole results returned on that set and on seeds 0-999 and
/// 11000-11999 were moved at most 7.1 cm (two correct poses moved further, 10189 and 10192, are
/// settled on the scene now, from 0.58 and 0.38 degrees off to 0.01 and 0.02).
fn scene_disagrees(first: &CheckReport) -> Option<Error> {
    first.moved_beyond_held().then(|| {
        Error::calibration(
            FailureKind::NoAgreement,
            format!(
                "the pole pose passes the check, but the check's local re-alignment on the whole \
                 scene moves it by {:.1} cm and {:.2} deg (more than {:.0} cm): the scene holds \
                 the pose elsewhere, and the re-aligned pose cannot be taken instead (it moves \
                 too far, leaves a pole off its axis or fails the check)",
                first.correction_translation * 100.0,
                first.correction_rotation.to_degrees(),
                MAX_HELD_CORRECTION * 100.0
            ),
        )
    })
}

/// The pose [`settle`] returns.
pub(super) struct Settled {
    pub(super) pose: Isometry3<f64>,
    /// RMS point-to-axis residual of each matched pole at `pose`.
    pub(super) pole_rmse: Vec<f64>,
    /// The check's report of `pose`.
    pub(super) check: CheckReport,
    /// `pose` is the check's re-alignment of the pole pose.
    pub(super) scene_aligned: bool,
}
