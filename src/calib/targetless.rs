//! Targetless calibration from the planes of an ordinary scene (road, yard, hall): no target, no
//! initial guess, any mounting (the side units of a road rig are tilted ~45 degrees).
//!
//! # Pipeline
//! 1. **Downsample.** Each cloud is reduced to voxel centroids ([`TargetlessOptions::voxel_size`]),
//!    which evens out a spinning LiDAR's density and bounds the work.
//! 2. **Planes.** Up to [`TargetlessOptions::max_planes`] distinct planes per cloud
//!    ([`segment_planes`]: flat patches of [`PATCH_SIZE`] grown into surfaces and merged where
//!    they continue one another, as an uneven road does, plus sequential RANSAC for the few scan
//!    lines a tilted unit puts on a facade, which make no flat patch). Each keeps its inlier
//!    count, centroid and extent ([`PlaneFeature`]). The inlier threshold is `3 sigma` of each
//!    cloud's noise ([`estimate_threshold`]) unless given.
//! 3. **Hypotheses.** Two non-parallel planes fix the rotation: for every pair of reference planes
//!    at least [`MIN_PAIR_ANGLE`] from parallel and every ordered pair of target planes whose
//!    normals make the same angle (within [`TargetlessOptions::normal_tolerance`]), Kabsch on the
//!    two unit normals and their cross product gives `R` (normals are oriented toward their
//!    sensor, so the handedness is kept and mirror matches never arise). The pair gives two
//!    components of `t` (`n_ref . t = d_tgt - d_ref` per matched plane). A third target plane
//!    out of the pair's span, matched to a reference plane of the same normal, gives the third: a
//!    **triplet** hypothesis, solved by least squares on the three planes. The pair is also a
//!    hypothesis of its own (a street of ground and facades has no third plane; in a street grid
//!    the third plane matched by its normal may be another facade): its third component is left
//!    at the minimum-norm value (sensors of one rig are close together) and is settled by its
//!    slide and by ICP.
//!    **Ground sweep** ([`TargetlessOptions::ground_sweep`]): the largest plane of each cloud (the
//!    road) levelled onto the other's and turned about its normal in [`SWEEP_STEP`] steps, the
//!    in-plane translation left to ICP; this covers scenes that share no plane pair.
//!    **Slides**: a pair hypothesis starts at the minimum-norm translation, which is as far from
//!    the truth along the free direction as the sensors are apart along it (3 m for a unit at the
//!    back of a car) and beyond the reach of ICP. Each of the best pair hypotheses also gets a
//!    slid copy, moved along its free direction by the multiple of [`SLIDE_STEP`] whose sampled
//!    points agree best with the reference (and violate its free space least).
//! 4. **Verification.** Pair hypotheses are deduplicated (1 degree, 10 cm) and ranked by the
//!    planes they bring into agreement (a target plane agrees with a reference plane when their
//!    normals are within the tolerance and, where the hypothesis fixes it, their offsets within
//!    [`TargetlessOptions::offset_tolerance`]), weighted by inliers. The best
//!    [`TargetlessOptions::max_verified`], their slid copies and the sweep hypotheses are
//!    screened (a quick ICP and score), and the best [`SCREEN_KEEP`] distinct ones get a longer ICP and the full score: the
//!    share of target points within [`VERIFY_DISTANCE`] of a reference point minus
//!    [`VIOLATION_WEIGHT`] times the free-space violations both ways ([`crate::visibility`]:
//!    points that land in space the other sensor saw through). Point agreement alone prefers the
//!    180-degree turn of some streets; the violations reject it. The best score of a pose more
//!    than 2 degrees or 30 cm away is the second best; when it reaches [`AMBIGUITY_RATIO`] of the
//!    best after both are polished, the result is refused as ambiguous (or flagged) unless the
//!    check ([`crate::check`]) passes the best and rules the rival out: a rival turned at least
//!    10 degrees from the best whose overlap leaves a direction unconstrained (a half turn whose
//!    agreement comes from sliding along a wall) or that puts more points into free space than
//!    the check allows is no rival, and the next close contender is examined instead. A rival
//!    the check refuses only because its local re-alignment moves it (a pose not settled) still
//!    counts, and so does a slide of the best pose itself.
//!    **Symmetry probes**: the hypotheses never enumerate a scene's symmetries on purpose, and
//!    when the two sensors' fields of view differ the truth can rank below its own mirror image
//!    and never be verified (a corridor or a room is the same box turned half a turn about its
//!    axis: floor onto ceiling, walls swapped). So the best pose is also turned half a turn about
//!    each axis of the largest reference planes (normals, and the lines two of them share) through
//!    the reference centroid and through its middle along the normals (a room's own centre); each
//!    turn is settled by ICP and scored, and one that comes within
//!    [`AMBIGUITY_RATIO`] of the best (and is not ruled out by the check) makes the result
//!    ambiguous.
//!    **Challengers**: hypotheses up to [`TargetlessOptions::challenger_range`] times
//!    [`TargetlessOptions::max_translation`] away are verified as well but never returned. When
//!    one verifies best, the scene says the sensors are further apart than allowed and the
//!    calibration is refused as out of range; when one comes within
//!    [`CHALLENGER_AMBIGUITY_RATIO`] of the best, as ambiguous. Without them, sensors 5-8 m apart
//!    came back as the best pose within 5 m: a quarter turn, a half turn or a shift along the
//!    street.
//! 5. **Refinement.** Every target plane that agrees with a reference plane at the winning pose is
//!    matched; Levenberg–Marquardt minimises the symmetric point-to-plane cost over all matched
//!    planes (exact per-plane sufficient statistics, [`PlaneMomentsProblem`]). Then, unless
//!    disabled, point-to-plane ICP on the whole (downsampled) clouds ([`point_to_plane_icp`]),
//!    with a shrinking correspondence distance and a Cauchy loss, so the part of each scan the
//!    other sensor does not see drops out.
//! 6. **Observability.** The calibration is refused when the data do not constrain all six
//!    degrees of freedom: the weakest direction of the translation (and rotation) information of
//!    the final problem (`sum w n n^T` over the ICP correspondences, or over the matched planes
//!    without ICP) must hold at least [`TargetlessOptions::min_information_share`] of it. A
//!    corridor (floor and parallel walls) has none along its axis and is refused with that
//!    direction named; so is a pose that only planes constrain when their normals span fewer than
//!    three directions. It is also refused when ICP carried the target beyond
//!    [`TargetlessOptions::max_translation`].
//!
//! # Limits
//! * Both sensors must see at least two common non-parallel planes (the ground and one facade
//!   suffice); the verification needs a few hundred common points.
//! * On a straight street of ground and facades only, the translation along the street comes
//!   from the other structures ICP sees in both clouds (trunks, poles, kerbs, parked cars): its
//!   share of the information is reported (`weakest_translation`) and the calibration is refused
//!   when it is too small.
//!
//! # Example
#![cfg_attr(feature = "sim", doc = "```")]
#![cfg_attr(not(feature = "sim"), doc = "```ignore")]
//! use lidarcal::calib::targetless::{calibrate_targetless, TargetlessOptions};
//! use lidarcal::sim::scenes::{street_scene, StreetOptions};
//!
//! let scene = street_scene(&StreetOptions::default())?;
//! let result = calibrate_targetless(
//!     &scene.reference.positions(),
//!     &scene.target.positions(),
//!     &TargetlessOptions::default(),
//! )?;
//! let error = result.reference_from_target.inverse() * scene.reference_from_target;
//! assert!(error.rotation.angle() < 0.005 && error.translation.vector.norm() < 0.05);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::cell::OnceCell;
use std::collections::{HashMap, HashSet};

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3};

use super::planes::estimate_threshold;
use super::{Stopwatch, Timings};
use crate::check::{certify, CheckOptions, CheckReport, PreparedPair, Verdict};
use crate::error::{ensure_finite, ensure_positive, Error, FailureKind, Result};
use crate::fit::Moments;
use crate::geometry::{rotation_angle, Plane};
use crate::icp::{
    point_to_plane_fit, point_to_plane_icp, voxel_downsample, weakest_direction, IcpOptions,
    IcpResult, SurfaceCloud,
};
use crate::kabsch::kabsch;
use crate::lm::{solve, LmOptions, LmReport};
use crate::ransac::plane::ransac_plane;
use crate::ransac::RansacOptions;
use crate::residuals::{Frame, PlaneMomentGroup, PlaneMomentsProblem};
use crate::visibility::RangeImage;

