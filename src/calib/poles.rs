//! Calibration from two (or more) non-parallel poles wrapped in retro-reflective tape, after seed
//! 003 ("two non-parallel poles"), with its errata fixed: the pole is fitted as a **cylinder
//! axis**, not as the centroid line of the points (which sits up to a radius in front of the axis,
//! on the side facing each sensor, so the two sensors' lines are up to a diameter apart).
//!
//! # Pipeline
//! 1. **Intensity threshold.** `vendor` selects the seed's thresholds (Velodyne 230; Hesai,
//!    Leishen, RoboSense 200); an explicit `intensity_threshold` wins over it. With neither, the
//!    threshold comes from the data ([`data_threshold`]): retro-reflective returns are saturated
//!    outliers of the intensity distribution, separated from the diffuse returns by a wide empty
//!    range, so the threshold is the middle of the **highest** gap between consecutive sorted
//!    intensities above the median that spans at least [`MIN_INTENSITY_GAP`] of the intensity
//!    range and leaves at least [`MIN_BRIGHT_CLASS`] returns above it (tape is the brightest
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
//!    least [`SPLIT_MIN_LENGTH`] long (poles leaning on each other, an X) is split by sequential
//!    RANSAC lines, each piece tested again. The cylinder fit must then have an RMS below
//!    [`MAX_CYLINDER_RMS`] and a diameter below the pole's length.
//! 4. **Axis.** A RANSAC line ([`crate::ransac::line::ransac_line`], threshold `1.2 r + 3 cm`, or
//!    `3 sqrt(l2) + 3 cm` when the radius is unknown) drops stray points, then
//!    [`fit_cylinder`] finds the axis by Levenberg–Marquardt on `dist(x, axis) - r` from the sensor's
//!    side (radius given or estimated). [`AxisFit::Line`] keeps the centroid line instead, for
//!    comparison only.
//! 5. **Hypotheses.** Two non-parallel pole axes fix the transform, but not which target pole is
//!    which, nor the direction signs: 2 correspondences x 4 signs = 8 hypotheses for two poles
//!    (with more poles: the first non-parallel pair of reference poles against every ordered pair
//!    of target poles, at most [`MAX_HYPOTHESES`], further poles matched by proximity). Each is
//!    solved in closed form: `R` by Kabsch on the signed unit directions, `t` by linear least
//!    squares on the perpendicular offsets, `sum_i P_i (R c_t,i + t - c_r,i) = 0` with
//!    `P_i = I - u_i u_i^T`; then refined by Levenberg–Marquardt on point-to-axis distances in both
//!    directions. For the cylinder residual `|dist| - r`, each point is moved toward its own
//!    sensor's fitted axis by the radius once, in its own frame (independent of the unknown
//!    transform); its distance to the other sensor's axis is then `|dist| - r` at the solution, and
//!    the problem is the point-to-line problem of [`PointToLine`] with its tested analytic Jacobians.
//! 6. **Choice.** The axes alone are symmetric: flipping both signs maps to the rotation by 180 deg
//!    about the common perpendicular, and swapping the poles to a 180 deg rotation about a bisector
//!    of the axes; four of the eight hypotheses fit the axes exactly. Each hypothesis gets a score
//!    (lower is better), the sum of
//!    * the RMS point-to-axis residual over [`AXIS_RMS_SCALE`];
//!    * the angle between the reference's and the mapped target's largest plane among the points
//!      below the intensity threshold (the ground in a pole scene, both normals toward the
//!      sensors; it must hold [`MIN_PLANE_POINTS`] points and 10 % of the cloud) over [`GROUND_ANGLE_SCALE`], and the difference
//!      of their offsets over [`GROUND_OFFSET_SCALE`] (omitted when a cloud shows no plane);
//!    * `1 - overlap` over [`OVERLAP_SCALE`], where `overlap` is the fraction of (at most
//!      [`OVERLAP_SAMPLE`]) target points that land within [`PoleOptions::overlap_distance`] of a
//!      reference point.
//!
//!    The lowest score wins; `margin` is the runner-up's score minus the winner's. Below
//!    [`AMBIGUITY_MARGIN`] the result is flagged `ambiguous`; below [`REFUSE_MARGIN`] the two are
//!    indistinguishable and the calibration is refused. Two vertical poles on flat ground with no
//!    other structure are genuinely symmetric under the swap (a 180 deg turn about the vertical
//!    between them); tilted poles, the ground seen from two places and any other structure break it.
//! 7. **Settling and check.** Two near-parallel axes hold the height along them and the tilt only
//!    loosely (4-8 cm and up to 1.5 deg off in adversarial scenes with 2-3 cm noise), which the
//!    check ([`crate::check`]) then refuses. When it does, the check's local re-alignment on the
//!    whole scene, started from the pole pose, is taken instead when it moves it by at most
//!    [`SCENE_REFINE_ANGLE`] and [`SCENE_REFINE_DISTANCE`], every matched pole still lies within
//!    [`MAX_POLE_RMSE`] of its axis there, and it passes the check itself (cylinder fits only: a
//!    centroid line's residuals include the pole's thickness and cannot tell whether the poles
//!    still fit). In 1000 adversarial scenes this took the solvable pole scenes solved from 54 to
//!    74, none wrong. A pole pose that passes is kept.
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

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3};

use super::{Stopwatch, Timings};
use crate::budget::Deadline;
use crate::check::{CheckOptions, CheckReport, PreparedPair};
use crate::cluster::{euclidean_clusters_until, Grid};
use crate::error::{ensure_positive, Error, FailureKind, Result};
use crate::fit::cylinder::fit_cylinder;
use crate::fit::Moments;
use crate::geometry::pose_error;
use crate::geometry::{Line, Plane};
use crate::kabsch::kabsch;
use crate::lm::{solve, LmOptions, LmReport, Loss};
use crate::ransac::line::ransac_line;
use crate::ransac::plane::ransac_plane;
use crate::ransac::RansacOptions;
use crate::residuals::{Frame, LineGroup, PointToLine};

