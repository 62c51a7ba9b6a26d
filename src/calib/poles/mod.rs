//! Calibration from two (or more) non-parallel poles wrapped in retro-reflective tape, after Xue
//! et al., "Automatic Calibration of Dual-LiDARs Using Two Poles Stickered with Retro-Reflective
//! Tape" (2019), with the errata of that text fixed: the pole is fitted as a **cylinder axis**, not
//! as the centroid line of the points (which sits up to a radius in front of the axis, on the side
//! facing each sensor, so the two sensors' lines are up to a diameter apart).
//!
//! # Pipeline
//! 1. **Intensity threshold.** `vendor` selects the paper's thresholds (Velodyne 230; Hesai,
//!    Leishen, RoboSense 200); an explicit `intensity_threshold` wins over it. With neither, the
//!    threshold comes from the data ([`data_threshold`]): retro-reflective returns are saturated
//!    outliers of the intensity distribution, separated from the diffuse returns by a wide empty
//!    range, so the threshold is the middle of the **highest** gap between consecutive sorted
//!    intensities above the median that spans at least 10 % of the intensity
//!    range and leaves at least 20 returns above it (tape is the brightest
//!    class: a bright facade opens a wider gap below itself); without one the cloud has no clear
//!    bright class and is refused.
//! 2. **Clustering.** The bright points are grouped by Euclidean clustering
//!    ([`crate::cluster::euclidean_clusters`], our own hash grid: no new dependency, O(N) for a
//!    fixed tolerance) with [`PoleOptions::cluster_tolerance`], which must exceed the gap between
//!    rings on a pole (a VLP-16's 2 deg at 10 m is 0.35 m) and stay below the poles' spacing.
//! 3. **Pole test.** A cluster is a pole when it has at least [`PoleOptions::min_points`] points,
//!    its extent along the principal axis is at least [`PoleOptions::min_length`], and it is
//!    elongated: `sqrt(l3 / l2)` of its scatter eigenvalues is at least
//!    [`PoleOptions::min_elongation`]. A road sign or any compact bright blob (`l3 ~ l2`) fails
//!    the last test and is reported among the rejected clusters. A cluster that fails but is at
//!    least 1 m long (poles leaning on each other, an X) is split by sequential
//!    RANSAC lines, each piece tested again. The cylinder fit must then have an RMS below
//!    3 cm and a diameter below the pole's length.
//! 4. **Axis.** A RANSAC line ([`crate::ransac::line::ransac_line`], threshold `1.2 r + 3 cm`, or
//!    `3 sqrt(l2) + 3 cm` when the radius is unknown) drops stray points, then
//!    [`fit_cylinder`](crate::fit::cylinder::fit_cylinder) finds the axis by Levenberg–Marquardt
//!    on `dist(x, axis) - r` from the sensor's side (radius given or estimated). [`AxisFit::Line`] keeps the centroid line instead, for
//!    comparison only.
//! 5. **Hypotheses.** Two non-parallel pole axes fix the transform, but not which target pole is
//!    which, nor the direction signs: 2 correspondences x 4 signs = 8 hypotheses for two poles
//!    (with more poles: the first non-parallel pair of reference poles against every ordered pair
//!    of target poles, at most 120, further poles matched by proximity). Each is
//!    solved in closed form: `R` by Kabsch on the signed unit directions, `t` by linear least
//!    squares on the perpendicular offsets, `sum_i P_i (R c_t,i + t - c_r,i) = 0` with
//!    `P_i = I - u_i u_i^T`; then refined by Levenberg–Marquardt on point-to-axis distances in both
//!    directions. For the cylinder residual `|dist| - r`, each point is moved toward its own
//!    sensor's fitted axis by the radius once, in its own frame (independent of the unknown
//!    transform); its distance to the other sensor's axis is then `|dist| - r` at the solution, and
//!    the problem is the point-to-line problem of [`PointToLine`](crate::residuals::PointToLine)
//!    with its tested analytic Jacobians.
//! 6. **Choice.** The axes alone are symmetric: flipping both signs maps to the rotation by 180 deg
//!    about the common perpendicular, and swapping the poles to a 180 deg rotation about a bisector
//!    of the axes; four of the eight hypotheses fit the axes exactly. Each hypothesis gets a score
//!    (lower is better), the sum of
//!    * the RMS point-to-axis residual over 2 cm;
//!    * the angle between the reference's and the mapped target's largest plane among the points
//!      below the intensity threshold (the ground in a pole scene, both normals toward the
//!      sensors; it must hold 200 points and 10 % of the cloud) over 5 degrees, and the difference
//!      of their offsets over 0.2 m (omitted when a cloud shows no plane);
//!    * `1 - overlap` over 0.1, where `overlap` is the fraction of (at most
//!      1500) target points that land within [`PoleOptions::overlap_distance`] of a
//!      reference point.
//!
//!    The lowest score wins; `margin` is the runner-up's score minus the winner's. Below
//!    1 the result is flagged `ambiguous`; below 0.2 the two are
//!    indistinguishable and the calibration is refused. Two vertical poles on flat ground with no
//!    other structure are genuinely symmetric under the swap (a 180 deg turn about the vertical
//!    between them); tilted poles, the ground seen from two places and any other structure break it.
//! 6b. **Height from the ground.** Two near-parallel axes hold the translation along them only
//!    through their small angle: a fraction of a degree of axis error put the height 10-13 cm off
//!    in fresh adversarial scenes, with a covariance of under a centimetre. When both clouds show
//!    a largest plane and the chosen pose maps the target's onto the reference's within 2 degrees,
//!    the pose is moved along the poles' mean axis (at most 0.3 m) until the two offsets agree
//!    (`level_on_ground` in `ground.rs`).
//! 7. **Settling and check.** Two near-parallel axes hold the height along them and the tilt only
//!    loosely (4-8 cm and up to 1.5 deg off in adversarial scenes with 2-3 cm noise), which the
//!    check ([`crate::check`]) then refuses. When it does, the check's local re-alignment on the
//!    whole scene, started from the pole pose, is taken instead when it moves it by at most
//!    3 degrees and 0.2 m, every matched pole still lies within
//!    5 cm of its axis there, and it passes the check itself (cylinder fits only: a
//!    centroid line's residuals include the pole's thickness and cannot tell whether the poles
//!    still fit). In 1000 adversarial scenes this took the solvable pole scenes solved from 54 to
//!    74, none wrong. A pole pose that passes is kept, unless the check's re-alignment moves it
//!    by more than 10 cm (a move that counts as evidence): it is then settled the same way, or
//!    refused (pole scene 10166 had come back 10.4 cm off with a clean check).
//! 7b. **A second start from the ground.** The scene's re-alignment can settle a tilted pose
//!    where it is (fresh pole scene 16022: 0.95 deg and 13 cm off, passing the check with 14-15 %
//!    of the points in the other sensor's free space, against the truth's 1 %). When the two
//!    grounds under the settled pose are 0.2-2 deg apart, the pose is turned about the poles'
//!    centre until they are parallel, levelled, and re-aligned on the scene; that pose is taken
//!    when it stays within 3 deg and 0.2 m of the pole pose, the poles still fit and it passes
//!    the check with the free space clearly clearer ([`crate::check`]'s `clearer`: at most half
//!    as many points there). Cylinder fits only.
//!
//! # Limits
//! * The default [`PoleOptions::cluster_tolerance`] (0.5 m) joins the rings of a VLP-16 (2 deg
//!   apart) on a pole up to about 14 m away; further poles need a larger tolerance.
//! * With more than two poles, the hypotheses start from the first non-parallel pair of
//!   reference poles (largest first): that pair must be visible to the target sensor too.
//! * The overlap term prefers transforms that superimpose similar-looking scans; when the two
//!   scans are alike (sensors facing each other across a symmetric pair of poles), "same pose"
//!   and the true turn tie, and the calibration is refused rather than guessed.
//! * The plane term assumes both sensors see the same dominant plane (the ground) from the same
//!   side; without one it is left out.
//!
//! # Example
#![cfg_attr(feature = "sim", doc = "```")]
#![cfg_attr(not(feature = "sim"), doc = "```ignore")]
//! use lidarcal::calib::poles::{calibrate_poles, PoleOptions, Vendor};
//! use lidarcal::sim::scenes::{poles_scene, PolesOptions};
//! use lidarcal::sim::{BeamModel, Preset};
//!
//! let scene = poles_scene(&BeamModel::preset(Preset::Vlp16), &PolesOptions::default())?;
//! let split = |s: &lidarcal::sim::Scan| -> (Vec<_>, Vec<f64>) {
//!     (s.positions(), s.points.iter().map(|p| p.intensity).collect())
//! };
//! let (reference, ref_intensity) = split(&scene.reference);
//! let (target, tgt_intensity) = split(&scene.target);
//! let options = PoleOptions { vendor: Some(Vendor::Velodyne), ..PoleOptions::default() };
//! let result = calibrate_poles(&reference, &ref_intensity, &target, &tgt_intensity, &options)?;
//! let error = result.reference_from_target.inverse() * scene.reference_from_target;
//! assert!(error.rotation.angle() < 0.01 && error.translation.vector.norm() < 0.05);
//! # Ok::<(), lidarcal::Error>(())
//! ```