/// Two planes of a hypothesis pair must be at least this far from parallel (radians, 30 degrees).
pub const MIN_PAIR_ANGLE: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// A third plane completes a triplet when its normal leaves the pair's span by at least this
/// angle (radians, 20 degrees).
pub const MIN_THIRD_ANGLE: f64 = 20.0 * std::f64::consts::PI / 180.0;
/// Most hypotheses enumerated (pairs and triplets, before deduplication).
pub const MAX_HYPOTHESES: usize = 50_000;
/// Hypotheses within this rotation (radians, 1 degree) ...
pub const DUPLICATE_ANGLE: f64 = 1.0 * std::f64::consts::PI / 180.0;
/// ... and translation (metres) of each other are one.
pub const DUPLICATE_DISTANCE: f64 = 0.1;
/// Two verified hypotheses further apart than this rotation (radians, 2 degrees) ...
pub const DISTINCT_ANGLE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// ... or this translation (metres) are different answers (for the second-best score).
pub const DISTINCT_DISTANCE: f64 = 0.3;
/// A verified target point agrees when a reference point lies within this distance (metres).
pub const VERIFY_DISTANCE: f64 = 0.25;
/// Target points (at most, by a fixed stride) scored in the verification.
pub const VERIFY_SAMPLES: usize = 800;
/// Reference points (at most, by a fixed stride) checked against the target's free space.
pub const VERIFY_REFERENCE_SAMPLES: usize = 2000;
/// Weight of the free-space violations in the verification score: `score = agreement -
/// VIOLATION_WEIGHT (v_target + v_reference)`, each `v` the share of a cloud's checked points that
/// fall into space the other sensor saw through ([`crate::visibility`]).
pub const VIOLATION_WEIGHT: f64 = 3.0;
/// Yaw step of the ground sweep (radians, 15 degrees): the hypotheses that level the largest
/// plane of each cloud onto the other's and turn about its normal.
pub const SWEEP_STEP: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// Largest planes of the target tried as the reference's largest plane in the ground sweep.
pub const SWEEP_TARGET_PLANES: usize = 1;
/// Step (metres) of the slide of a plane-pair hypothesis along the direction its planes leave
/// free (the axis of a street): see the module docs, step 3.
pub const SLIDE_STEP: f64 = 0.5;
/// Farthest a hypothesis slides (metres) when [`TargetlessOptions::max_translation`] is larger
/// (or infinite).
pub const SLIDE_RANGE: f64 = 10.0;
/// A slid target point agrees when it lands in a cell of this side (metres) that holds a reference
/// point: as coarse as the step, so the best offset is found before any ICP.
pub const SLIDE_CELL: f64 = 0.5;
/// Iterations of the final ICP (default of `TargetlessOptions::icp_options.max_iterations`). On
/// a sparse 16-beam scan the pose keeps creeping 0.5-1 mm per iteration along the weakest
/// direction for tens of iterations; at 30, eight solvable adversarial scenes (of 1000) were
/// refused as unsettled that settle on the truth within 100.
pub const FINAL_ICP_ITERATIONS: usize = 100;
/// Verified hypotheses within [`DISTINCT_ANGLE`] / [`DISTINCT_DISTANCE`] of the winner (the same
/// answer to the ranking) that are also run through the final ICP; the one that settles elsewhere
/// and keeps the other sensor's free space clearer replaces the result (the plane refinement's
/// pose is the other candidate; see [`SCORE_MARGIN`]).
pub const NEAR_ALTERNATIVES: usize = 2;
/// Poses within this angle (radians, 0.5 deg) ...
pub const SETTLED_ANGLE: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// ... and this distance (metres) are one result: the check's default detectable error.
pub const SETTLED_DISTANCE: f64 = 0.06;
/// A candidate replaces the final ICP result when it puts fewer points into the other sensor's
/// free space and its score on the check's figures, `agreement - VIOLATION_WEIGHT violations`
/// (as in the verification), is higher by at least this much, and it passes the check.
pub const SCORE_MARGIN: f64 = 0.02;
/// Pairs of the best pose and a close contender polished by the full ICP before the result is
/// called ambiguous or not (see the verification in [`calibrate_targetless`]).
pub const MAX_POLISHED: usize = 4;
/// Largest reference planes whose normals (and the lines they share) give the half turns of
/// [`half_turns`].
const SYMMETRY_PLANES: usize = 3;
/// Two planes share a line for [`half_turns`] when their normals are at least this far from
/// parallel (the sine of the angle between them, ~12 degrees).
const MIN_AXIS_NORM: f64 = 0.2;
/// Axes closer than this (the cosine of 10 degrees) are one.
const SAME_AXIS_COSINE: f64 = 0.985;
/// Default of [`TargetlessOptions::challenger_range`].
pub const CHALLENGER_RANGE: f64 = 2.0;
/// A challenger (beyond `max_translation`) makes the result ambiguous when it scores at least
/// this share of the best (a pose within range does from [`AMBIGUITY_RATIO`]).
pub const CHALLENGER_AMBIGUITY_RATIO: f64 = 0.9;
/// Target points (at most, by a fixed stride) scored at every slide offset.
pub const SLIDE_SAMPLES: usize = 400;
/// Offsets closer than this to the hypothesis' own (metres) are left to its screening ICP.
pub const SLIDE_MIN: f64 = 0.75;
/// Local maxima of the slide score of the best pose probed for a repeated structure (see
/// [`calibrate_targetless`]).
const SLIDE_PEAKS: usize = 2;
/// A slid copy of the best pose (a repeated structure one period off) that passes the check makes
/// the result ambiguous when the best pose puts more than this share of the points into the other
/// sensor's free space (the larger of the two ways; the truth of a simulated scene puts under
/// 1 %) ...
const SLID_FREE_SPACE_MIN: f64 = 0.01;
/// ... and the slid copy at most this fraction of the best pose's share.
const SLID_FREE_SPACE_RATIO: f64 = 0.5;
/// Target points (at most, by a fixed stride) scored in the screening of every hypothesis.
pub const SCREEN_SAMPLES: usize = 300;
/// Reference points (at most, by a fixed stride) checked against the target's free space in the
/// screening.
pub const SCREEN_REFERENCE_SAMPLES: usize = 700;
/// Distinct hypotheses (best screening scores) that go on to the full verification.
pub const SCREEN_KEEP: usize = 12;
/// The result is ambiguous when a distinct pose scores at least this share of the best. At 0.8,
/// two adversarial rooms and corners whose runner-up scored 78-79 % came back 107-120 degrees
/// off; the real pairs' runner-ups score at most 70 %.
pub const AMBIGUITY_RATIO: f64 = 0.75;
/// Bounds of the inlier threshold taken from the noise estimate (metres). Road scenes are not
/// flat (camber, kerbs, pavements): when the estimate fails or exceeds the upper bound, the upper
/// bound is used.
pub const ESTIMATED_THRESHOLD_RANGE: (f64, f64) = (0.03, 0.1);
/// Side of the cubic cells whose points form the local patches of the plane segmentation (m).
pub const PATCH_SIZE: f64 = 1.0;
/// Fewest (downsampled) points of a patch.
pub const PATCH_MIN_POINTS: usize = 5;
/// A patch is flat when the RMS distance of its points to their plane is under this fraction of
/// the inlier threshold ...
pub const PATCH_MAX_THICKNESS: f64 = 0.8;
/// ... and its points spread at least this far (metres, RMS) along its second axis (not a line).
pub const PATCH_MIN_SPREAD: f64 = 0.1;
/// A neighbouring patch joins a growing plane when its normal is within this angle (radians,
/// 10 degrees) of the plane's ...
pub const GROW_ANGLE: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// ... and its centroid within this many inlier thresholds of the plane.
pub const GROW_OFFSET: f64 = 2.0;
/// A segmented plane within this angle (radians, 5 degrees) ...
pub const MERGE_ANGLE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// ... and offset (metres) of a larger one is another part of the same surface (an uneven road)
/// and is not kept as a plane of its own.
pub const MERGE_OFFSET: f64 = 0.3;
/// RANSAC hypotheses per sequentially extracted plane.
pub const PLANE_RANSAC_ITERATIONS: usize = 1000;
/// Points (at most, by a fixed stride) each sequential RANSAC run samples and scores; the
/// inliers are then collected from all remaining points.
pub const SEQUENTIAL_SAMPLES: usize = 15_000;
/// Smallest extent of a plane along its second in-plane axis (metres).
pub const MIN_PLANE_WIDTH: f64 = 1.0;

/// Options of [`calibrate_targetless`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetlessOptions {
    /// Plane inlier distance (metres), or `None` to estimate it per cloud (3 sigma, within
    /// [`ESTIMATED_THRESHOLD_RANGE`]).
    pub distance_threshold: Option<f64>,
    /// Voxel side of the downsampling (metres).
    pub voxel_size: f64,
    /// Most planes extracted per cloud.
    pub max_planes: usize,
    /// Fewest inliers (voxels) of a plane.
    pub min_inliers: usize,
    /// Angles between normals that agree (radians).
    pub normal_tolerance: f64,
    /// Offsets of planes that agree (metres).
    pub offset_tolerance: f64,
    /// Hypotheses polished by a short ICP and scored by point agreement.
    pub max_verified: usize,
    /// Largest distance between the sensors (metres): the sensors of one rig are a few metres
    /// apart at most. Poses beyond it are never returned. `f64::INFINITY` keeps all.
    pub max_translation: f64,
    /// Hypotheses up to this multiple of `max_translation` away are verified too, as
    /// **challengers** (see the module docs, step 4): never returned, but when one verifies
    /// best the calibration is refused as out of range, and when one comes within
    /// [`CHALLENGER_AMBIGUITY_RATIO`] of the best, as ambiguous. In 1000 adversarial scenes
    /// every wrong answer for sensors 5.3-8 m apart (a shift along the street, a quarter or half
    /// turn) was the best pose within 5 m. The price: on streets that repeat themselves along
    /// their axis a pose beyond the bound can fit as well as the truth within it, and the
    /// calibration is refused. `1.0` trusts the bound (no challengers); at least 1.
    pub challenger_range: f64,
    /// Run the final ICP on the whole clouds.
    pub icp: bool,
    /// Options of the final ICP.
    pub icp_options: IcpOptions,
    /// Smallest share of the translation (and rotation) information in its weakest direction;
    /// below it the calibration is refused as unobservable.
    pub min_information_share: f64,
    /// Also hypothesise from the largest plane of each cloud (the ground of a road scene) turned
    /// about its normal in steps of [`SWEEP_STEP`], each polished by ICP: this finds the pose
    /// when the clouds share no pair of non-parallel planes.
    pub ground_sweep: bool,
    /// Refuse (rather than flag [`TargetlessCalibration::ambiguous`]) when a distinct pose
    /// verifies almost as well as the best ([`AMBIGUITY_RATIO`]).
    pub refuse_ambiguous: bool,
    /// Seed of the RANSAC sampler.
    pub seed: u64,
    /// The final check every result must pass ([`crate::check`]).
    pub check: CheckOptions,
}

impl Default for TargetlessOptions {
    fn default() -> Self {
        TargetlessOptions {
            distance_threshold: None,
            voxel_size: 0.1,
            max_planes: 10,
            min_inliers: 30,
            normal_tolerance: 5f64.to_radians(),
            offset_tolerance: 0.3,
            max_verified: 24,
            max_translation: 5.0,
            challenger_range: CHALLENGER_RANGE,
            icp: true,
            icp_options: IcpOptions {
                max_iterations: FINAL_ICP_ITERATIONS,
                ..IcpOptions::default()
            },
            min_information_share: 0.01,
            ground_sweep: true,
            refuse_ambiguous: true,
            seed: 0,
            check: CheckOptions::default(),
        }
    }
}

impl TargetlessOptions {
    fn validate(&self) -> Result<()> {
        if let Some(t) = self.distance_threshold {
            ensure_positive("distance_threshold", t)?;
        }
        ensure_positive("voxel_size", self.voxel_size)?;
        ensure_positive("normal_tolerance", self.normal_tolerance)?;
        ensure_positive("offset_tolerance", self.offset_tolerance)?;
        if self.max_translation.is_nan() || self.max_translation <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "max_translation must be positive (or inf), got {}",
                self.max_translation
            )));
        }
        if !(0.0..1.0 / 3.0).contains(&self.min_information_share) {
            return Err(Error::InvalidInput(format!(
                "min_information_share must be in [0, 1/3), got {}",
                self.min_information_share
            )));
        }
        if self.challenger_range.is_nan() || self.challenger_range < 1.0 {
            return Err(Error::InvalidInput(format!(
                "challenger_range must be at least 1 (or inf), got {}",
                self.challenger_range
            )));
        }
        if self.max_planes < 2 || self.max_verified == 0 || self.min_inliers < 3 {
            return Err(Error::InvalidInput(format!(
                "need max_planes >= 2, max_verified >= 1 and min_inliers >= 3; got {}, {}, {}",
                self.max_planes, self.max_verified, self.min_inliers
            )));
        }
        Ok(())
    }
}

/// A plane of one cloud with what the matching uses.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneFeature {
    /// The plane, normal toward the sensor.
    pub plane: Plane,
    /// Indices of its inliers in the downsampled cloud.
    pub voxels: Vec<usize>,
    /// Centroid of the inliers.
    pub centroid: Point3<f64>,
    /// Extent of the inliers along their two principal in-plane axes (metres, larger first:
    /// `sqrt(12 l)` of the scatter eigenvalues, the side of a uniform patch).
    pub extent: [f64; 2],
}

/// Result of [`calibrate_targetless`].
#[derive(Debug, Clone, PartialEq)]
pub struct TargetlessCalibration {
    /// The final check's report (its verdict is always consistent: other poses are refused).
    pub check: CheckReport,
    /// The calibrated `reference_from_target`.
    pub reference_from_target: Isometry3<f64>,
    /// The winning hypothesis (planes only, before any refinement).
    pub initial_reference_from_target: Isometry3<f64>,
    /// The matched planes in the reference frame (row `i` matches `planes_target[i]`).
    pub planes_reference: Vec<Plane>,
    /// The matched planes in the target frame.
    pub planes_target: Vec<Plane>,
    /// Indices into the reference input of each matched plane's points.
    pub inliers_reference: Vec<Vec<usize>>,
    /// Indices into the target input of each matched plane's points.
    pub inliers_target: Vec<Vec<usize>>,
    /// RMS point-to-plane residual of each matched plane at the result (both clouds).
    pub rmse: Vec<f64>,
    /// Planes extracted from the reference and the target cloud.
    pub features: [Vec<PlaneFeature>; 2],
    /// Hypotheses enumerated and, after deduplication, distinct ones.
    pub hypotheses: [usize; 2],
    /// Hypotheses verified by ICP.
    pub verified: usize,
    /// Whether the winning hypothesis came from a plane triplet (all three translation
    /// components from planes) rather than a pair.
    pub triplet: bool,
    /// Whether the winning hypothesis came from the ground sweep.
    pub sweep: bool,
    /// Verification score of the best hypothesis: the share of target points within
    /// [`VERIFY_DISTANCE`] of a reference point, minus [`VIOLATION_WEIGHT`] times the free-space
    /// violations ([`TargetlessCalibration::violations`]).
    pub best_score: f64,
    /// Best verification score of a hypothesis ending at a different pose (0 when none).
    pub second_score: f64,
    /// Share of the best hypothesis' checked target points within [`VERIFY_DISTANCE`] of a
    /// reference point.
    pub agreement: f64,
    /// Free-space violations of the best hypothesis: the share of checked target points in space
    /// the reference saw through, and of reference points in space the target saw through.
    pub violations: [f64; 2],
    /// `true` when a distinct pose scored at least [`AMBIGUITY_RATIO`] of the best (only
    /// returned when [`TargetlessOptions::refuse_ambiguous`] is off).
    pub ambiguous: bool,
    /// Inlier thresholds used for the reference and the target cloud (metres).
    pub distance_thresholds: [f64; 2],
    /// Levenberg–Marquardt report of the plane refinement.
    pub report: Option<LmReport>,
    /// The final ICP (`None` when disabled).
    pub icp: Option<IcpResult>,
    /// Weakest translation direction (reference frame) of the final problem and its share of
    /// the information.
    pub weakest_translation: (Vector3<f64>, f64),
    /// Weakest rotation axis of the final problem and its share.
    pub weakest_rotation: (Vector3<f64>, f64),
    /// Share of the weakest translation direction spanned by the matched planes' normals alone.
    pub plane_translation_share: f64,
    /// Covariance of the left-perturbation tangent `[rho; phi]` of the result (from ICP when it
    /// ran, else from the plane refinement).
    pub covariance: Option<Matrix6<f64>>,
    /// Stage timings.
    pub timings: Timings,
}