/// Two poles closer than this to parallel (radians, 2 degrees) do not determine the rotation
/// about them.
pub const MIN_POLE_ANGLE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Cap on the number of hypotheses scored (more poles than that enumerate only the first).
pub const MAX_HYPOTHESES: usize = 120;
/// Unit of the axis RMS term of a hypothesis score (metres).
pub const AXIS_RMS_SCALE: f64 = 0.02;
/// Unit of the ground-normal angle term (radians, 5 degrees).
pub const GROUND_ANGLE_SCALE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Unit of the ground-offset term (metres).
pub const GROUND_OFFSET_SCALE: f64 = 0.2;
/// Unit of the `1 - overlap` term.
pub const OVERLAP_SCALE: f64 = 0.1;
/// Target points (at most, by a fixed stride) used for the overlap term.
pub const OVERLAP_SAMPLE: usize = 1500;
/// Points (at most, by a fixed stride) used to find each cloud's largest plane.
pub const GROUND_SAMPLE: usize = 3000;
/// Fewest points (and at least 10 % of the cloud) of the largest plane used in the scores.
pub const MIN_PLANE_POINTS: usize = 200;
/// Inlier distance of the largest-plane search (metres).
pub const GROUND_THRESHOLD: f64 = 0.05;
/// Two refined hypotheses within this rotation (radians) ...
pub const SAME_POSE_ANGLE: f64 = 0.01;
/// ... and this translation (metres) of each other are the same solution.
pub const SAME_POSE_DISTANCE: f64 = 0.05;
/// A score margin below this flags the choice as ambiguous.
pub const AMBIGUITY_MARGIN: f64 = 1.0;
/// A score margin below this refuses the calibration: the best two are indistinguishable.
pub const REFUSE_MARGIN: f64 = 0.2;
/// The automatic threshold's gap must span at least this fraction of the intensity range.
pub const MIN_INTENSITY_GAP: f64 = 0.1;
/// Fewest returns above the automatic threshold's gap: a handful of saturated returns above the
/// tape is not the tape class.
pub const MIN_BRIGHT_CLASS: usize = 20;
/// Largest RMS of a pole's cylinder fit (metres): a flat strip of a sign does not fit.
pub const MAX_CYLINDER_RMS: f64 = 0.03;
/// Line inlier distance when splitting a merged cluster with an unknown radius (metres).
pub const SPLIT_LINE_THRESHOLD: f64 = 0.2;
/// Shortest cluster that is split into several lines (metres): crossing poles, not a sign.
pub const SPLIT_MIN_LENGTH: f64 = 1.0;
/// Smallest elongation of each piece of a split cluster.
pub const SPLIT_MIN_ELONGATION: f64 = 3.0;
/// Largest accepted estimated radius (metres).
pub const MAX_RADIUS: f64 = 1.0;
/// Largest RMS distance (metres) of a matched pole's points from its axis model at the result;
/// correct results stay under 1 cm, a pose from mismatched poles lands decimetres off.
pub const MAX_POLE_RMSE: f64 = 0.05;
/// What [`MAX_POLE_RMSE`] allows in addition for [`AxisFit::Line`], whose residuals include the
/// pole's thickness (metres).
pub const LINE_FIT_THICKNESS: f64 = 0.2;
/// The scene's re-alignment of the pole pose is kept only within this rotation (radians, 3
/// degrees) ...
pub const SCENE_REFINE_ANGLE: f64 = 3.0 * std::f64::consts::PI / 180.0;
/// ... and this translation (metres) of it, where the poles still fit ([`MAX_POLE_RMSE`]).
pub const SCENE_REFINE_DISTANCE: f64 = 0.2;
/// A further pole matches a mapped pole when their directions are within this angle (radians,
/// 5 degrees) ...
pub const MATCH_ANGLE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// ... and the mapped axis passes within this distance (metres) of the pole's centre.
pub const MATCH_DISTANCE: f64 = 0.3;

/// LiDAR vendors with the seed's intensity thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Vendor {
    /// Velodyne: 230.
    Velodyne,
    /// Hesai: 200.
    Hesai,
    /// Leishen: 200.
    Leishen,
    /// RoboSense: 200.
    RoboSense,
}

impl Vendor {
    /// The seed's intensity threshold for this vendor.
    pub fn threshold(self) -> f64 {
        match self {
            Vendor::Velodyne => 230.0,
            Vendor::Hesai | Vendor::Leishen | Vendor::RoboSense => 200.0,
        }
    }

    /// Parses "velodyne", "hesai", "leishen" or "robosense" (case-insensitive).
    pub fn from_name(name: &str) -> Result<Vendor> {
        match name.to_ascii_lowercase().as_str() {
            "velodyne" => Ok(Vendor::Velodyne),
            "hesai" => Ok(Vendor::Hesai),
            "leishen" => Ok(Vendor::Leishen),
            "robosense" => Ok(Vendor::RoboSense),
            _ => Err(Error::InvalidInput(format!(
                "vendor must be one of 'velodyne', 'hesai', 'leishen', 'robosense', got {name:?}"
            ))),
        }
    }
}

/// How a pole's line is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AxisFit {
    /// The cylinder axis (correct: the points lie on the surface facing the sensor).
    #[default]
    Cylinder,
    /// The least-squares line through the points (the seed's method; biased by up to a radius,
    /// kept for comparison).
    Line,
}

/// Options of [`calibrate_poles`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleOptions {
    /// Intensity at or above which a return is taped; wins over `vendor`.
    pub intensity_threshold: Option<f64>,
    /// Selects the seed's threshold when `intensity_threshold` is `None`; with neither, the
    /// threshold comes from the data (module docs).
    pub vendor: Option<Vendor>,
    /// Pole radius in metres, or `None` to estimate it per pole.
    pub pole_radius: Option<f64>,
    /// Seed of the RANSAC samplers.
    pub seed: u64,
    /// Euclidean clustering tolerance (metres).
    pub cluster_tolerance: f64,
    /// Fewest points of a pole.
    pub min_points: usize,
    /// Shortest extent of a pole along its axis (metres).
    pub min_length: f64,
    /// Smallest `sqrt(l3 / l2)` of a pole's scatter eigenvalues.
    pub min_elongation: f64,
    /// Most poles used per cloud (the largest clusters).
    pub max_poles: usize,
    /// Cylinder axis or centroid line.
    pub axis_fit: AxisFit,
    /// Distance within which a mapped target point counts as landing on a reference point
    /// (metres).
    pub overlap_distance: f64,
    /// Loss of the point-to-axis refinement.
    pub loss: Loss,
    /// Levenberg–Marquardt options.
    pub lm: LmOptions,
    /// Wall-clock budget: past it the calibration stops with [`Error::Calibration`] (see
    /// [`crate::budget`]); `None` for no limit.
    pub time_budget: Option<std::time::Duration>,
    /// The final check every result must pass ([`crate::check`]).
    pub check: CheckOptions,
    /// Largest share of a cloud's returns that may be at or above the intensity threshold.
    /// Tape is a small part of any scene (1-2 % in the simulated ones); a threshold that makes
    /// most returns "tape" (e.g. 0) leaves walls and ground to be fitted as poles, and gave poses
    /// 45-180 degrees off that were not always flagged (and thresholds marking 30 % still gave
    /// poses 40-140 degrees off in simulated scenes). Above this share the calibration is
    /// refused, naming the share and the data-driven threshold. A cloud cropped to the poles
    /// themselves is mostly tape: raise it to 1.0 there.
    pub max_bright_fraction: f64,
}