mod choose;
mod detect;
mod fit;
mod ground;
mod hypotheses;
mod options;
mod scene;
mod score;
mod threshold;

pub use self::detect::{extract_poles, DetectedPole, PoleExtraction, RejectedCluster};
pub use self::hypotheses::Hypothesis;
pub use self::options::{AxisFit, PoleOptions, Vendor, MAX_BRIGHT_FRACTION};
pub use self::threshold::data_threshold;

use self::choose::{check_pole_fit, choose, MatchedPoles, AMBIGUITY_MARGIN};
use self::detect::detect_cloud;
use self::ground::{ground_start, level_on_ground};
use self::hypotheses::{base_matches, per_pole_rms, Clouds};
use self::options::{check_cloud, check_options};
use self::scene::settle;
use self::score::Scorer;

use nalgebra::{Isometry3, Point3};

pub use super::result::PoleCalibration;
use super::result::{Refinement, Solver};
use super::Stopwatch;
use crate::budget::Deadline;
use crate::error::Result;
use crate::geometry::Line;
use crate::lm::LmReport;

/// The pole method's own diagnostics: [`PoleCalibration::details`].
#[derive(Debug, Clone, PartialEq)]
pub struct PoleDetails {
    /// Matched pole axes in the reference frame.
    pub poles_reference: Vec<Line>,
    /// Matched pole axes in the target frame (directions signed to match the reference's).
    pub poles_target: Vec<Line>,
    /// Radius of each matched pole (mean of the two clouds' estimates, or the given radius).
    pub radii: Vec<f64>,
    /// The poles extracted from each cloud (reference, target).
    pub extractions: [PoleExtraction; 2],
    /// Every hypothesis scored, in enumeration order.
    pub hypotheses: Vec<Hypothesis>,
    /// Index of the chosen hypothesis.
    pub chosen: usize,
    /// Score of the best hypothesis that refined to a different transform minus the chosen one's
    /// (infinite when all reached the same transform).
    pub margin: f64,
    /// The margin is below 1.
    pub ambiguous: bool,
    /// The chosen hypothesis's Levenberg–Marquardt report (its pose is the result unless the
    /// scene settled it: [`Calibration::refinement`](crate::calib::Calibration::refinement)).
    pub report: Option<LmReport>,
}