fn check_cloud(points: &[Point3<f64>], which: &str) -> Result<()> {
    if points.len() < 100 {
        return Err(Error::InvalidInput(format!(
            "the {which} cloud has {} points; the targetless method needs at least 100",
            points.len()
        )));
    }
    ensure_finite(which, points.iter().flat_map(|p| p.coords.iter()))
}

fn isometry(rotation: &nalgebra::Rotation3<f64>, t: Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(rotation),
    )
}

/// A downsampled cloud with its planes.
struct Prepared {
    points: Vec<Point3<f64>>,
    owner: Vec<usize>,
    threshold: f64,
    features: Vec<PlaneFeature>,
}

fn prepare(points: &[Point3<f64>], options: &TargetlessOptions) -> Result<Prepared> {
    let (ds, owner) = voxel_downsample(points, options.voxel_size)?;
    let threshold = match options.distance_threshold {
        Some(t) => t,
        None => match estimate_threshold(&ds, options.seed) {
            Ok(t) => t.clamp(ESTIMATED_THRESHOLD_RANGE.0, ESTIMATED_THRESHOLD_RANGE.1),
            Err(Error::Calibration { .. }) => ESTIMATED_THRESHOLD_RANGE.1,
            Err(e) => return Err(e),
        },
    };
    let mut features = segment_planes(&ds, threshold, options.max_planes, options.min_inliers)?;
    let seq = sequential_planes(
        &ds,
        threshold,
        2 * options.max_planes,
        options.min_inliers,
        options.seed,
    )?;
    features.extend(seq);
    let features = distinct(features, 2 * options.max_planes);
    Ok(Prepared {
        points: ds,
        owner,
        threshold,
        features,
    })
}

/// A flat cell of the segmentation.
struct Patch {
    moments: Moments,
    normal: Vector3<f64>,
    centroid: Point3<f64>,
    indices: Vec<usize>,
}

/// Up to `max_planes` distinct planar surfaces of `points` by region growing over flat local
/// patches (see [`PATCH_SIZE`] and the growing constants), largest first. Each plane is refitted
/// on its patches' points; its inliers are those within `threshold`.
pub fn segment_planes(
    points: &[Point3<f64>],
    threshold: f64,
    max_planes: usize,
    min_inliers: usize,
) -> Result<Vec<PlaneFeature>> {
    let mut cells: std::collections::HashMap<[i64; 3], Vec<usize>> =
        std::collections::HashMap::new();
    for (i, p) in points.iter().enumerate() {
        let key = [
            (p.x / PATCH_SIZE).floor() as i64,
            (p.y / PATCH_SIZE).floor() as i64,
            (p.z / PATCH_SIZE).floor() as i64,
        ];
        cells.entry(key).or_default().push(i);
    }
    let mut keys: Vec<[i64; 3]> = cells.keys().copied().collect();
    keys.sort_unstable();
    let mut patches: Vec<Patch> = Vec::new();
    let mut patch_of: std::collections::HashMap<[i64; 3], usize> = std::collections::HashMap::new();
    for key in &keys {
        let Some(indices) = cells.remove(key) else {
            continue;
        };
        if indices.len() < PATCH_MIN_POINTS {
            continue;
        }
        let moments = Moments::from_points(indices.iter().filter_map(|&i| points.get(i)));
        let (values, vectors) = moments.principal_axes();
        let n = moments.weight();
        let thickness = (values[0] / n).sqrt();
        let spread = (values[1] / n).sqrt();
        if thickness > PATCH_MAX_THICKNESS * threshold || spread < PATCH_MIN_SPREAD {
            continue;
        }
        let centroid = moments.mean();
        let mut normal = vectors[0];
        if normal.dot(&centroid.coords) > 0.0 {
            normal = -normal; // toward the sensor
        }
        patch_of.insert(*key, patches.len());
        patches.push(Patch {
            moments,
            normal,
            centroid,
            indices,
        });
    }
    let patch_keys: Vec<[i64; 3]> = {
        let mut v = vec![[0i64; 3]; patches.len()];
        for (k, &i) in &patch_of {
            if let Some(slot) = v.get_mut(i) {
                *slot = *k;
            }
        }
        v
    };
    let mut order: Vec<usize> = (0..patches.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(patches[i].indices.len()));
    let mut assigned = vec![false; patches.len()];
    let mut regions: Vec<Vec<usize>> = Vec::new();
    for &seed in &order {
        if assigned[seed] {
            continue;
        }
        assigned[seed] = true;
        let mut region = vec![seed];
        let mut moments = patches[seed].moments;
        let mut plane = Plane::from_point_normal(&patches[seed].centroid, &patches[seed].normal)?;
        let mut queue = std::collections::VecDeque::from([seed]);
        while let Some(current) = queue.pop_front() {
            if let Ok(fit) = moments.plane() {
                plane = fit.plane;
            }
            let [x, y, z] = patch_keys[current];
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(&j) = patch_of.get(&[x + dx, y + dy, z + dz]) else {
                            continue;
                        };
                        if assigned[j] {
                            continue;
                        }
                        let p = &patches[j];
                        let aligned = p.normal.dot(&plane.normal).abs() > GROW_ANGLE.cos();
                        let near =
                            plane.signed_distance(&p.centroid).abs() < GROW_OFFSET * threshold;
                        if aligned && near {
                            assigned[j] = true;
                            region.push(j);
                            merge_moments(&mut moments, &p.moments);
                            queue.push_back(j);
                        }
                    }
                }
            }
        }
        regions.push(region);
    }
    let mut features: Vec<PlaneFeature> = Vec::new();
    for region in regions {
        let candidates: Vec<usize> = region
            .iter()
            .flat_map(|&r| patches[r].indices.iter().copied())
            .collect();
        if candidates.len() < min_inliers {
            continue;
        }
        let Ok(fit) =
            Moments::from_points(candidates.iter().filter_map(|&i| points.get(i))).plane()
        else {
            continue;
        };
        let plane = fit.plane.oriented_toward(&Point3::origin());
        let mut voxels: Vec<usize> = candidates
            .into_iter()
            .filter(|&i| {
                points
                    .get(i)
                    .is_some_and(|p| plane.signed_distance(p).abs() < threshold)
            })
            .collect();
        voxels.sort_unstable();
        if voxels.len() < min_inliers {
            continue;
        }
        features.extend(feature(points, plane, voxels));
    }
    Ok(distinct(features, max_planes))
}

/// The largest `max_planes` of `features` that are not within [`MERGE_ANGLE`] and
/// [`MERGE_OFFSET`] of a larger one.
fn distinct(mut features: Vec<PlaneFeature>, max_planes: usize) -> Vec<PlaneFeature> {
    features.sort_by_key(|f| std::cmp::Reverse(f.voxels.len()));
    let mut kept: Vec<PlaneFeature> = Vec::new();
    for f in features {
        if kept.len() >= max_planes {
            break;
        }
        let duplicate = kept.iter().any(|k| {
            k.plane.normal.dot(&f.plane.normal) > MERGE_ANGLE.cos()
                && (k.plane.offset - f.plane.offset).abs() < MERGE_OFFSET
        });
        if !duplicate {
            kept.push(f);
        }
    }
    kept
}

/// A plane feature from inlier indices, if it is at least [`MIN_PLANE_WIDTH`] wide.
fn feature(points: &[Point3<f64>], plane: Plane, voxels: Vec<usize>) -> Option<PlaneFeature> {
    let m = Moments::from_points(voxels.iter().filter_map(|&i| points.get(i)));
    let extent = m.extents();
    (extent[1] >= MIN_PLANE_WIDTH).then(|| PlaneFeature {
        plane,
        voxels,
        centroid: m.mean(),
        extent,
    })
}

/// Up to `count` planes by sequential RANSAC (infinite planes, each run on the points the
/// previous ones left). It finds what the patches miss in sparse clouds: a facade crossed by a
/// few scan lines of a tilted unit.
fn sequential_planes(
    points: &[Point3<f64>],
    threshold: f64,
    count: usize,
    min_inliers: usize,
    seed: u64,
) -> Result<Vec<PlaneFeature>> {
    let mut taken = vec![false; points.len()];
    let mut out = Vec::new();
    for run in 0..count {
        let remaining: Vec<usize> = (0..points.len()).filter(|&i| !taken[i]).collect();
        if remaining.len() < min_inliers.max(3) {
            break;
        }
        // RANSAC runs on an even subsample of a large cloud; the inliers are then taken from
        // all remaining points.
        let stride = remaining.len().div_ceil(SEQUENTIAL_SAMPLES).max(1);
        let subset: Vec<Point3<f64>> = remaining
            .iter()
            .step_by(stride)
            .filter_map(|&i| points.get(i).copied())
            .collect();
        let mut options = RansacOptions::new(threshold);
        options.seed = seed.wrapping_add((run as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        options.max_iterations = PLANE_RANSAC_ITERATIONS;
        let found = match ransac_plane(&subset, &options) {
            Ok(f) => f,
            Err(Error::Degenerate(_)) => break,
            Err(e) => return Err(e),
        };
        let voxels: Vec<usize> = remaining
            .iter()
            .copied()
            .filter(|&i| {
                points
                    .get(i)
                    .is_some_and(|p| found.model.signed_distance(p).abs() < threshold)
            })
            .collect();
        if voxels.len() < min_inliers {
            break;
        }
        for &i in &voxels {
            taken[i] = true;
        }
        out.extend(feature(points, found.model, voxels));
    }
    Ok(out)
}

/// Adds the moments `b` into `a` (both shifted to their own origins).
fn merge_moments(a: &mut Moments, b: &Moments) {
    // Moments only exposes point accumulation; rebuild `b`'s contribution from its mean and
    // scatter: adding the scatter's principal components as weighted point pairs is exact.
    let n = b.weight();
    if n <= 0.0 {
        return;
    }
    let mean = b.mean();
    let (values, vectors) = b.principal_axes();
    // Two points at mean +- s v with weight n/2 each per axis reproduce the scatter l v v^T
    // when s = sqrt(l / n); the mean is kept and the total weight is 3n, so scale by 1/3.
    for (l, v) in values.iter().zip(vectors.iter()) {
        let s = (l / n).sqrt() * 3f64.sqrt();
        a.add_weighted(&(mean + v * s), n / 6.0);
        a.add_weighted(&(mean - v * s), n / 6.0);
    }
}

/// The planes [`calibrate_targetless`] extracts from one cloud (steps 1 and 2 of the module docs)
/// and the inlier threshold used; feature voxel indices refer to the downsampled cloud.
pub fn plane_features(
    points: &[Point3<f64>],
    options: &TargetlessOptions,
) -> Result<(Vec<PlaneFeature>, f64)> {
    options.validate()?;
    check_cloud(points, "input")?;
    let p = prepare(points, options)?;
    Ok((p.features, p.threshold))
}

/// A candidate transform from plane correspondences.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    pose: Isometry3<f64>,
    /// Unit direction of translation no plane of the hypothesis fixes (pairs only).
    free: Option<Vector3<f64>>,
    support: f64,
    /// From the ground sweep rather than a plane pair.
    sweep: bool,
}

fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos()
}