/// Default of [`PoleOptions::max_bright_fraction`].
pub const MAX_BRIGHT_FRACTION: f64 = 0.25;

impl Default for PoleOptions {
    fn default() -> Self {
        PoleOptions {
            intensity_threshold: None,
            vendor: None,
            pole_radius: None,
            seed: 0,
            cluster_tolerance: 0.5,
            min_points: 15,
            min_length: 0.4,
            min_elongation: 1.6,
            max_poles: 6,
            axis_fit: AxisFit::Cylinder,
            overlap_distance: 0.3,
            loss: Loss::Squared,
            lm: LmOptions {
                cost_tolerance: 1e-10,
                ..LmOptions::default()
            },
            time_budget: None,
            check: CheckOptions::poles(),
            max_bright_fraction: MAX_BRIGHT_FRACTION,
        }
    }
}

/// A pole found in one cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectedPole {
    /// The axis (cylinder axis or line), in the cloud's frame; the point is the foot of the
    /// points' centroid.
    pub axis: Line,
    /// Fitted or given radius (0 for [`AxisFit::Line`]).
    pub radius: f64,
    /// RMS residual of the axis fit (metres).
    pub rms: f64,
    /// Indices of the pole's points (RANSAC inliers) in the cloud.
    pub indices: Vec<usize>,
    /// Extent of the points along the axis, `(min, max)` from the axis point (metres).
    pub extent: (f64, f64),
}

/// A bright cluster that was not taken as a pole.
#[derive(Debug, Clone, PartialEq)]
pub struct RejectedCluster {
    /// Points in the cluster.
    pub size: usize,
    /// Why it was rejected.
    pub reason: String,
}

/// The poles of one cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct PoleExtraction {
    /// The intensity threshold used.
    pub intensity_threshold: f64,
    /// Returns at or above it.
    pub bright_points: usize,
    /// The poles, largest first.
    pub poles: Vec<DetectedPole>,
    /// Clusters of at least `min_points` that failed a pole test.
    pub rejected: Vec<RejectedCluster>,
}

/// One correspondence/sign hypothesis and its score.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// `(reference pole, target pole, sign)` pairs; `sign = -1` flips the target direction.
    pub matches: Vec<(usize, usize, i8)>,
    /// The refined transform of this hypothesis.
    pub reference_from_target: Isometry3<f64>,
    /// RMS point-to-axis residual after refinement (metres), both directions.
    pub axis_rms: f64,
    /// Angle between the reference's and the mapped target's largest plane (radians).
    pub ground_angle: Option<f64>,
    /// Difference of their offsets (metres).
    pub ground_offset: Option<f64>,
    /// Fraction of target points landing within `overlap_distance` of a reference point.
    pub overlap: f64,
    /// The score of the module docs (lower is better).
    pub score: f64,
}

/// Result of [`calibrate_poles`].
#[derive(Debug, Clone, PartialEq)]
pub struct PoleCalibration {
    /// The final check's report (its verdict is always consistent: other poses are refused).
    pub check: CheckReport,
    /// The calibrated `reference_from_target`.
    pub reference_from_target: Isometry3<f64>,
    /// The closed-form estimate of the chosen hypothesis before refinement.
    pub initial_reference_from_target: Isometry3<f64>,
    /// Matched pole axes in the reference frame.
    pub poles_reference: Vec<Line>,
    /// Matched pole axes in the target frame (directions signed to match the reference's).
    pub poles_target: Vec<Line>,
    /// Radius of each matched pole (mean of the two clouds' estimates, or the given radius).
    pub radii: Vec<f64>,
    /// Indices of each matched pole's points in the reference cloud.
    pub indices_reference: Vec<Vec<usize>>,
    /// Indices of each matched pole's points in the target cloud.
    pub indices_target: Vec<Vec<usize>>,
    /// The poles extracted from each cloud (reference, target).
    pub extractions: [PoleExtraction; 2],
    /// Every hypothesis scored, in enumeration order.
    pub hypotheses: Vec<Hypothesis>,
    /// Index of the chosen hypothesis.
    pub chosen: usize,
    /// Score of the best hypothesis that refined to a different transform minus the chosen one's
    /// (infinite when all reached the same transform).
    pub margin: f64,
    /// The margin is below [`AMBIGUITY_MARGIN`].
    pub ambiguous: bool,
    /// RMS point-to-axis residual at the result (metres), all poles and both directions.
    pub rmse: f64,
    /// The same per matched pole.
    pub pole_rmse: Vec<f64>,
    /// The chosen hypothesis's refinement report.
    pub report: Option<LmReport>,
    /// Covariance of the left-perturbation tangent `[rho; phi]` (least-squares loss).
    pub covariance: Option<Matrix6<f64>>,
    /// Stage timings.
    pub timings: Timings,
}

/// The data-driven intensity threshold of the module docs.
pub fn data_threshold(intensities: &[f64]) -> Result<f64> {
    let mut v: Vec<f64> = intensities
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if v.len() < 2 {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            "too few intensities to choose a threshold",
        ));
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let (lo, hi) = (v[0], v[v.len() - 1]);
    let range = hi - lo;
    // Tape is the brightest class: take the highest gap above the median that is wide enough
    // and leaves at least MIN_BRIGHT_CLASS returns above it, not the widest gap (a bright facade
    // between the clutter and the tape opens a wider gap below itself and was taken for tape).
    let upper = &v[v.len() / 2..];
    let mut best = (0.0, hi);
    for (k, w) in upper.windows(2).enumerate().rev() {
        let gap = w[1] - w[0];
        let above = upper.len() - (k + 1);
        if above >= MIN_BRIGHT_CLASS && range > 0.0 && gap >= MIN_INTENSITY_GAP * range {
            best = (gap, 0.5 * (w[0] + w[1]));
            break;
        }
        if gap > best.0 {
            best = (gap, 0.5 * (w[0] + w[1]));
        }
    }
    if range <= 0.0 || best.0 < MIN_INTENSITY_GAP * range {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "no clear class of bright (retro-reflective) returns: the widest intensity gap above \
             the median is {:.1} of a range {lo:.1}..{hi:.1} (need {:.0} %); pass \
             intensity_threshold or vendor",
            best.0,
            MIN_INTENSITY_GAP * 100.0
        ),
        ));
    }
    Ok(best.1)
}