/// Calibrates `reference_from_target` from taped poles seen by both sensors (see the module
/// docs). `*_intensities` hold one intensity per point.
///
/// Errors: [`Error::InvalidInput`](crate::Error::InvalidInput) for malformed input (lengths, NaN
/// coordinates or intensities, options); [`Error::Calibration`](crate::Error::Calibration) when a
/// cloud has no bright points, fewer than two poles, only parallel poles, or when the best two
/// hypotheses are indistinguishable.
pub fn calibrate_poles(
    reference: &[Point3<f64>],
    reference_intensities: &[f64],
    target: &[Point3<f64>],
    target_intensities: &[f64],
    options: &PoleOptions,
) -> Result<PoleCalibration> {
    check_cloud(reference, reference_intensities, "reference")?;
    check_cloud(target, target_intensities, "target")?;
    check_options(options)?;
    let deadline = Deadline::new(options.time_budget);
    let mut clock = Stopwatch::start();

    // Steps 1-4 on each cloud: its poles and its largest plane.
    let (ref_result, tgt_result) = crate::join(
        || {
            detect_cloud(
                reference,
                reference_intensities,
                "reference",
                options,
                &deadline,
            )
        },
        || detect_cloud(target, target_intensities, "target", options, &deadline),
    );
    let (ext_ref, ground_ref) = ref_result?;
    let (ext_tgt, ground_tgt) = tgt_result?;
    clock.lap("poles");
    deadline.check("pole extraction")?;

    // Step 5: every correspondence and sign of a base pair, solved, refined and scored.
    let clouds = Clouds {
        reference,
        target,
        poles_ref: &ext_ref.poles,
        poles_tgt: &ext_tgt.poles,
    };
    let bases = base_matches(&ext_ref.poles, &ext_tgt.poles)?;
    let scorer = Scorer::new(&clouds, [ground_ref, ground_tgt], options, &deadline)?;
    let (hypotheses, starts, reports) = scorer.score_all(&bases)?;
    clock.lap("hypotheses");

    // Step 6: the lowest score, clear of the runner-up, with every matched pole on its axis.
    let (chosen, margin) = choose(&hypotheses)?;
    let best = &hypotheses[chosen];
    let pose = best.reference_from_target;
    let matched = MatchedPoles::new(&clouds, &best.matches, options);
    let pole_rmse = per_pole_rms(&clouds, &best.matches, options.loss, &pose)?;
    check_pole_fit(&pole_rmse, &matched.radii, options.axis_fit)?;
    let report = reports[chosen];
    let covariance = report.as_ref().and_then(|r| r.covariance());
    let initial = starts[chosen];
    clock.lap("choose");

    // Step 7: the check, and the scene's settling of a pole pose it refuses.
    let level = |pose: &Isometry3<f64>| {
        level_on_ground(pose, &matched.poles_reference, [ground_ref, ground_tgt])
    };
    let reground = |pose: &Isometry3<f64>| {
        ground_start(pose, &matched.poles_reference, [ground_ref, ground_tgt])
    };
    let settled = settle(
        &clouds,
        &best.matches,
        pose,
        pole_rmse,
        level,
        reground,
        options,
    )?;
    let refinement = match settled.scene_aligned {
        false => Refinement::from_lm(report.as_ref()),
        true => Refinement::without_iterations(Solver::SceneAlignment),
    };
    clock.lap("certify");
    Ok(PoleCalibration {
        reference_from_target: settled.pose,
        initial_reference_from_target: initial,
        check: settled.check,
        rmse: settled.pole_rmse,
        inliers_reference: matched.inliers_reference,
        inliers_target: matched.inliers_target,
        covariance,
        refinement,
        timings: clock.finish(),
        details: PoleDetails {
            poles_reference: matched.poles_reference,
            poles_target: matched.poles_target,
            radii: matched.radii,
            extractions: [ext_ref, ext_tgt],
            ambiguous: margin < AMBIGUITY_MARGIN,
            hypotheses,
            chosen,
            margin,
            report,
        },
    })
}