/// Least squares `t` from rows `n_i . t = b_i`: the minimum-norm solution when the normals span
/// two directions, with the free direction.
fn solve_translation(
    normals: &[Vector3<f64>],
    rhs: &[f64],
) -> Option<(Vector3<f64>, Option<Vector3<f64>>)> {
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    for (n, b) in normals.iter().zip(rhs) {
        ata += n * n.transpose();
        atb += n * *b;
    }
    let eig = nalgebra::SymmetricEigen::new(ata);
    let largest = eig.eigenvalues.amax();
    if largest <= 0.0 {
        return None;
    }
    let mut t = Vector3::zeros();
    let mut free = None;
    for k in 0..3 {
        let v = eig.eigenvectors.column(k).into_owned();
        let l = eig.eigenvalues[k];
        if l > 0.04 * largest {
            t += v * (v.dot(&atb) / l);
        } else if free.is_none() {
            free = Some(v);
        } else {
            return None; // one direction only
        }
    }
    Some((t, free))
}

/// Keeps the first of each group of candidates within [`DUPLICATE_ANGLE`] and
/// [`DUPLICATE_DISTANCE`] of a kept one, in order. Kept poses are hashed by translation in cells of
/// [`DUPLICATE_DISTANCE`], so a candidate is compared only with those of the 27 neighbouring cells:
/// the same result as comparing with every kept one, without the quadratic cost (a scan of a
/// building with many planes gives ~10 000 scored hypotheses and ~7 000 distinct ones).
fn deduplicate(candidates: Vec<Candidate>) -> Vec<Candidate> {
    let cell = |v: &Vector3<f64>| -> [i64; 3] {
        [0, 1, 2].map(|k| (v[k] / DUPLICATE_DISTANCE).floor() as i64)
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut distinct: Vec<Candidate> = Vec::with_capacity(candidates.len());
    for c in candidates {
        let key = cell(&c.pose.translation.vector);
        let mut duplicate = false;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let near = [key[0] + dx, key[1] + dy, key[2] + dz];
                    let Some(kept) = grid.get(&near) else {
                        continue;
                    };
                    if kept.iter().any(|&i| {
                        distinct.get(i).is_some_and(|d| {
                            same_pose(&d.pose, &c.pose, DUPLICATE_ANGLE, DUPLICATE_DISTANCE)
                        })
                    }) {
                        duplicate = true;
                        break 'search;
                    }
                }
            }
        }
        if !duplicate {
            grid.entry(key).or_default().push(distinct.len());
            distinct.push(c);
        }
    }
    distinct
}

fn same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>, angle: f64, distance: f64) -> bool {
    let d = a.inverse() * b;
    d.rotation.angle() < angle && (a.translation.vector - b.translation.vector).norm() < distance
}

/// Matches every target plane to the best agreeing reference plane under `pose`:
/// `(reference index, target index)` pairs. Offsets are checked except along `free`.
fn agreeing(
    reference: &[PlaneFeature],
    target: &[PlaneFeature],
    pose: &Isometry3<f64>,
    free: Option<&Vector3<f64>>,
    normal_tolerance: f64,
    offset_tolerance: f64,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (j, t) in target.iter().enumerate() {
        let mapped = t.plane.transformed(pose);
        let n = mapped.normal.into_inner();
        let offset_known = free.is_none_or(|v| n.dot(v).abs() < 0.2);
        let mut best: Option<(usize, f64)> = None;
        for (i, r) in reference.iter().enumerate() {
            let angle = angle_between(&n, &r.plane.normal);
            if angle > normal_tolerance {
                continue;
            }
            let gap = (mapped.offset - r.plane.offset).abs();
            if offset_known && gap > offset_tolerance {
                continue;
            }
            let cost = angle / normal_tolerance + if offset_known { gap } else { 1.0 };
            if best.is_none_or(|(_, c)| cost < c) {
                best = Some((i, cost));
            }
        }
        if let Some((i, _)) = best {
            out.push((i, j));
        }
    }
    out
}

fn support(reference: &[PlaneFeature], target: &[PlaneFeature], matches: &[(usize, usize)]) -> f64 {
    matches
        .iter()
        .filter_map(|&(i, j)| Some((reference.get(i)?.voxels.len(), target.get(j)?.voxels.len())))
        .map(|(a, b)| (a.min(b) as f64).sqrt())
        .sum()
}

/// Every pair and triplet hypothesis (step 3 of the module docs); `(enumerated, distinct)`.
fn hypotheses(
    reference: &[PlaneFeature],
    target: &[PlaneFeature],
    options: &TargetlessOptions,
) -> (usize, Vec<Candidate>) {
    let tol = options.normal_tolerance;
    let n_ref: Vec<Vector3<f64>> = reference
        .iter()
        .map(|f| f.plane.normal.into_inner())
        .collect();
    let n_tgt: Vec<Vector3<f64>> = target.iter().map(|f| f.plane.normal.into_inner()).collect();
    let mut raw: Vec<Candidate> = Vec::new();
    let mut enumerated = 0usize;
    'outer: for i in 0..n_ref.len() {
        for j in (i + 1)..n_ref.len() {
            let angle_ref = angle_between(&n_ref[i], &n_ref[j]);
            if !(MIN_PAIR_ANGLE..=std::f64::consts::PI - MIN_PAIR_ANGLE).contains(&angle_ref) {
                continue;
            }
            for k in 0..n_tgt.len() {
                for l in 0..n_tgt.len() {
                    if k == l || (angle_between(&n_tgt[k], &n_tgt[l]) - angle_ref).abs() > tol {
                        continue;
                    }
                    let a = [n_ref[i], n_ref[j], n_ref[i].cross(&n_ref[j]).normalize()];
                    let b = [n_tgt[k], n_tgt[l], n_tgt[k].cross(&n_tgt[l]).normalize()];
                    let Ok(solution) = kabsch(&a, &b, None) else {
                        continue;
                    };
                    let r = solution.rotation;
                    let d = |f: &PlaneFeature| f.plane.offset;
                    let mut rows = vec![n_ref[i], n_ref[j]];
                    let mut rhs = vec![
                        d(&target[k]) - d(&reference[i]),
                        d(&target[l]) - d(&reference[j]),
                    ];
                    let span = a[2];
                    for m in 0..n_tgt.len() {
                        if m == k || m == l {
                            continue;
                        }
                        let mapped = r * n_tgt[m];
                        if mapped.dot(&span).abs() < MIN_THIRD_ANGLE.sin() {
                            continue;
                        }
                        for (p, np) in n_ref.iter().enumerate() {
                            if angle_between(&mapped, np) > tol {
                                continue;
                            }
                            rows.push(*np);
                            rhs.push(d(&target[m]) - d(&reference[p]));
                            if let Some((t, None)) = solve_translation(&rows, &rhs) {
                                raw.push(Candidate {
                                    pose: isometry(&r, t),
                                    free: None,
                                    support: 0.0,
                                    sweep: false,
                                });
                            }
                            rows.pop();
                            rhs.pop();
                            enumerated += 1;
                        }
                    }
                    // The pair alone too, even when thirds were found: a third plane matched
                    // by its normal only may be another facade of the same direction (a street
                    // grid), and then only the pair, slid along its free direction, reaches the
                    // truth.
                    if let Some((t, free)) = solve_translation(&rows, &rhs) {
                        raw.push(Candidate {
                            pose: isometry(&r, t),
                            free,
                            support: 0.0,
                            sweep: false,
                        });
                    }
                    enumerated += 1;
                    if enumerated >= MAX_HYPOTHESES {
                        break 'outer;
                    }
                }
            }
        }
    }
    // Score, then deduplicate keeping the best supported of each cluster.
    let reach = options.max_translation * options.challenger_range;
    raw.retain(|c| c.pose.translation.vector.norm() <= reach);
    for c in &mut raw {
        let matches = agreeing(
            reference,
            target,
            &c.pose,
            c.free.as_ref(),
            tol,
            options.offset_tolerance,
        );
        c.support = support(reference, target, &matches);
    }
    raw.sort_by(|a, b| {
        b.support
            .total_cmp(&a.support)
            .then_with(|| a.free.is_some().cmp(&b.free.is_some()))
    });
    (enumerated, deduplicate(raw))
}

/// The ground-sweep hypotheses (see [`TargetlessOptions::ground_sweep`]): the largest reference
/// plane matched to each of the [`SWEEP_TARGET_PLANES`] largest target planes (normals aligned,
/// offsets equal), turned about its normal in [`SWEEP_STEP`] steps; the in-plane translation is
/// zero (the sensors of one rig are close together) and left to ICP.
fn ground_sweep(reference: &[PlaneFeature], target: &[PlaneFeature]) -> Vec<Candidate> {
    let mut out = Vec::new();
    let Some(ground) = reference.first() else {
        return out;
    };
    let n_ref = ground.plane.normal;
    let steps = (std::f64::consts::TAU / SWEEP_STEP).round() as usize;
    for t in target.iter().take(SWEEP_TARGET_PLANES) {
        let n_tgt = t.plane.normal;
        // Normals face their sensors, so the target plane's normal maps onto the reference's.
        let align = nalgebra::Rotation3::rotation_between(&n_tgt.into_inner(), &n_ref.into_inner())
            .unwrap_or_else(|| {
                // Opposite normals: half a turn about any perpendicular axis.
                let axis = n_ref.cross(&Vector3::x());
                let axis = if axis.norm() > 0.1 {
                    axis
                } else {
                    n_ref.cross(&Vector3::y())
                };
                nalgebra::Rotation3::new(axis.normalize() * std::f64::consts::PI)
            });
        let translation = n_ref.into_inner() * (t.plane.offset - ground.plane.offset);
        for k in 0..steps {
            let turn = nalgebra::Rotation3::from_axis_angle(&n_ref, k as f64 * SWEEP_STEP);
            out.push(Candidate {
                pose: isometry(&(turn * align), translation),
                free: None,
                support: 0.0,
                sweep: true,
            });
        }
    }
    out
}

/// The cells of a cubic grid that hold at least one point: a coarse, constant-time "is there a
/// point near here" for the slide search.
struct Occupancy {
    cell: f64,
    cells: HashSet<[i64; 3]>,
}

impl Occupancy {
    fn key(cell: f64, p: &Point3<f64>) -> [i64; 3] {
        // Inputs are bounded by MAX_COORDINATE; beyond i64 a float-to-int cast saturates.
        [
            (p.x / cell).floor() as i64,
            (p.y / cell).floor() as i64,
            (p.z / cell).floor() as i64,
        ]
    }

    fn new(points: &[Point3<f64>], cell: f64) -> Self {
        let cells = points.iter().map(|p| Self::key(cell, p)).collect();
        Occupancy { cell, cells }
    }

    fn share(&self, points: &[Point3<f64>]) -> f64 {
        let hits = points
            .iter()
            .filter(|p| self.cells.contains(&Self::key(self.cell, p)))
            .count();
        hits as f64 / points.len().max(1) as f64
    }
}

/// The slide score of `pose` moved along `free` by every multiple of [`SLIDE_STEP`] at least
/// [`SLIDE_MIN`] and at most [`SLIDE_RANGE`] away (within `max_translation`), as `(offset,
/// score)` in order of offset: the share of `samples` (target points) that land in a cell
/// holding a reference point, minus [`VIOLATION_WEIGHT`] times the share that lands in space the
/// reference saw through.
fn slide_scores(
    pose: &Isometry3<f64>,
    free: &Vector3<f64>,
    reference: &Occupancy,
    image: &RangeImage,
    samples: &[Point3<f64>],
    max_translation: f64,
) -> Vec<(f64, f64)> {
    let t = pose.translation.vector;
    let steps = (max_translation.min(SLIDE_RANGE) / SLIDE_STEP).ceil() as i64;
    (-steps..=steps)
        .map(|k| k as f64 * SLIDE_STEP)
        .filter(|offset| {
            offset.abs() >= SLIDE_MIN && (t + free * *offset).norm() <= max_translation
        })
        .map(|offset| {
            let moved = Translation3::from(free * offset) * pose;
            let agreement = reference.share(&mapped(samples, &moved));
            let violations = image.count_violations(samples, &moved) as f64;
            (
                offset,
                agreement - VIOLATION_WEIGHT * violations / samples.len().max(1) as f64,
            )
        })
        .collect()
}