fn check_cloud(points: &[Point3<f64>], intensities: &[f64], which: &str) -> Result<()> {
    if points.len() != intensities.len() {
        return Err(Error::InvalidInput(format!(
            "the {which} cloud has {} points but {} intensities",
            points.len(),
            intensities.len()
        )));
    }
    let bad: Vec<usize> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.coords.iter().all(|x| x.is_finite()))
        .map(|(i, _)| i)
        .collect();
    if let Some(first) = bad.first() {
        return Err(Error::InvalidInput(format!(
            "the {which} cloud has {} point(s) with non-finite coordinates, the first in row {first}",
            bad.len()
        )));
    }
    crate::error::ensure_points(&format!("the {which} cloud"), points.iter())?;
    let bad = intensities.iter().filter(|x| !x.is_finite()).count();
    if let Some(first) = intensities.iter().position(|x| !x.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "the {which} intensities contain {bad} NaN or infinite value(s), the first in row {first}"
        )));
    }
    Ok(())
}

fn check_options(o: &PoleOptions) -> Result<()> {
    if let Some(t) = o.intensity_threshold {
        if !t.is_finite() {
            return Err(Error::InvalidInput(format!(
                "intensity_threshold must be finite, got {t}"
            )));
        }
    }
    if let Some(r) = o.pole_radius {
        ensure_positive("pole_radius", r)?;
    }
    ensure_positive("cluster_tolerance", o.cluster_tolerance)?;
    ensure_positive("overlap_distance", o.overlap_distance)?;
    if !(o.max_bright_fraction > 0.0 && o.max_bright_fraction <= 1.0) {
        return Err(Error::InvalidInput(format!(
            "max_bright_fraction must be in (0, 1], got {}",
            o.max_bright_fraction
        )));
    }
    ensure_positive("min_elongation", o.min_elongation)?;
    if !(o.min_length.is_finite() && o.min_length >= 0.0) {
        return Err(Error::InvalidInput(format!(
            "min_length must be finite and >= 0, got {}",
            o.min_length
        )));
    }
    if o.min_points < crate::fit::cylinder::MIN_POINTS {
        return Err(Error::InvalidInput(format!(
            "min_points must be at least {}, got {}",
            crate::fit::cylinder::MIN_POINTS,
            o.min_points
        )));
    }
    if o.max_poles < 2 {
        return Err(Error::InvalidInput(format!(
            "max_poles must be at least 2, got {}",
            o.max_poles
        )));
    }
    o.loss.validate()
}

/// Finds the poles of one cloud (steps 1–4 of the module docs).
pub fn extract_poles(
    points: &[Point3<f64>],
    intensities: &[f64],
    options: &PoleOptions,
) -> Result<PoleExtraction> {
    extract_poles_until(
        points,
        intensities,
        options,
        &Deadline::new(options.time_budget),
    )
}

/// [`extract_poles`] against a deadline set by the caller.
fn extract_poles_until(
    points: &[Point3<f64>],
    intensities: &[f64],
    options: &PoleOptions,
    deadline: &Deadline,
) -> Result<PoleExtraction> {
    check_cloud(points, intensities, "input")?;
    check_options(options)?;
    let threshold = match (options.intensity_threshold, options.vendor) {
        (Some(t), _) => t,
        (None, Some(v)) => v.threshold(),
        (None, None) => data_threshold(intensities)?,
    };
    let bright: Vec<usize> = (0..points.len())
        .filter(|&i| intensities[i] >= threshold)
        .collect();
    if bright.len() < options.min_points {
        let max = intensities
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "only {} bright point(s) at or above intensity {threshold:.1} (need {} per pole; the \
             highest intensity is {max:.1}): no taped poles visible, or the threshold is too high",
            bright.len(),
            options.min_points
        ),
        ));
    }
    let share = bright.len() as f64 / points.len() as f64;
    if share > options.max_bright_fraction {
        let suggestion = match data_threshold(intensities) {
            Ok(t) => format!("this cloud's data-driven threshold is {t:.1}"),
            Err(_) => "this cloud has no clear bright class either".into(),
        };
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "intensity threshold {threshold:.1} marks {:.1} % of the returns as tape (more than \
             {:.0} %): tape is a small part of a scene, so this threshold does not separate it; \
             raise it ({suggestion}), or, for a cloud cropped to the poles, raise \
             max_bright_fraction",
            100.0 * share,
            100.0 * options.max_bright_fraction
        ),
        ));
    }
    let bright_points: Vec<Point3<f64>> = bright.iter().map(|&i| points[i]).collect();
    let clusters = euclidean_clusters_until(&bright_points, options.cluster_tolerance, deadline)?;
    let mut poles = Vec::new();
    let mut rejected = Vec::new();
    for cluster in clusters {
        if cluster.len() < options.min_points {
            continue;
        }
        let members: Vec<Point3<f64>> = cluster.iter().map(|&k| bright_points[k]).collect();
        let indices: Vec<usize> = cluster.iter().map(|&k| bright[k]).collect();
        match fit_pole(&members, &indices, options) {
            Ok(pole) => poles.push(pole),
            Err(reason) => {
                // Poles that lean on each other (an X) form one compact-looking cluster: look for
                // several lines in it before giving up.
                let split = split_cluster(&members, &indices, options);
                if split.is_empty() {
                    rejected.push(RejectedCluster {
                        size: cluster.len(),
                        reason,
                    });
                } else {
                    poles.extend(split);
                }
            }
        }
    }
    poles.sort_by_key(|p| std::cmp::Reverse(p.indices.len()));
    poles.truncate(options.max_poles);
    Ok(PoleExtraction {
        intensity_threshold: threshold,
        bright_points: bright.len(),
        poles,
        rejected,
    })
}

/// Sequential RANSAC lines in a cluster that failed the pole test as a whole (poles crossing or
/// touching); every line's inliers must pass the pole test on their own with an elongation of at
/// least [`SPLIT_MIN_ELONGATION`]. Only clusters of at least two poles' worth of points and
/// [`SPLIT_MIN_LENGTH`] are split, so a compact sign stays whole and is rejected.
fn split_cluster(
    members: &[Point3<f64>],
    indices: &[usize],
    options: &PoleOptions,
) -> Vec<DetectedPole> {
    let mut out = Vec::new();
    if members.len() < 2 * options.min_points {
        return out;
    }
    // Only a cluster at least as long as a pole can hold crossing poles; a sign is not split.
    let moments = Moments::from_points(members);
    let (_, vectors) = moments.principal_axes();
    let (lo, hi) = extent_along(members, &moments.mean(), &vectors[2]);
    if hi - lo < SPLIT_MIN_LENGTH {
        return out;
    }
    // Each piece must be clearly a line on its own.
    let strict = PoleOptions {
        min_elongation: options.min_elongation.max(SPLIT_MIN_ELONGATION),
        min_length: options.min_length.max(0.5 * SPLIT_MIN_LENGTH),
        ..*options
    };
    let options = &strict;
    let threshold = options
        .pole_radius
        .map_or(SPLIT_LINE_THRESHOLD, |r| 1.2 * r + 0.03);
    let mut remaining: Vec<usize> = (0..members.len()).collect();
    for round in 0..options.max_poles {
        if remaining.len() < options.min_points {
            break;
        }
        let pts: Vec<Point3<f64>> = remaining.iter().map(|&k| members[k]).collect();
        let mut ransac = RansacOptions::new(threshold);
        ransac.seed = options.seed.wrapping_add(round as u64);
        let Ok(line) = ransac_line(&pts, &ransac) else {
            break;
        };
        if line.inliers.len() < options.min_points {
            break;
        }
        let sub: Vec<Point3<f64>> = line.inliers.iter().map(|&k| pts[k]).collect();
        let sub_indices: Vec<usize> = line
            .inliers
            .iter()
            .map(|&k| indices[remaining[k]])
            .collect();
        if let Ok(pole) = fit_pole(&sub, &sub_indices, options) {
            out.push(pole);
        }
        let taken: std::collections::HashSet<usize> = line.inliers.iter().copied().collect();
        remaining = remaining
            .iter()
            .enumerate()
            .filter(|(k, _)| !taken.contains(k))
            .map(|(_, &m)| m)
            .collect();
    }
    out
}

/// Tests and fits one cluster; `Err` carries the reason it is not a pole.
fn fit_pole(
    members: &[Point3<f64>],
    indices: &[usize],
    options: &PoleOptions,
) -> std::result::Result<DetectedPole, String> {
    let moments = Moments::from_points(members);
    let (values, vectors) = moments.principal_axes();
    let elongation = if values[1] > 0.0 {
        (values[2] / values[1]).sqrt()
    } else {
        f64::INFINITY
    };
    let mean = moments.mean();
    let (lo, hi) = extent_along(members, &mean, &vectors[2]);
    let length = hi - lo;
    if elongation < options.min_elongation {
        return Err(format!(
            "compact bright blob (a sign?): elongation {elongation:.2} < {:.2}, length {length:.2} m",
            options.min_elongation
        ));
    }
    if length < options.min_length {
        return Err(format!(
            "too short: {length:.2} m < {:.2} m",
            options.min_length
        ));
    }
    let threshold = match options.pole_radius {
        Some(r) => 1.2 * r + 0.03,
        None => 3.0 * values[1].sqrt() + 0.03,
    };
    let mut ransac = RansacOptions::new(threshold);
    ransac.seed = options.seed;
    let line = ransac_line(members, &ransac).map_err(|e| format!("no line: {e}"))?;
    if line.inliers.len() < options.min_points {
        return Err(format!(
            "only {} points on its line (need {})",
            line.inliers.len(),
            options.min_points
        ));
    }
    let inlier_points: Vec<Point3<f64>> = line.inliers.iter().map(|&k| members[k]).collect();
    let inlier_indices: Vec<usize> = line.inliers.iter().map(|&k| indices[k]).collect();
    let (axis, radius, rms) = match options.axis_fit {
        AxisFit::Line => {
            let fit = Moments::from_points(&inlier_points)
                .line()
                .map_err(|e| format!("no line: {e}"))?;
            (fit.line, 0.0, fit.rms)
        }
        AxisFit::Cylinder => {
            let fit = fit_cylinder(
                &inlier_points,
                options.pole_radius,
                &line.model,
                &Point3::origin(),
            )
            .map_err(|e| format!("no cylinder: {e}"))?;
            if fit.rms > MAX_CYLINDER_RMS {
                return Err(format!(
                    "not a cylinder: RMS {:.3} m > {MAX_CYLINDER_RMS} m",
                    fit.rms
                ));
            }
            if 2.0 * fit.radius > length {
                return Err(format!(
                    "wider than long: radius {:.3} m for a length of {length:.2} m",
                    fit.radius
                ));
            }
            if !(fit.radius > 0.0 && fit.radius <= MAX_RADIUS) {
                return Err(format!(
                    "implausible radius {:.3} m (max {MAX_RADIUS} m)",
                    fit.radius
                ));
            }
            (fit.axis, fit.radius, fit.rms)
        }
    };
    // Deterministic direction: away from the sensor's "down" is not known, so point it along the
    // largest coordinate of the direction with a positive sign.
    let d = axis.direction.into_inner();
    let k = d.iamax();
    let axis = if d[k] < 0.0 { axis.reversed() } else { axis };
    let (lo, hi) = inlier_points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let s = (p - axis.point).dot(&axis.direction);
            (lo.min(s), hi.max(s))
        });
    Ok(DetectedPole {
        axis,
        radius,
        rms,
        indices: inlier_indices,
        extent: (lo, hi),
    })
}

fn angle_between_lines(a: &Line, b: &Line) -> f64 {
    a.direction.dot(&b.direction).abs().clamp(0.0, 1.0).acos()
}

/// Closed-form transform from matched axes: Kabsch on directions, least squares on offsets.
fn closed_form(pairs: &[(Line, Line)]) -> Result<Isometry3<f64>> {
    let a: Vec<Vector3<f64>> = pairs
        .iter()
        .map(|(r, _)| r.direction.into_inner())
        .collect();
    let b: Vec<Vector3<f64>> = pairs
        .iter()
        .map(|(_, t)| t.direction.into_inner())
        .collect();
    let rotation = kabsch(&a, &b, None)?.rotation;
    let mut lhs = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for (r, t) in pairs {
        let u = r.direction.into_inner();
        let p = Matrix3::identity() - u * u.transpose();
        lhs += p;
        rhs += p * (r.point.coords - rotation * t.point.coords);
    }
    let translation = lhs.cholesky().map(|c| c.solve(&rhs)).ok_or_else(|| {
        Error::Degenerate("the matched axes are parallel: translation undetermined".into())
    })?;
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// Points of a pole moved toward their own axis by the radius (see the module docs).
fn offset_points(points: &[Point3<f64>], pole: &DetectedPole) -> Vec<Point3<f64>> {
    pole.indices
        .iter()
        .filter_map(|&i| points.get(i))
        .map(|p| {
            let foot = pole.axis.closest_point(p);
            let radial = p - foot;
            let rho = radial.norm();
            if rho > 0.0 && pole.radius > 0.0 {
                p - radial * (pole.radius / rho)
            } else {
                *p
            }
        })
        .collect()
}

struct Clouds<'a> {
    reference: &'a [Point3<f64>],
    target: &'a [Point3<f64>],
    poles_ref: &'a [DetectedPole],
    poles_tgt: &'a [DetectedPole],
}