/// The [`SLIDE_PEAKS`] best local maxima of the slide score of `pose` along `free`
/// ([`slide_scores`]) that score above zero, as slid poses: where a repeated structure (a
/// colonnade, a row of posts) would put the target one period off.
fn slide_peaks(
    pose: &Isometry3<f64>,
    free: &Vector3<f64>,
    reference: &Occupancy,
    image: &RangeImage,
    samples: &[Point3<f64>],
    max_translation: f64,
) -> Vec<Isometry3<f64>> {
    let scores = slide_scores(pose, free, reference, image, samples, max_translation);
    let mut peaks: Vec<(f64, f64)> = scores
        .iter()
        .enumerate()
        .filter(|&(k, &(offset, score))| {
            let neighbour = |j: Option<usize>| {
                j.and_then(|j| scores.get(j))
                    .filter(|(o, _)| (o - offset).abs() < 1.5 * SLIDE_STEP)
                    .map_or(f64::NEG_INFINITY, |s| s.1)
            };
            score > 0.0 && score > neighbour(k.checked_sub(1)) && score >= neighbour(Some(k + 1))
        })
        .map(|(_, &s)| s)
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks
        .into_iter()
        .take(SLIDE_PEAKS)
        .map(|(offset, _)| Translation3::from(free * offset) * pose)
        .collect()
}

/// The slid copy of each plane-pair hypothesis (step 3 of the module docs): the pose moved along
/// its free direction by the multiple of [`SLIDE_STEP`] (at least [`SLIDE_MIN`] and at most
/// [`SLIDE_RANGE`] away, within `max_translation`) that scores best: the share of sampled target points that land in a
/// [`SLIDE_CELL`] cell holding a reference point, minus [`VIOLATION_WEIGHT`] times the share that
/// lands in space the reference saw through. A pair fixes the translation only across the
/// street; its minimum-norm start is as far from the truth as the sensors are apart along it,
/// beyond the reach of ICP.
fn slides(
    candidates: &[Candidate],
    reference: &Occupancy,
    image: &RangeImage,
    samples: &[Point3<f64>],
    max_translation: f64,
) -> Vec<Candidate> {
    let best_slide = |c: &Candidate| -> Option<Candidate> {
        let free = c.free?;
        let (offset, _) = slide_scores(&c.pose, &free, reference, image, samples, max_translation)
            .into_iter()
            .reduce(|best, s| if s.1 > best.1 { s } else { best })?;
        Some(Candidate {
            pose: Translation3::from(free * offset) * c.pose,
            ..*c
        })
    };
    let slid: Vec<Candidate> = {
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            candidates.par_iter().filter_map(best_slide).collect()
        }
        #[cfg(not(feature = "parallel"))]
        {
            candidates.iter().filter_map(best_slide).collect()
        }
    };
    // Pair hypotheses that differ only along their free direction slide to the same pose.
    deduplicate(slid)
}

/// Options of the quick ICP of the screening (the first stage of the verification), for a
/// plane-pair hypothesis or a ground-sweep one (wider first distance: the start is up to half a
/// step of yaw and the in-plane translation away).
fn screen_icp_options(sweep: bool) -> IcpOptions {
    IcpOptions {
        max_distance: if sweep { 2.0 } else { 1.0 },
        min_distance: 0.5,
        shrink: 0.7,
        max_iterations: if sweep { 7 } else { 3 },
        samples: 300,
        step_tolerance: 1e-4,
    }
}

/// Options of the short ICP that continues from the screened pose of each verified hypothesis.
fn verify_icp_options() -> IcpOptions {
    IcpOptions {
        max_distance: 0.5,
        min_distance: 0.3,
        shrink: 0.7,
        max_iterations: 6,
        samples: 400,
        step_tolerance: 1e-4,
    }
}

/// The final ICP result `main`, or the first of `candidates` (other results for the same answer)
/// that settles elsewhere and fits better on the [`check`](crate::check::check)'s own figures (the
/// two clouds prepared for it once, by `prepare`): it
/// must pass the check, put fewer points into the other sensor's free space (both ways
/// together), and score `agreement - VIOLATION_WEIGHT violations` (the smaller agreement of the
/// two ways) at least [`SCORE_MARGIN`] higher.
///
/// ICP maximises agreement, not free space: on sparse 16-beam corners it settled 16-23 cm off
/// the truth along the weakest direction, a point or two of agreement above the truth but with
/// 3-13 % of the points in space the other sensor saw through (the truth: under 1 %). Both pass
/// the check, whose local re-alignment cannot see the other.
fn prefer_free_space<'a>(
    main: IcpResult,
    candidates: impl IntoIterator<Item = IcpResult>,
    prepare: impl Fn() -> Result<&'a PreparedPair>,
) -> IcpResult {
    // (passes, share of points in free space, score)
    let judge = |pose: &Isometry3<f64>| {
        prepare().and_then(|pair| pair.check(pose)).ok().map(|c| {
            let free = c.violations + c.reverse_violations;
            let agreement = c.agreement.min(c.reverse_agreement);
            (
                c.failure.is_none(),
                free,
                agreement - VIOLATION_WEIGHT * free,
            )
        })
    };
    let mut best = main;
    let mut best_judged = None;
    // Poses already judged: the plane fit and the verified pose are one pose whenever the plane
    // refinement kept the verified pose, and a check costs as much as the ICP.
    let mut judged_poses: Vec<Isometry3<f64>> = Vec::new();
    for candidate in candidates {
        if same_pose(&candidate.pose, &best.pose, SETTLED_ANGLE, SETTLED_DISTANCE)
            || judged_poses.contains(&candidate.pose)
        {
            continue;
        }
        judged_poses.push(candidate.pose);
        if best_judged.is_none() {
            best_judged = judge(&best.pose);
        }
        let (Some((_, free, score)), Some(judged @ (passes, c_free, c_score))) =
            (best_judged, judge(&candidate.pose))
        else {
            continue;
        };
        if passes && c_free < free && c_score >= score + SCORE_MARGIN {
            best = candidate;
            best_judged = Some(judged);
        }
    }
    best
}

/// Whether a pose that puts the share `free` of the points into the other sensor's free space
/// (the larger of the two ways, on the check's figures) keeps it clearly clearer than one that
/// puts `other`: `other` above [`SLID_FREE_SPACE_MIN`] and `free` at most
/// [`SLID_FREE_SPACE_RATIO`] of it.
fn clearer(free: f64, other: f64) -> bool {
    other > SLID_FREE_SPACE_MIN && free <= SLID_FREE_SPACE_RATIO * other
}

/// A hypothesis after its short ICP, with its verification (see [`VIOLATION_WEIGHT`]).
#[derive(Debug, Clone, Copy)]
struct Verified {
    pose: Isometry3<f64>,
    agreement: f64,
    violations: [f64; 2],
    score: f64,
}

/// A rival the check rules out is dismissed only when it is turned at least this far from the best
/// pose (radians, 10 degrees); see `calibrate_targetless`.
const RULED_OUT_TURN: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// Adds the direction of `a` to `axes` unless it is too short (a cross product of two planes
/// within ~12 degrees of parallel, [`MIN_AXIS_NORM`]) or within 10 degrees of one already there.
fn add_axis(axes: &mut Vec<Vector3<f64>>, a: Vector3<f64>) {
    let norm = a.norm();
    if norm > MIN_AXIS_NORM
        && axes
            .iter()
            .all(|b| (a.dot(b) / norm).abs() < SAME_AXIS_COSINE)
    {
        axes.push(a / norm);
    }
}

/// Unit normals of the [`SYMMETRY_PLANES`] largest reference planes.
fn largest_normals(features: &[PlaneFeature]) -> Vec<Vector3<f64>> {
    features
        .iter()
        .take(SYMMETRY_PLANES)
        .map(|f| f.plane.normal.into_inner())
        .collect()
}

/// Unit directions of the lines planes of these `normals` share, two by two ([`add_axis`]).
fn shared_lines(normals: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let mut lines = Vec::new();
    for (i, a) in normals.iter().enumerate() {
        for b in normals.iter().skip(i + 1) {
            add_axis(&mut lines, a.cross(b));
        }
    }
    lines
}

/// Half turns about the axes of the largest reference planes (their normals and the lines two of
/// them share, [`SYMMETRY_PLANES`] planes), each through the centroid of the reference points and
/// through their middle ([`middle`], when it lies [`DISTINCT_DISTANCE`] or more away): the
/// symmetries a corridor, a room or a box would have. A corridor turned about its axis is the
/// same box (floor onto ceiling, walls swapped), and when the two sensors' fields of view differ
/// the hypotheses of the truth rank below those of the flip and may never be verified: a 16-beam
/// unit turned upside down put 80 % of its points near the 32-beam reference, the truth 61 %. A
/// room's own centre is its middle, not the centroid, which leans toward the walls the sensor
/// sees best: two rooms turned about the vertical came back 180 degrees off while the turns
/// through the centroid settled metres away. Each turn, applied to the best pose and settled by
/// ICP, is one more runner-up.
fn half_turns(features: &[PlaneFeature], points: &[Point3<f64>]) -> Vec<Isometry3<f64>> {
    let normals = largest_normals(features);
    let mut directions = Vec::new();
    for n in &normals {
        add_axis(&mut directions, *n);
    }
    let mut axes = directions.clone();
    for a in shared_lines(&normals) {
        add_axis(&mut axes, a);
    }
    let centroid = points
        .iter()
        .fold(Vector3::zeros(), |sum, p| sum + p.coords)
        / points.len().max(1) as f64;
    let mid = middle(points, &directions, centroid);
    let mut centres = vec![centroid];
    if (mid - centroid).norm() >= DISTINCT_DISTANCE {
        centres.push(mid);
    }
    centres
        .iter()
        .flat_map(|centre| {
            axes.iter().map(move |axis| {
                let rotation = UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_unchecked(*axis),
                    std::f64::consts::PI,
                );
                Isometry3::from_parts(Translation3::from(centre - rotation * centre), rotation)
            })
        })
        .collect()
}

/// `start` moved, along each unit direction in turn, to the midpoint of the 2nd and 98th
/// percentiles of the points' projections on it: the middle of a room or a corridor along the
/// normals of its walls, floor and ceiling (exact for orthogonal directions).
fn middle(
    points: &[Point3<f64>],
    directions: &[Vector3<f64>],
    start: Vector3<f64>,
) -> Vector3<f64> {
    let mut centre = start;
    if points.is_empty() {
        return centre;
    }
    let mut projections = vec![0.0; points.len()];
    for d in directions {
        for (value, p) in projections.iter_mut().zip(points) {
            *value = d.dot(&p.coords);
        }
        projections.sort_by(f64::total_cmp);
        let at = |q: f64| projections[((projections.len() - 1) as f64 * q).round() as usize];
        let mid = 0.5 * (at(0.02) + at(0.98));
        centre += d * (mid - d.dot(&centre));
    }
    centre
}

/// Indices and scores of the verified hypotheses, best first (ties keep the enumeration order).
fn rank(verified: &[Option<Verified>]) -> Vec<(usize, f64)> {
    let mut ranked: Vec<(usize, f64)> = verified
        .iter()
        .enumerate()
        .filter_map(|(k, v)| v.map(|v| (k, v.score)))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    ranked
}