fn point_to_axis_problem(
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    loss: Loss,
) -> Result<PointToLine> {
    let mut groups = Vec::with_capacity(2 * matches.len());
    for &(i, k, _) in matches {
        let (pr, pt) = (&clouds.poles_ref[i], &clouds.poles_tgt[k]);
        groups.push(LineGroup {
            line: pr.axis,
            points: offset_points(clouds.target, pt),
            frame: Frame::Target,
        });
        groups.push(LineGroup {
            line: pt.axis,
            points: offset_points(clouds.reference, pr),
            frame: Frame::Reference,
        });
    }
    PointToLine::new(groups, loss)
}

fn axis_rms(problem: &PointToLine, pose: &Isometry3<f64>) -> f64 {
    let r = problem.residuals(pose);
    if r.is_empty() {
        return f64::INFINITY;
    }
    let sum: f64 = r.iter().map(|(v, _)| v[0] * v[0] + v[1] * v[1]).sum();
    (sum / r.len() as f64).sqrt()
}

/// Extends a base match by the poles not in it, by proximity of the mapped axes.
fn extend_matches(
    base: &[(usize, usize, i8)],
    pose: &Isometry3<f64>,
    clouds: &Clouds<'_>,
) -> Vec<(usize, usize, i8)> {
    let mut matches = base.to_vec();
    for (i, pr) in clouds.poles_ref.iter().enumerate() {
        if matches.iter().any(|m| m.0 == i) {
            continue;
        }
        let mut best: Option<(f64, usize, i8)> = None;
        for (k, pt) in clouds.poles_tgt.iter().enumerate() {
            if matches.iter().any(|m| m.1 == k) {
                continue;
            }
            let mapped = pt.axis.transformed(pose);
            let cos = mapped.direction.dot(&pr.axis.direction);
            if cos.abs().clamp(0.0, 1.0).acos() > MATCH_ANGLE {
                continue;
            }
            let d = mapped.distance(&pr.axis.point);
            if d < MATCH_DISTANCE && best.is_none_or(|b| d < b.0) {
                best = Some((d, k, if cos < 0.0 { -1 } else { 1 }));
            }
        }
        if let Some((_, k, s)) = best {
            matches.push((i, k, s));
        }
    }
    matches
}

fn signed_axis(pole: &DetectedPole, sign: i8) -> Line {
    if sign < 0 {
        pole.axis.reversed()
    } else {
        pole.axis
    }
}

fn largest_plane(points: &[Point3<f64>], total: usize, seed: u64) -> Option<Plane> {
    if points.len() < MIN_PLANE_POINTS {
        return None;
    }
    let stride = points.len().div_ceil(GROUND_SAMPLE).max(1);
    let sample: Vec<Point3<f64>> = points.iter().step_by(stride).copied().collect();
    let mut o = RansacOptions::new(GROUND_THRESHOLD);
    o.seed = seed;
    let found = ransac_plane(&sample, &o).ok()?;
    // A "plane" of a few points (the paint of two poles side by side) is not a ground.
    let inliers = found.inliers.len() * stride;
    (inliers >= MIN_PLANE_POINTS && inliers * 10 >= total).then_some(found.model)
}