/// The best of verified poses (`pool`, best first, each with its hypothesis) and its closest
/// distinct rival. A close runner-up may be the same answer, not polished as far: both get the
/// full ICP (`polish`) and are scored again before the result is called ambiguous. When the two
/// settle on one pose, the next distinct contender is polished in turn (up to [`MAX_POLISHED`]):
/// in a street turned by half a turn the two best hypotheses can be the same flip 0.4 m apart,
/// and the truth beyond max_translation only third. A best pose beyond max_translation (not
/// `within`) is always polished against the best pose within range, and only poses within range
/// challenge it.
fn settle_best(
    pool: &[(Candidate, Verified)],
    within: &impl Fn(&Verified) -> bool,
    polish: &impl Fn(&Verified) -> Option<Verified>,
) -> Option<(Candidate, Verified, Option<Verified>)> {
    let &(winner, mut top) = pool.first()?;
    let mut top_polished = None;
    let mut runner_up = None;
    let mut polished_pairs = 0;
    for &(_, v) in pool {
        // Against a challenger that screened best, the best pose within range.
        let eligible = within(&v) || (within(&top) && v.score >= AMBIGUITY_RATIO * top.score);
        if !eligible || same_pose(&v.pose, &top.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE) {
            continue;
        }
        let close = !within(&top) || v.score >= AMBIGUITY_RATIO * top.score;
        if !close || polished_pairs == MAX_POLISHED {
            runner_up = Some(v);
            break;
        }
        polished_pairs += 1;
        let a = top_polished.or_else(|| polish(&top));
        match (a, polish(&v)) {
            (Some(a), Some(b))
                if same_pose(&a.pose, &b.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE) =>
            {
                top = if b.score > a.score { b } else { a };
                top_polished = Some(top);
            }
            (Some(a), Some(b)) => {
                (top, runner_up) = if b.score > a.score {
                    (b, Some(a))
                } else {
                    (a, Some(b))
                };
                break;
            }
            (Some(a), None) => {
                (top, runner_up) = (a, Some(v));
                break;
            }
            (None, Some(b)) => {
                top = b;
                top_polished = Some(b);
            }
            (None, None) => {
                runner_up = Some(v);
                break;
            }
        }
    }
    Some((winner, top, runner_up))
}

fn mapped(points: &[Point3<f64>], pose: &Isometry3<f64>) -> Vec<Point3<f64>> {
    points.iter().map(|p| pose * p).collect()
}