/// Calibrates `reference_from_target` from taped poles seen by both sensors (see the module
/// docs). `*_intensities` hold one intensity per point.
///
/// Errors: [`Error::InvalidInput`] for malformed input (lengths, NaN coordinates or intensities,
/// options); [`Error::Calibration`] when a cloud has no bright points, fewer than two poles, only
/// parallel poles, or when the best two hypotheses are indistinguishable.
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

    let per_cloud = |points: &[Point3<f64>], intensities: &[f64], which: &str| {
        let extraction = extract_poles_until(points, intensities, options, &deadline)
            .map_err(|e| with_cloud(e, which))?;
        // The tape is left out: the front faces of two poles can pass for a plane.
        let dull: Vec<Point3<f64>> = points
            .iter()
            .zip(intensities)
            .filter(|(_, &i)| i < extraction.intensity_threshold)
            .map(|(p, _)| *p)
            .collect();
        let plane = largest_plane(&dull, points.len(), options.seed);
        check_poles(&extraction, which).map(|_| (extraction, plane))
    };
    let (ref_result, tgt_result) = crate::join(
        || per_cloud(reference, reference_intensities, "reference"),
        || per_cloud(target, target_intensities, "target"),
    );
    let (ext_ref, ground_ref) = ref_result?;
    let (ext_tgt, ground_tgt) = tgt_result?;
    clock.lap("poles");
    deadline.check("pole extraction")?;

    let clouds = Clouds {
        reference,
        target,
        poles_ref: &ext_ref.poles,
        poles_tgt: &ext_tgt.poles,
    };
    // The base pair of reference poles: the first non-parallel pair, largest poles first.
    let base = base_pair(&ext_ref.poles).ok_or_else(|| {
        Error::calibration(
            FailureKind::Unobservable,
            "reference cloud: the poles are parallel",
        )
    })?;
    let mut bases = Vec::new();
    for k0 in 0..ext_tgt.poles.len() {
        for k1 in 0..ext_tgt.poles.len() {
            if k0 == k1
                || angle_between_lines(&ext_tgt.poles[k0].axis, &ext_tgt.poles[k1].axis)
                    < MIN_POLE_ANGLE
            {
                continue;
            }
            for (s0, s1) in [(1, 1), (1, -1), (-1, 1), (-1, -1)] {
                if bases.len() < MAX_HYPOTHESES {
                    bases.push([(base.0, k0, s0), (base.1, k1, s1)]);
                }
            }
        }
    }

    let stride = target.len().div_ceil(OVERLAP_SAMPLE).max(1);
    let sample: Vec<Point3<f64>> = target.iter().step_by(stride).copied().collect();
    let grid = Grid::new(reference, options.overlap_distance)?;
    let evaluate =
        |b: &[(usize, usize, i8); 2]| -> Result<(Hypothesis, Isometry3<f64>, Option<LmReport>)> {
            deadline.check("the pole hypotheses")?;
            let pairs: Vec<(Line, Line)> = b
                .iter()
                .map(|&(i, k, s)| (ext_ref.poles[i].axis, signed_axis(&ext_tgt.poles[k], s)))
                .collect();
            let start = closed_form(&pairs)?;
            let matches = extend_matches(b, &start, &clouds);
            let start = if matches.len() > 2 {
                let pairs: Vec<(Line, Line)> = matches
                    .iter()
                    .map(|&(i, k, s)| (ext_ref.poles[i].axis, signed_axis(&ext_tgt.poles[k], s)))
                    .collect();
                closed_form(&pairs)?
            } else {
                start
            };
            let problem = point_to_axis_problem(&clouds, &matches, options.loss)?;
            let solution = solve(&problem, &start, &options.lm)?;
            let pose = solution.pose;
            let rms = axis_rms(&problem, &pose);
            let (ground_angle, ground_offset) = match (ground_ref, ground_tgt) {
                (Some(gr), Some(gt)) => {
                    let mapped = gt.transformed(&pose);
                    let angle = mapped.normal.dot(&gr.normal).clamp(-1.0, 1.0).acos();
                    (Some(angle), Some((mapped.offset - gr.offset).abs()))
                }
                _ => (None, None),
            };
            let near = sample
                .iter()
                .filter(|p| grid.any_within(&(pose * *p), options.overlap_distance))
                .count();
            let overlap = near as f64 / sample.len().max(1) as f64;
            let score = rms / AXIS_RMS_SCALE
                + ground_angle.map_or(0.0, |a| a / GROUND_ANGLE_SCALE)
                + ground_offset.map_or(0.0, |d| d / GROUND_OFFSET_SCALE)
                + (1.0 - overlap) / OVERLAP_SCALE;
            Ok((
                Hypothesis {
                    matches,
                    reference_from_target: pose,
                    axis_rms: rms,
                    ground_angle,
                    ground_offset,
                    overlap,
                    score,
                },
                start,
                Some(solution.report),
            ))
        };
    #[cfg(feature = "parallel")]
    let evaluated: Vec<_> = {
        use rayon::prelude::*;
        bases.par_iter().map(evaluate).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let evaluated: Vec<_> = bases.iter().map(evaluate).collect();
    let mut hypotheses = Vec::with_capacity(evaluated.len());
    let mut starts = Vec::with_capacity(evaluated.len());
    let mut reports = Vec::with_capacity(evaluated.len());
    for e in evaluated {
        let (h, s, r) = e?;
        hypotheses.push(h);
        starts.push(s);
        reports.push(r);
    }
    clock.lap("hypotheses");

    let mut order: Vec<usize> = (0..hypotheses.len()).collect();
    order.sort_by(|&a, &b| hypotheses[a].score.total_cmp(&hypotheses[b].score));
    let Some(&chosen) = order.first() else {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            "no pair of non-parallel target poles to match",
        ));
    };
    // The runner-up is the best hypothesis that reached a different transform: hypotheses that
    // refine to the same pose are one solution, not a tie.
    let best_pose = hypotheses[chosen].reference_from_target;
    let runner_up = order.iter().copied().skip(1).find(|&j| {
        let d = hypotheses[j].reference_from_target.inverse() * best_pose;
        d.rotation.angle() > SAME_POSE_ANGLE || d.translation.vector.norm() > SAME_POSE_DISTANCE
    });
    let margin = runner_up.map_or(f64::INFINITY, |j| {
        hypotheses[j].score - hypotheses[chosen].score
    });
    if let Some(j) = runner_up.filter(|_| margin < REFUSE_MARGIN) {
        let (a, b) = (&hypotheses[chosen], &hypotheses[j]);
        return Err(Error::calibration(FailureKind::Ambiguous, format!(
            "ambiguous pole correspondence: the best two hypotheses score {:.3} and {:.3} \
             (margin {margin:.3} < {REFUSE_MARGIN}; axis RMS {:.4} / {:.4} m, overlap {:.3} / {:.3}); \
             the scene is symmetric (e.g. two vertical poles on flat ground with nothing else)",
            a.score, b.score, a.axis_rms, b.axis_rms, a.overlap, b.overlap
        )));
    }
    let best = &hypotheses[chosen];
    let pose = best.reference_from_target;
    let mut poles_reference = Vec::new();
    let mut poles_target = Vec::new();
    let mut radii = Vec::new();
    let mut indices_reference = Vec::new();
    let mut indices_target = Vec::new();
    for &(i, k, s) in &best.matches {
        let (pr, pt) = (&ext_ref.poles[i], &ext_tgt.poles[k]);
        poles_reference.push(pr.axis);
        poles_target.push(signed_axis(pt, s));
        radii.push(match options.pole_radius {
            Some(r) if options.axis_fit == AxisFit::Cylinder => r,
            _ => 0.5 * (pr.radius + pt.radius),
        });
        indices_reference.push(pr.indices.clone());
        indices_target.push(pt.indices.clone());
    }
    let pole_rmse = per_pole_rms(&clouds, &best.matches, options.loss, &pose)?;
    // A centroid line sits up to a radius in front of the axis and estimates no radius: its
    // residuals include the pole's thickness, allowed up to LINE_FIT_THICKNESS.
    let allowed = match options.axis_fit {
        AxisFit::Cylinder => MAX_POLE_RMSE,
        AxisFit::Line => MAX_POLE_RMSE + LINE_FIT_THICKNESS,
    };
    if let Some((k, worst)) = pole_rmse
        .iter()
        .copied()
        .enumerate()
        .find(|&(_, r)| !(r.is_finite() && r <= allowed))
    {
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!(
                "pole {k} lies {worst:.3} m (RMS) from its matched axis at the best pose (> \
                 {:.3} m; correct matches stay under 1 cm): the poles found in the two \
                 clouds are not the same poles, or one is barely seen",
                allowed
            ),
        ));
    }
    if let Some(r) = radii.iter().find(|r| !(r.is_finite() && **r <= MAX_RADIUS)) {
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!("a matched pole has a radius of {r:.2} m (> {MAX_RADIUS} m): not a pole"),
        ));
    }
    let report = reports[chosen];
    let covariance = report.as_ref().and_then(|r| r.covariance());
    let rmse = best.axis_rms;
    let initial = starts[chosen];
    clock.lap("choose");
    // The poles hold the pose only as well as a few hundred tape points can: two near-parallel
    // axes leave the height along them and the tilt loosely held (4-8 cm and up to 1.5 degrees
    // off in 1000 adversarial scenes with 2-3 cm noise), which the check then refuses. The
    // scene's surfaces settle those: when the pole pose fails the check, the check's local
    // re-alignment from it is taken if it stays near it, the poles still lie within
    // MAX_POLE_RMSE of their axes there and it passes the check (the pole-only pose fits the
    // tape's noise too: at the true pose of noisy units the RMS is 2-4 cm, not 1-2). A pole pose
    // that passes is kept: on clean scans it is the more precise (20 simulated scenes: median
    // 2.7 mrad / 1.35 cm against 3.1 mrad / 1.5 cm).
    let pair = PreparedPair::new(reference, target, &options.check)?;
    let first = pair.check(&pose)?;
    let (pose, pole_rmse, check) = match first.refusal() {
        None => (pose, pole_rmse, first),
        Some(refused) => {
            // A centroid line's residuals include the pole's thickness (up to 25 cm allowed):
            // they cannot tell whether the poles still fit, and the scene then moved one of 20
            // simulated line-fit results 19 cm along a direction it holds only weakly.
            if options.axis_fit != AxisFit::Cylinder {
                return Err(refused);
            }
            let aligned = first.aligned;
            let (angle, distance) = pose_error(&aligned, &pose);
            if angle > SCENE_REFINE_ANGLE || distance > SCENE_REFINE_DISTANCE {
                return Err(refused);
            }
            let rms = per_pole_rms(&clouds, &best.matches, options.loss, &aligned)?;
            if !rms.iter().all(|r| r.is_finite() && *r <= MAX_POLE_RMSE) {
                return Err(refused);
            }
            match pair.check(&aligned)? {
                c if c.failure.is_none() => (aligned, rms, c),
                _ => return Err(refused),
            }
        }
    };
    clock.lap("certify");
    Ok(PoleCalibration {
        check,
        reference_from_target: pose,
        initial_reference_from_target: initial,
        poles_reference,
        poles_target,
        radii,
        indices_reference,
        indices_target,
        extractions: [ext_ref, ext_tgt],
        ambiguous: margin < AMBIGUITY_MARGIN,
        hypotheses,
        chosen,
        margin,
        rmse,
        pole_rmse,
        report,
        covariance,
        timings: clock.finish(),
    })
}