/// Calibrates `reference_from_target` from the planes both sensors see (see the module docs).
///
/// Errors: [`Error::InvalidInput`] for malformed input or options; [`Error::Calibration`] when
/// fewer than two non-parallel planes are found or matched, no hypothesis verifies, or the data
/// do not constrain all six degrees of freedom (the message names the weak direction).
pub fn calibrate_targetless(
    reference: &[Point3<f64>],
    target: &[Point3<f64>],
    options: &TargetlessOptions,
) -> Result<TargetlessCalibration> {
    options.validate()?;
    check_cloud(reference, "reference")?;
    check_cloud(target, "target")?;
    let mut clock = Stopwatch::start();

    let (ref_result, tgt_result) =
        crate::join(|| prepare(reference, options), || prepare(target, options));
    let (reference_ds, target_ds) = (ref_result?, tgt_result?);
    clock.lap("planes");
    for (prepared, which) in [(&reference_ds, "reference"), (&target_ds, "target")] {
        let needed = if options.ground_sweep { 1 } else { 2 };
        if prepared.features.len() < needed {
            return Err(Error::calibration(
                FailureKind::TooFewFeatures,
                format!(
                    "the {which} cloud shows {} plane(s) with at least {} inliers; the targetless \
                 method needs {}",
                    prepared.features.len(),
                    options.min_inliers,
                    if options.ground_sweep {
                        "a plane both sensors see (the ground)"
                    } else {
                        "two non-parallel planes seen by both sensors"
                    }
                ),
            ));
        }
    }

    let (enumerated, candidates) = hypotheses(&reference_ds.features, &target_ds.features, options);
    let sweep = if options.ground_sweep {
        ground_sweep(&reference_ds.features, &target_ds.features)
    } else {
        Vec::new()
    };
    if candidates.is_empty() && sweep.is_empty() {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
                "no pair of non-parallel planes matches between the clouds ({} reference and {} \
             target planes; normals must agree within {:.1} deg)",
                reference_ds.features.len(),
                target_ds.features.len(),
                options.normal_tolerance.to_degrees()
            ),
        ));
    }
    clock.lap("hypotheses");

    let surface = SurfaceCloud::new(reference_ds.points.clone())?;
    let reference_image = RangeImage::new(&reference_ds.points, RangeImage::DEFAULT_RESOLUTION)?;
    let target_image = RangeImage::new(&target_ds.points, RangeImage::DEFAULT_RESOLUTION)?;
    clock.lap("normals");

    // Verification in two stages: a quick ICP and score for every hypothesis (screening), then
    // a longer ICP and the full score for the best few distinct ones.
    let sample = |points: &[Point3<f64>], count: usize| -> Vec<Point3<f64>> {
        let stride = points.len().div_ceil(count).max(1);
        points.iter().step_by(stride).copied().collect()
    };
    let full = [
        sample(&target_ds.points, VERIFY_SAMPLES),
        sample(&reference_ds.points, VERIFY_REFERENCE_SAMPLES),
    ];
    let quick = [
        sample(&target_ds.points, SCREEN_SAMPLES),
        sample(&reference_ds.points, SCREEN_REFERENCE_SAMPLES),
    ];
    let score = |pose: Isometry3<f64>,
                 [target_points, reference_points]: &[Vec<Point3<f64>>; 2]| {
        let agreement = surface.overlap(target_points, &pose, VERIFY_DISTANCE);
        let share = |count: usize, total: usize| count as f64 / total.max(1) as f64;
        let violations = [
            share(
                reference_image.count_violations(target_points, &pose),
                target_points.len(),
            ),
            share(
                target_image.count_violations(reference_points, &pose.inverse()),
                reference_points.len(),
            ),
        ];
        Verified {
            pose,
            agreement,
            violations,
            score: agreement - VIOLATION_WEIGHT * (violations[0] + violations[1]),
        }
    };
    let icp_then_score = |start: &Isometry3<f64>, icp: &IcpOptions, samples| {
        point_to_plane_icp(&surface, &target_ds.points, start, icp)
            .ok()
            .map(|r| score(r.pose, samples))
    };
    // The best supported hypotheses within range, and half as many challengers beyond it.
    let in_bound =
        |pose: &Isometry3<f64>| pose.translation.vector.norm() <= options.max_translation;
    let in_range = |c: &Candidate| in_bound(&c.pose);
    let paired: Vec<Candidate> = candidates
        .iter()
        .filter(|c| in_range(c))
        .take(options.max_verified)
        .chain(
            candidates
                .iter()
                .filter(|c| !in_range(c))
                .take(options.max_verified.div_ceil(2)),
        )
        .copied()
        .collect();
    let occupancy = Occupancy::new(&reference_ds.points, SLIDE_CELL);
    let slide_samples = sample(&target_ds.points, SLIDE_SAMPLES);
    let slid = slides(
        &paired,
        &occupancy,
        &reference_image,
        &slide_samples,
        options.max_translation * options.challenger_range,
    );
    clock.lap("slides");
    let chosen: Vec<Candidate> = paired
        .iter()
        .chain(sweep.iter())
        .chain(slid.iter())
        .copied()
        .collect();
    let (screen_pair, screen_sweep, short) = (
        screen_icp_options(false),
        screen_icp_options(true),
        verify_icp_options(),
    );
    let screen_one = |c: &Candidate| {
        let icp = if c.sweep { &screen_sweep } else { &screen_pair };
        icp_then_score(&c.pose, icp, &quick)
    };
    #[cfg(feature = "parallel")]
    let screened: Vec<Option<Verified>> = {
        use rayon::prelude::*;
        chosen.par_iter().map(screen_one).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let screened: Vec<Option<Verified>> = chosen.iter().map(screen_one).collect();
    let mut kept: Vec<(usize, Isometry3<f64>)> = Vec::new();
    for (k, _) in rank(&screened) {
        if kept.len() >= SCREEN_KEEP {
            break;
        }
        let Some(Some(v)) = screened.get(k) else {
            continue;
        };
        if !kept
            .iter()
            .any(|(_, p)| same_pose(p, &v.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE))
        {
            kept.push((k, v.pose));
        }
    }
    let verify_one = |(_, pose): &(usize, Isometry3<f64>)| icp_then_score(pose, &short, &full);
    #[cfg(feature = "parallel")]
    let verified: Vec<Option<Verified>> = {
        use rayon::prelude::*;
        kept.par_iter().map(verify_one).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let verified: Vec<Option<Verified>> = kept.iter().map(verify_one).collect();
    let ranked = rank(&verified);
    // The verified poses best first, each with the hypothesis it grew from.
    let pool: Vec<(Candidate, Verified)> = ranked
        .iter()
        .filter_map(|&(k, _)| {
            let v = verified.get(k).copied().flatten()?;
            let c = kept.get(k).and_then(|(i, _)| chosen.get(*i)).copied()?;
            Some((c, v))
        })
        .collect();
    // A challenger beyond max_translation competes only when it comes close to the best: the
    // user's bound on the rig already rules such poses out, and a corner turned by half a turn
    // 6-9 m away scores 75-90 % of the truth.
    let within = |v: &Verified| in_bound(&v.pose);
    let ratio = |v: &Verified| {
        if within(v) {
            AMBIGUITY_RATIO
        } else {
            CHALLENGER_AMBIGUITY_RATIO
        }
    };
    let polish = |v: &Verified| {
        point_to_plane_icp(&surface, &target_ds.points, &v.pose, &options.icp_options)
            .ok()
            .map(|r| score(r.pose, &full))
    };
    let Some((winner, top, mut runner_up)) = settle_best(&pool, &within, &polish) else {
        return Err(Error::calibration(
            FailureKind::NoAgreement,
            "no plane hypothesis brings the clouds into agreement (ICP found no overlap)",
        ));
    };
    if top.score <= 0.0 {
        return Err(Error::calibration(
            FailureKind::NoAgreement,
            format!(
                "no hypothesis brings the clouds into agreement: the best verified pose agrees on \
             {:.1} % of the target points and puts {:.1} % / {:.1} % of the points into space \
             the other sensor saw through",
                100.0 * top.agreement,
                100.0 * top.violations[0],
                100.0 * top.violations[1]
            ),
        ));
    }
    let distance = top.pose.translation.vector.norm();
    if distance > options.max_translation {
        let best_within = runner_up
            .filter(within)
            .map_or(f64::NEG_INFINITY, |r| r.score);
        // A challenger that fails the check itself says only that nothing fits (a cloud with
        // no real structure): that failure is the reason. (Falling back to the best pose within
        // range then was tried: in 1000 adversarial scenes it solved two corners and returned
        // one pole scene 1.6 m off.)
        if let Err(e) = certify(reference, target, &top.pose, &options.check) {
            return Err(e.context(&format!(
                "the best pose puts the target {distance:.2} m away, beyond max_translation, \
                 and fails the check as well"
            )));
        }
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!(
                "the clouds agree best with the target {distance:.2} m from the reference, beyond \
                 max_translation ({:.2} m; score {:.3}, best within range {}): the sensors seem \
                 further apart than allowed; raise max_translation if they are",
                options.max_translation,
                top.score,
                if best_within.is_finite() {
                    format!("{best_within:.3}")
                } else {
                    "none".to_string()
                }
            ),
        ));
    }
    let (polished, best_score) = (top.pose, top.score);
    // The agreement is a share of the sampled target points: two poses whose scores differ by
    // less than one standard error of that share are not told apart by the verification,
    // whatever the ratio of their scores (near zero, where free-space violations eat the
    // agreement, the ratio says nothing: two identical boxes swapped scored 0.086 and 0.077).
    let resolution = {
        let (a, n) = (top.agreement.clamp(0.0, 1.0), full[0].len().max(1) as f64);
        (a * (1.0 - a) / n).sqrt()
    };
    let ties = |r: &Verified| r.score >= ratio(r) * best_score || best_score - r.score < resolution;
    // The check's preparation of the two clouds (most of its work), made at most once for every
    // pose checked from here on.
    let prepared = OnceCell::new();
    let prepare = || -> Result<&PreparedPair> {
        if let Some(pair) = prepared.get() {
            return Ok(pair);
        }
        let pair = PreparedPair::new(reference, target, &options.check)?;
        Ok(prepared.get_or_init(|| pair))
    };
    // A rival the check rules out is no rival when the best pose passes it: the rival's overlap
    // leaves a direction unconstrained (a half turn whose agreement comes from sliding along a
    // wall) or puts points into free space. A rival that fails only because the check's local
    // re-alignment moves it is not settled, and still counts; so does a slide of the best pose
    // itself (turned by less than RULED_OUT_TURN): a corridor turned upside down, the best pose
    // of one held-out scene, had only its own slides as rivals, and they were the only sign.
    // (Dismissing slides that put clearly more points into free space than the best pose, see
    // `clearer`, solved refused adversarial corners whose slides put 11 % there, but returned
    // that corridor: its slides put 7 % there, and the truth was never verified.)
    // The share of points the best pose puts into free space (the larger way) when it passes the
    // check.
    let top_free = OnceCell::new();
    let top_passes = || -> Result<Option<f64>> {
        let pair = prepare()?;
        Ok(*top_free.get_or_init(|| {
            pair.check(&polished)
                .ok()
                .filter(|c| c.verdict == Verdict::Consistent)
                .map(|c| c.violations.max(c.reverse_violations))
        }))
    };
    let rules_out = |r: &Verified| -> Result<bool> {
        if pose_error(&r.pose, &polished).0 < RULED_OUT_TURN || top_passes()?.is_none() {
            return Ok(false);
        }
        let c = prepare()?.check(&r.pose)?;
        Ok(match c.verdict {
            Verdict::Consistent => false,
            Verdict::Unverifiable => true,
            Verdict::Inconsistent => {
                c.violations.max(c.reverse_violations) > options.check.max_violations
                    || c.agreement.min(c.reverse_agreement) < options.check.min_agreement
            }
        })
    };
    let rival = |r: &Verified| -> Result<bool> { Ok(ties(r) && !rules_out(r)?) };
    let mut ambiguous = false;
    if let Some(r) = runner_up {
        if rival(&r)? {
            ambiguous = true;
        } else if ties(&r) {
            // Ruled out: the next distinct contenders that tie are checked in turn.
            let mut seen = vec![polished, r.pose];
            for v in ranked
                .iter()
                .filter_map(|&(k, _)| verified.get(k).copied().flatten())
                .filter(|v| ties(v))
            {
                if seen
                    .iter()
                    .any(|p| same_pose(p, &v.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE))
                {
                    continue;
                }
                if seen.len() > MAX_POLISHED || rival(&v)? {
                    (ambiguous, runner_up) = (true, Some(v));
                    break;
                }
                seen.push(v.pose);
            }
        }
    }
    if !ambiguous {
        // The scene's own half-turn symmetries: a rival the hypotheses may not have reached.
        let settle = |pose: &Isometry3<f64>| {
            icp_then_score(pose, &screen_pair, &quick)
                .and_then(|v| icp_then_score(&v.pose, &short, &full))
        };
        if let Some(turned) = half_turns(&reference_ds.features, &reference_ds.points)
            .into_iter()
            .filter_map(|turn| settle(&(turn * polished)))
            .filter(|v| !same_pose(&v.pose, &polished, DISTINCT_ANGLE, DISTINCT_DISTANCE))
            .find(|v| rival(v).unwrap_or(true))
        {
            runner_up = Some(turned);
            ambiguous = true;
        }
    }
    // A repeated structure along the direction the best plane pair leaves free (a colonnade)
    // scores highest where the overlap is largest, which may be one period off the truth: the
    // verification ranks by the share of target points that agree, and one period off can share
    // more. A copy slid to another peak that passes the check and keeps the free space clearer
    // than the best pose is a rival the ranking cannot see: in a colonnade of the adversarial
    // suite the best pose, one column off, put 1.6 % of the points into free space and the
    // truth, a peak 3.9 m along, 0.6 %. (Any slid copy that passes the check counting as a rival
    // refused that colonnade too, but also 68 of 194 solved simulated streets.)
    let mut slid_rival = None;
    if !ambiguous {
        if let Some(free) = winner.free {
            if let Some(top_free) = top_passes()?.filter(|f| *f > SLID_FREE_SPACE_MIN) {
                for peak in slide_peaks(
                    &polished,
                    &free,
                    &occupancy,
                    &reference_image,
                    &slide_samples,
                    options.max_translation,
                ) {
                    let Some(v) = icp_then_score(&peak, &screen_pair, &quick)
                        .and_then(|v| icp_then_score(&v.pose, &short, &full))
                    else {
                        continue;
                    };
                    if !in_bound(&v.pose)
                        || same_pose(&v.pose, &polished, DISTINCT_ANGLE, DISTINCT_DISTANCE)
                    {
                        continue;
                    }
                    let c = prepare()?.check(&v.pose)?;
                    let free_space = c.violations.max(c.reverse_violations);
                    if c.verdict == Verdict::Consistent && clearer(free_space, top_free) {
                        slid_rival = Some((top_free, free_space));
                        runner_up = Some(v);
                        ambiguous = true;
                        break;
                    }
                }
            }
        }
    }
    let second_score = runner_up.map_or(0.0, |r| r.score.max(0.0));
    // Refused after the observability check below, whose reason is the more fundamental one
    // (a corridor is ambiguous along its axis because nothing constrains that direction).
    let ambiguity = (ambiguous && options.refuse_ambiguous).then(|| {
        let (angle, distance) = runner_up.map_or((0.0, 0.0), |r| pose_error(&r.pose, &polished));
        let beyond = runner_up.filter(|r| !within(r)).map_or(String::new(), |r| {
            format!(
                "; the other puts the target {:.2} m away, beyond max_translation",
                r.pose.translation.vector.norm()
            )
        });
        if let Some((top_free, free_space)) = slid_rival {
            return format!(
                "ambiguous: a copy of the best pose slid {distance:.2} m along a repeated \
                 structure (a colonnade, a row of posts) also passes the check and puts fewer \
                 points into the other sensor's free space ({:.1} % against {:.1} %), though the \
                 verification ranks it lower (scores {second_score:.3} and {best_score:.3}); add \
                 structure that breaks the repetition",
                100.0 * free_space,
                100.0 * top_free
            );
        }
        format!(
            "ambiguous: two poses {:.1} deg and {:.2} m apart verify almost equally well \
             (scores {best_score:.3} and {second_score:.3}{beyond}; a symmetric scene such as a \
             straight street seen from its middle); add structure that breaks the symmetry",
            angle.to_degrees(),
            distance
        )
    });
    clock.lap("verify");

    // Plane refinement on every matched plane.
    let (ref_f, tgt_f) = (&reference_ds.features, &target_ds.features);
    let threshold = reference_ds.threshold.max(target_ds.threshold);
    let matches = agreeing(
        ref_f,
        tgt_f,
        &polished,
        None,
        options.normal_tolerance,
        (2.0 * threshold).max(0.1),
    );
    let mut groups = Vec::with_capacity(2 * matches.len());
    let voxels = |ds: &[Point3<f64>], f: &PlaneFeature| {
        Moments::from_points(f.voxels.iter().filter_map(|&i| ds.get(i)))
    };
    for &(i, j) in &matches {
        groups.push(PlaneMomentGroup {
            plane: ref_f[i].plane,
            moments: voxels(&target_ds.points, &tgt_f[j]),
            frame: Frame::Target,
        });
        groups.push(PlaneMomentGroup {
            plane: tgt_f[j].plane,
            moments: voxels(&reference_ds.points, &ref_f[i]),
            frame: Frame::Reference,
        });
    }
    let lm = LmOptions {
        cost_tolerance: super::planes::CALIBRATION_COST_TOLERANCE,
        ..LmOptions::default()
    };
    let (plane_pose, report, problem) = if groups.is_empty() {
        (polished, None, None)
    } else {
        let problem = PlaneMomentsProblem::new(groups)?;
        let s = solve(&problem, &polished, &lm)?;
        // Planes matched wrongly (parallel planes at a similar offset) can pull the pose away
        // from what the points agree on; then the verified pose is kept.
        if same_pose(&s.pose, &polished, DISTINCT_ANGLE, DISTINCT_DISTANCE) {
            (s.pose, Some(s.report), Some(problem))
        } else {
            (polished, Some(s.report), Some(problem))
        }
    };
    clock.lap("refine");

    let icp = if options.icp {
        Some(point_to_plane_icp(
            &surface,
            &target_ds.points,
            &plane_pose,
            &options.icp_options,
        )?)
    } else {
        None
    };
    let mut pose = icp.map_or(plane_pose, |r| r.pose);
    let mut icp = icp;
    // (Not for a result about to be refused as ambiguous: that refusal stands either way.)
    if let Some(main) = icp.filter(|_| ambiguity.is_none()) {
        // Hypotheses within DISTINCT of the winner were never polished on their own; when one
        // settles clearly elsewhere, the check's free space decides between the two.
        let near: Vec<Isometry3<f64>> = ranked
            .iter()
            .filter_map(|&(k, _)| verified.get(k).copied().flatten())
            .map(|v| v.pose)
            .filter(|p| {
                same_pose(p, &polished, DISTINCT_ANGLE, DISTINCT_DISTANCE)
                    && !same_pose(p, &polished, SETTLED_ANGLE, SETTLED_DISTANCE)
            })
            .take(NEAR_ALTERNATIVES)
            .collect();
        let settled = near
            .iter()
            .filter_map(|start| {
                point_to_plane_icp(&surface, &target_ds.points, start, &options.icp_options).ok()
            })
            .filter(|r| r.converged);
        // The plane fit itself: on sparse 16-beam corners the final ICP pulled the exact pose
        // of the plane refinement 16-18 cm along the weakest direction (neighbouring scan rings
        // taken for the surface), where 3-13 % of the points land in the other's free space.
        let plane = point_to_plane_fit(
            &surface,
            &target_ds.points,
            &plane_pose,
            &options.icp_options,
        )
        .ok();
        // And the verified pose: matched planes that are not the same surface (a box top for
        // the ground) can pull the plane refinement, and ICP after it, off a verified pose that
        // kept free space clear.
        let verified_pose =
            point_to_plane_fit(&surface, &target_ds.points, &polished, &options.icp_options).ok();
        let chosen = prefer_free_space(main, settled.chain(plane).chain(verified_pose), prepare);
        pose = chosen.pose;
        icp = Some(chosen);
    }
    clock.lap("icp");

    // Observability of the final problem.
    let mut plane_info = Matrix3::zeros();
    for &(i, _) in &matches {
        let n = ref_f[i].plane.normal.into_inner();
        plane_info += n * n.transpose();
    }
    let plane_translation_share = weakest_direction(&plane_info).1;
    let (weakest_translation, weakest_rotation) = match (&icp, &report) {
        (Some(r), _) => (r.weakest_translation(), r.weakest_rotation()),
        (None, Some(rep)) => (
            weakest_direction(&rep.hessian.fixed_view::<3, 3>(0, 0).into_owned()),
            weakest_direction(&rep.hessian.fixed_view::<3, 3>(3, 3).into_owned()),
        ),
        (None, None) => ((Vector3::x(), 0.0), (Vector3::x(), 0.0)),
    };
    let source = if icp.is_some() {
        "the point-to-plane ICP"
    } else {
        "the matched planes"
    };
    let fmt = |v: &Vector3<f64>| format!("[{:.2}, {:.2}, {:.2}]", v.x, v.y, v.z);
    if weakest_translation.1 < options.min_information_share {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
            "the scene does not constrain the translation along {} (reference frame): it holds \
             {:.2} % of the translation information of {source} (< {:.2} %); the matched planes' \
             normals span {} direction(s) (as in a corridor or a straight street with only \
             ground and parallel walls); add structure across that direction (a cross wall, \
             poles, a building corner)",
            fmt(&weakest_translation.0),
            100.0 * weakest_translation.1,
            100.0 * options.min_information_share,
            if plane_translation_share > 1e-3 {
                3
            } else if matches.len() > 1 {
                2
            } else {
                1
            },
        ),
        ));
    }
    if weakest_rotation.1 < options.min_information_share {
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
                "the scene does not constrain the rotation about {} (reference frame): it holds \
             {:.2} % of the rotation information of {source} (< {:.2} %)",
                fmt(&weakest_rotation.0),
                100.0 * weakest_rotation.1,
                100.0 * options.min_information_share
            ),
        ));
    }
    let moved = pose.translation.vector.norm();
    if moved > options.max_translation {
        return Err(Error::calibration(
            FailureKind::OutOfRange,
            format!(
                "the best pose puts the target {moved:.2} m from the reference, beyond \
             max_translation ({:.2} m): the final ICP carried the target away (the clouds agree \
             best where the sensors cannot be)",
                options.max_translation
            ),
        ));
    }

    if let Some(message) = ambiguity {
        return Err(Error::calibration(FailureKind::Ambiguous, message));
    }
    // An ICP that has not settled is still trading correspondences. At 30 iterations this refused
    // 6 wrong results (a room, streets 1.5-8 m off) and 6 correct ones in 1000 adversarial
    // scenes; at 100 (the default) it refuses 8 there, 7 of them on scenes with no sure answer.
    if let Some(r) = icp.as_ref().filter(|r| !r.converged) {
        return Err(Error::calibration(
            FailureKind::NoAgreement,
            format!(
                "the final ICP did not converge in {} iterations (its last step stayed above the \
                 tolerance): the pose is not settled",
                r.iterations
            ),
        ));
    }

    // Matched planes, their input indices and residuals at the result.
    let expand = |prepared: &Prepared, f: &PlaneFeature| -> Vec<usize> {
        let mut inlier_voxel = vec![false; prepared.points.len()];
        for &v in &f.voxels {
            if let Some(slot) = inlier_voxel.get_mut(v) {
                *slot = true;
            }
        }
        prepared
            .owner
            .iter()
            .enumerate()
            .filter(|(_, &v)| inlier_voxel.get(v).copied().unwrap_or(false))
            .map(|(i, _)| i)
            .collect()
    };
    let group_rms = problem.as_ref().map(|p| p.group_rms(&pose));
    let mut rmse = Vec::with_capacity(matches.len());
    for (k, &(i, j)) in matches.iter().enumerate() {
        let (n_t, n_r) = (tgt_f[j].voxels.len() as f64, ref_f[i].voxels.len() as f64);
        let value = group_rms.as_ref().map_or(f64::NAN, |g| {
            let (a, b) = (g[2 * k], g[2 * k + 1]);
            ((a * a * n_t + b * b * n_r) / (n_t + n_r)).sqrt()
        });
        rmse.push(value);
    }
    let covariance = match (&icp, &report) {
        (Some(r), _) => r.covariance,
        (None, Some(rep)) => rep.covariance(),
        _ => None,
    };
    let check = prepare()?.certify(&pose)?;
    let result = TargetlessCalibration {
        check,
        reference_from_target: pose,
        initial_reference_from_target: winner.pose,
        planes_reference: matches.iter().map(|&(i, _)| ref_f[i].plane).collect(),
        planes_target: matches.iter().map(|&(_, j)| tgt_f[j].plane).collect(),
        inliers_reference: matches
            .iter()
            .map(|&(i, _)| expand(&reference_ds, &ref_f[i]))
            .collect(),
        inliers_target: matches
            .iter()
            .map(|&(_, j)| expand(&target_ds, &tgt_f[j]))
            .collect(),
        rmse,
        hypotheses: [enumerated, candidates.len()],
        verified: chosen.len(),
        triplet: !winner.sweep && winner.free.is_none(),
        sweep: winner.sweep,
        best_score,
        second_score,
        agreement: top.agreement,
        violations: top.violations,
        ambiguous,
        distance_thresholds: [reference_ds.threshold, target_ds.threshold],
        report,
        icp,
        weakest_translation,
        weakest_rotation,
        plane_translation_share,
        covariance,
        timings: Timings::default(),
        features: [reference_ds.features, target_ds.features],
    };
    clock.lap("check");
    Ok(TargetlessCalibration {
        timings: clock.finish(),
        ..result
    })
}

/// The rotation angle (radians) and translation distance (metres) between two transforms:
/// `angle(R_a R_b^T)` and `|t_a - t_b|`.
pub fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let r = (a.rotation * b.rotation.inverse()).to_rotation_matrix();
    (
        rotation_angle(&r),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn settle_best_polishes_a_close_rival_and_merges_one_that_settles_on_the_best() {
        let at = |x: f64, score: f64| {
            let pose = Isometry3::translation(x, 0.0, 0.0);
            let c = Candidate {
                pose,
                free: None,
                support: 0.0,
                sweep: false,
            };
            let v = Verified {
                pose,
                agreement: score,
                violations: [0.0; 2],
                score,
            };
            (c, v)
        };
        let within = |v: &Verified| v.pose.translation.vector.norm() <= 5.0;
        // A rival 1 m away at 90 % is polished and stays distinct: it is the runner-up.
        let pool = [at(0.0, 1.0), at(1.0, 0.9), at(2.0, 0.5)];
        let stay = |v: &Verified| Some(*v);
        let (_, top, runner) = settle_best(&pool, &within, &stay).unwrap();
        assert_eq!(top.score, 1.0);
        assert_eq!(runner.map(|r| r.score), Some(0.9));
        // When the rival settles onto the best (polishing moves 1 m to 0 m) they are one answer,
        // and the next contender, at 50 %, is the runner-up without being polished.
        let onto_best = |v: &Verified| {
            let x = v.pose.translation.vector.x;
            Some(if x < 1.5 { at(0.0, v.score).1 } else { *v })
        };
        let (_, top, runner) = settle_best(&pool, &within, &onto_best).unwrap();
        assert_eq!(top.pose.translation.vector.x, 0.0);
        assert_eq!(runner.map(|r| r.score), Some(0.5));
        // A best pose beyond range is always polished against the best within range, and the
        // better after polishing wins.
        let pool = [at(7.0, 1.0), at(1.0, 0.5)];
        let lift = |v: &Verified| Some(at(v.pose.translation.vector.x, v.score * 3.0).1);
        let (_, top, runner) = settle_best(&pool, &within, &lift).unwrap();
        assert_eq!(top.pose.translation.vector.x, 7.0);
        assert_eq!(runner.map(|r| r.pose.translation.vector.x), Some(1.0));
        assert!(settle_best(&[], &within, &stay).is_none());
    }

    #[test]
    fn slide_peaks_are_the_periods_of_a_row_of_posts() {
        // Five posts 4 m apart along x, 5 m to the side of the sensor; the target sees the same
        // row. Slid by one period, four of the five posts agree; between posts, none.
        let posts: Vec<Point3<f64>> = (-2..=2)
            .flat_map(|i| {
                (0..20).map(move |k| Point3::new(4.0 * f64::from(i), 5.0, 0.1 * f64::from(k)))
            })
            .collect();
        let occupancy = Occupancy::new(&posts, SLIDE_CELL);
        let image = RangeImage::new(&posts, RangeImage::DEFAULT_RESOLUTION).unwrap();
        let peaks = slide_peaks(
            &Isometry3::identity(),
            &Vector3::x(),
            &occupancy,
            &image,
            &posts,
            10.0,
        );
        let mut offsets: Vec<f64> = peaks.iter().map(|p| p.translation.vector.x).collect();
        offsets.sort_by(f64::total_cmp);
        assert_eq!(offsets.len(), 2);
        assert!((offsets[0] + 4.0).abs() < 1e-9 && (offsets[1] - 4.0).abs() < 1e-9);
        assert!(peaks
            .iter()
            .all(|p| p.translation.vector.yz().norm() < 1e-12));
    }

    #[test]
    fn clearer_needs_the_other_pose_in_free_space_and_half_as_much() {
        assert!(clearer(0.006, 0.016));
        assert!(!clearer(0.009, 0.016));
        assert!(!clearer(0.0, 0.008));
    }

    #[test]
    fn middle_is_the_centre_of_a_room_seen_mostly_on_one_side() {
        // Walls at x = 0 and x = 10 (y from 0 to 4): nine points in ten on the near wall.
        let mut points = Vec::new();
        for i in 0..1000 {
            let y = 4.0 * (i % 100) as f64 / 100.0;
            let x = if i % 10 == 0 { 10.0 } else { 0.0 };
            points.push(Point3::new(x, y, 1.5));
        }
        let centroid = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / 1000.0;
        assert!((centroid.x - 1.0).abs() < 1e-9);
        let mid = middle(&points, &[Vector3::x(), Vector3::y()], centroid);
        assert!((mid.x - 5.0).abs() < 1e-9, "{mid}");
        assert!((mid.y - 1.98).abs() < 0.05, "{mid}");
        assert_eq!(mid.z, centroid.z);
        assert_eq!(middle(&[], &[Vector3::x()], centroid), centroid);
    }

    #[test]
    fn half_turns_are_the_box_symmetries_about_the_centroid() {
        // A floor and two walls 60 degrees apart: three normals and three shared lines, of which
        // the floor's normal and the walls' shared line (vertical) are one axis.
        let feature = |normal: Vector3<f64>| PlaneFeature {
            plane: Plane::new(normal, 1.0).unwrap(),
            voxels: Vec::new(),
            centroid: Point3::origin(),
            extent: [1.0, 1.0],
        };
        let wall = Vector3::new(60f64.to_radians().cos(), 60f64.to_radians().sin(), 0.0);
        let features = [feature(Vector3::z()), feature(Vector3::x()), feature(wall)];
        assert_eq!(shared_lines(&largest_normals(&features)).len(), 3);
        let points = [Point3::new(1.0, 2.0, 0.0), Point3::new(3.0, 0.0, 2.0)];
        let turns = half_turns(&features, &points);
        assert_eq!(turns.len(), 5);
        let centre = Point3::new(2.0, 1.0, 1.0);
        for turn in &turns {
            assert!((turn.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
            assert!((turn * centre - centre).norm() < 1e-9);
            assert!((turn * turn).translation.vector.norm() < 1e-9);
        }
    }

    #[test]
    fn deduplicate_equals_comparing_with_every_kept_pose() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // Clusters of near-identical poses (within and beyond the duplicate limits) around a
        // few centres, some straddling cell boundaries.
        let mut candidates = Vec::new();
        for _ in 0..3000 {
            let centre = rng.random_range(0..6) as f64 * 0.15;
            let t = Vector3::new(
                centre + rng.random_range(-0.12..0.12),
                rng.random_range(-0.12..0.12),
                -0.05 + rng.random_range(-0.08..0.08),
            );
            let axis = Vector3::new(rng.random::<f64>(), rng.random(), rng.random())
                - Vector3::repeat(0.5);
            let angle = rng.random_range(0.0..3.0f64).to_radians();
            candidates.push(Candidate {
                pose: Isometry3::from_parts(
                    Translation3::from(t),
                    UnitQuaternion::from_scaled_axis(axis.normalize() * angle),
                ),
                free: None,
                support: 0.0,
                sweep: false,
            });
        }
        let mut brute: Vec<Isometry3<f64>> = Vec::new();
        for c in &candidates {
            if !brute
                .iter()
                .any(|d| same_pose(d, &c.pose, DUPLICATE_ANGLE, DUPLICATE_DISTANCE))
            {
                brute.push(c.pose);
            }
        }
        let fast: Vec<Isometry3<f64>> = deduplicate(candidates).iter().map(|c| c.pose).collect();
        assert!(brute.len() > 50, "{}", brute.len());
        assert_eq!(fast.len(), brute.len());
        assert!(fast == brute, "same count, different poses kept");
    }
}