fn per_pole_rms(
    clouds: &Clouds<'_>,
    matches: &[(usize, usize, i8)],
    loss: Loss,
    pose: &Isometry3<f64>,
) -> Result<Vec<f64>> {
    let problem = point_to_axis_problem(clouds, matches, loss)?;
    let residuals = problem.residuals(pose);
    let mut out = Vec::with_capacity(matches.len());
    let mut start = 0;
    let sizes: Vec<usize> = problem.groups().iter().map(|g| g.points.len()).collect();
    for pair in sizes.chunks(2) {
        let n: usize = pair.iter().sum();
        let sum: f64 = residuals
            .get(start..start + n)
            .unwrap_or(&[])
            .iter()
            .map(|(v, _)| v[0] * v[0] + v[1] * v[1])
            .sum();
        out.push((sum / n.max(1) as f64).sqrt());
        start += n;
    }
    Ok(out)
}

fn base_pair(poles: &[DetectedPole]) -> Option<(usize, usize)> {
    for i in 0..poles.len() {
        for j in i + 1..poles.len() {
            if angle_between_lines(&poles[i].axis, &poles[j].axis) >= MIN_POLE_ANGLE {
                return Some((i, j));
            }
        }
    }
    None
}

fn check_poles(extraction: &PoleExtraction, which: &str) -> Result<()> {
    let n = extraction.poles.len();
    let rejected = || {
        if extraction.rejected.is_empty() {
            String::new()
        } else {
            let parts: Vec<String> = extraction
                .rejected
                .iter()
                .map(|r| format!("{} points: {}", r.size, r.reason))
                .collect();
            format!("; rejected clusters: {}", parts.join("; "))
        }
    };
    if n < 2 {
        return Err(Error::calibration(FailureKind::TooFewFeatures, format!(
            "{which} cloud: found {n} pole(s) among {} bright points (intensity >= {:.1}); need two \
             non-parallel taped poles{}",
            extraction.bright_points,
            extraction.intensity_threshold,
            rejected()
        )));
    }
    if base_pair(&extraction.poles).is_none() {
        let widest = (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .map(|(i, j)| angle_between_lines(&extraction.poles[i].axis, &extraction.poles[j].axis))
            .fold(0.0, f64::max);
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
            "{which} cloud: the {n} poles are parallel within {:.1} deg (widest angle {:.2} deg): \
             they do not determine the rotation about them",
            MIN_POLE_ANGLE.to_degrees(),
            widest.to_degrees()
        ),
        ));
    }
    Ok(())
}

fn with_cloud(e: Error, which: &str) -> Error {
    match e {
        Error::Degenerate(m) => {
            Error::calibration(FailureKind::TooFewFeatures, format!("{which} cloud: {m}"))
        }
        e @ Error::Calibration { .. } => e.context(&format!("{which} cloud")),
        Error::InvalidInput(m) => Error::InvalidInput(format!("{which} cloud: {m}")),
        other => other,
    }
}

/// The smallest and largest coordinate of `points` along `axis`, measured from `origin`.
fn extent_along(points: &[Point3<f64>], origin: &Point3<f64>, axis: &Vector3<f64>) -> (f64, f64) {
    points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let s = (p - origin).dot(axis);
            (lo.min(s), hi.max(s))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::se3_exp;
    use nalgebra::Vector6;

    #[test]
    fn vendor_thresholds() {
        assert_eq!(Vendor::from_name("Velodyne").unwrap().threshold(), 230.0);
        for v in ["hesai", "leishen", "robosense"] {
            assert_eq!(Vendor::from_name(v).unwrap().threshold(), 200.0);
        }
        assert!(Vendor::from_name("ouster").is_err());
    }

    #[test]
    fn data_threshold_splits_the_bright_tail() {
        let mut v: Vec<f64> = (0..1000).map(|i| 5.0 + (i % 76) as f64).collect();
        v.extend((0..20).map(|i| 235.0 + i as f64));
        let t = data_threshold(&v).unwrap();
        assert!(t > 80.0 && t < 235.0, "{t}");
        let flat: Vec<f64> = (0..1000).map(|i| (i % 256) as f64).collect();
        assert!(matches!(
            data_threshold(&flat),
            Err(Error::Calibration { .. })
        ));
    }

    #[test]
    fn closed_form_recovers_a_pose_from_two_axes() {
        let truth = se3_exp(&Vector6::new(0.3, -1.2, 0.4, 0.2, -0.1, 2.5));
        let a = Line::new(Point3::new(5.0, -1.0, 0.0), Vector3::new(0.1, 0.0, 1.0)).unwrap();
        let b = Line::new(Point3::new(5.5, 2.0, 0.3), Vector3::new(-0.1, 0.2, 1.0)).unwrap();
        let inv = truth.inverse();
        // Target axes through other points of the same lines.
        let ta = Line::new(
            inv * (a.point + a.direction.into_inner() * 0.7),
            inv.rotation * a.direction.into_inner(),
        )
        .unwrap();
        let tb = Line::new(
            inv * (b.point - b.direction.into_inner() * 1.3),
            inv.rotation * b.direction.into_inner(),
        )
        .unwrap();
        let got = closed_form(&[(a, ta), (b, tb)]).unwrap();
        let err = got.inverse() * truth;
        assert!(err.rotation.angle() < 1e-9 && err.translation.vector.norm() < 1e-9);
        // The global sign flip fits the axes equally well but is another rotation.
        let flipped = closed_form(&[(a, ta.reversed()), (b, tb.reversed())]).unwrap();
        let err = flipped.inverse() * truth;
        assert!((err.rotation.angle() - std::f64::consts::PI).abs() < 1e-6);
        // Parallel axes leave the translation along them free.
        assert!(closed_form(&[(a, ta), (a, ta)]).is_err());
    }
}
