//! RANSAC for planes and lines: deterministic, parallel, with MSAC scoring and local optimisation.
//!
//! The engine is split the way robust-estimation libraries usually are:
//!
//! * an [`Estimator`] knows one model type: how to build a model from a minimal sample (rejecting
//!   degenerate samples), how to refit it by least squares on inliers, and how to score a batch of
//!   models against the cloud in one pass (the hot loop);
//! * the [`sampler`] draws minimal samples reproducibly: batch `b` of hypotheses comes from a
//!   ChaCha8 stream `b` of the user's seed, independent of threads;
//! * the [`consensus`] loop scores batches of hypotheses in parallel (rayon, feature `parallel`),
//!   keeps the best by MSAC cost (ties to the earlier hypothesis), locally optimises every new best
//!   model (least-squares refit on its inliers, re-scored, a few rounds), and stops adaptively
//!   when the number of hypotheses reaches `log(1 - confidence) / log(1 - w^s)` for inlier ratio
//!   `w` and sample size `s`; a final least-squares refit gives the returned model.
//!
//! The search runs on at most 32 768 points (a fixed stride through a
//! larger cloud, which keeps its inlier ratio); the returned model is refitted on, and its inliers
//! counted over, every point. Scoring runs on a structure-of-arrays copy of the searched points in `f32`, centred on the per-axis median of
//! a sample ([`robust_center`]) so that `f32` keeps sub-millimetre resolution far from the sensor
//! and beyond a few wild points; fits use the
//! original `f64` points. The MSAC cost of a model is `sum_i min(d_i^2, t^2)` (truncated quadratic)
//! with `d_i` the point's distance and `t` the threshold; inliers are the points with `d_i < t`.
//!
//! The same points, options and seed give bit-identical models and inliers on any number of
//! threads: batches have a fixed size, their scores are computed independently of scheduling and
//! reduced in hypothesis order.
//!
//! ```
//! use lidarcal::ransac::{plane::ransac_plane, RansacOptions};
//! use nalgebra::Point3;
//! // A floor with a few points above it.
//! let mut points: Vec<_> = (0..400)
//!     .map(|i| Point3::new((i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1, 0.0))
//!     .collect();
//! points.extend((0..40).map(|i| Point3::new(0.5, 0.5, 0.3 + i as f64 * 0.05)));
//! let options = RansacOptions::new(0.02);
//! let found = ransac_plane(&points, &options).unwrap();
//! assert_eq!(found.inliers.len(), 400);
//! assert!((found.model.normal.z.abs() - 1.0).abs() < 1e-9);
//! ```

pub mod consensus;
pub mod kernel;
pub mod line;
pub mod plane;
pub mod sampler;

use nalgebra::{Point3, Vector3};

use crate::error::{Error, Result};

pub use consensus::{ransac, Score};

/// Options shared by the RANSAC estimators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RansacOptions {
    /// Inlier threshold `t` on the point-to-model distance (metres).
    pub distance_threshold: f64,
    /// Probability of having drawn at least one all-inlier sample when stopping adaptively.
    pub confidence: f64,
    /// Upper bound on the number of hypotheses (minimal samples drawn).
    pub max_iterations: usize,
    /// Least-squares refit rounds applied to every new best model.
    pub local_optimization_rounds: usize,
    /// Seed of the sampler.
    pub seed: u64,
    /// Stop with an error once this deadline passes (checked between batches of hypotheses).
    pub deadline: Option<crate::budget::Deadline>,
}

impl RansacOptions {
    /// Defaults (confidence 0.999, at most 10 000 hypotheses, 3 LO rounds, seed 0) with the given
    /// threshold.
    pub fn new(distance_threshold: f64) -> Self {
        RansacOptions {
            distance_threshold,
            confidence: 0.999,
            max_iterations: 10_000,
            local_optimization_rounds: 3,
            seed: 0,
            deadline: None,
        }
    }

    /// Checks every option is in range.
    pub fn validate(&self) -> Result<()> {
        let t = self.distance_threshold;
        if !(t.is_finite() && t > 0.0) {
            return Err(Error::InvalidInput(format!(
                "distance_threshold must be finite and positive, got {t}"
            )));
        }
        let c = self.confidence;
        if !(c > 0.0 && c < 1.0) {
            return Err(Error::InvalidInput(format!(
                "confidence must be in (0, 1), got {c}"
            )));
        }
        if self.max_iterations == 0 {
            return Err(Error::InvalidInput(
                "max_iterations must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// A model found by RANSAC.
#[derive(Debug, Clone, PartialEq)]
pub struct RansacResult<M> {
    /// The model after the final least-squares refit.
    pub model: M,
    /// Indices (into the input) of the points within the threshold of `model`, ascending.
    pub inliers: Vec<usize>,
    /// Root-mean-square distance of the inliers to `model`.
    pub rms: f64,
    /// MSAC cost of the best hypothesis before the final refit (`f32` scoring).
    pub cost: f64,
    /// Hypotheses drawn (including degenerate samples that were rejected).
    pub hypotheses: usize,
    /// Hypotheses scored against the whole cloud.
    pub scored: usize,
    /// Point-to-model tests performed (scored hypotheses, LO re-scores, times points).
    pub point_tests: u64,
}

/// A point cloud prepared for scoring: the `f64` points and a centred `f32` structure-of-arrays copy.
#[derive(Debug, Clone)]
pub struct Cloud<'a> {
    points: &'a [Point3<f64>],
    center: Vector3<f64>,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
}

impl<'a> Cloud<'a> {
    /// Prepares `points` (checked finite) for scoring.
    pub fn new(points: &'a [Point3<f64>]) -> Result<Self> {
        crate::error::ensure_points("points", points.iter())?;
        let center = robust_center(points);
        let mut x = Vec::with_capacity(points.len());
        let mut y = Vec::with_capacity(points.len());
        let mut z = Vec::with_capacity(points.len());
        for p in points {
            let d = p.coords - center;
            x.push(d.x as f32);
            y.push(d.y as f32);
            z.push(d.z as f32);
        }
        Ok(Cloud {
            points,
            center,
            x,
            y,
            z,
        })
    }

    /// The original points.
    pub fn points(&self) -> &'a [Point3<f64>] {
        self.points
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// `true` for an empty cloud.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The centre subtracted before the `f32` conversion ([`robust_center`]).
    pub fn center(&self) -> Vector3<f64> {
        self.center
    }

    /// The centred `f32` coordinates `(x, y, z)`.
    pub fn soa(&self) -> (&[f32], &[f32], &[f32]) {
        (&self.x, &self.y, &self.z)
    }
}

/// Points (at most, a fixed stride through the cloud) whose per-axis median centres the `f32`
/// scoring copy.
const CENTER_SAMPLE: usize = 4096;

/// The per-axis median of a strided sample of at most 4096 points: the centre of the
/// `f32` scoring copy. Unlike the bounding-box midpoint it stays among the bulk of the points when
/// a few are wildly far (a single return at 1e9 m once moved the midpoint so far that `f32` lost
/// every centimetre and no plane was found). Deterministic: no dependence on threads or order of
/// evaluation.
pub fn robust_center(points: &[Point3<f64>]) -> Vector3<f64> {
    if points.is_empty() {
        return Vector3::zeros();
    }
    let stride = points.len().div_ceil(CENTER_SAMPLE).max(1);
    let mut center = Vector3::zeros();
    for axis in 0..3 {
        let mut values: Vec<f64> = points.iter().step_by(stride).map(|p| p[axis]).collect();
        let mid = values.len() / 2;
        let (_, median, _) = values.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        center[axis] = *median;
    }
    center
}

/// Midpoint of the axis-aligned bounding box (exactly reproducible, unlike a mean).
pub fn bounding_box_center(points: &[Point3<f64>]) -> Vector3<f64> {
    let Some(first) = points.first() else {
        return Vector3::zeros();
    };
    let mut lo = first.coords;
    let mut hi = first.coords;
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    (lo + hi) * 0.5
}

/// A model type RANSAC can estimate.
pub trait Estimator: Sync {
    /// The model.
    type Model: Copy + Send + Sync + std::fmt::Debug;

    /// Points in a minimal sample.
    const SAMPLE_SIZE: usize;

    /// A short name for error messages ("plane", "line").
    const NAME: &'static str;

    /// The model through a minimal sample, or `None` if the sample is degenerate.
    fn minimal_model(&self, points: &[Point3<f64>], sample: &[usize]) -> Option<Self::Model>;

    /// The least-squares model of `points[indices]`, or `None` if they are degenerate.
    fn refit(&self, points: &[Point3<f64>], indices: &[usize]) -> Option<Self::Model>;

    /// Squared distance from `p` to `model`, in `f64`.
    fn squared_distance(&self, model: &Self::Model, p: &Point3<f64>) -> f64;

    /// MSAC scores of `models` against the cloud, in one pass over the data where possible.
    /// `out[k]` receives the score of `models[k]`; its inlier count only when `count_inliers`
    /// (counting costs registers in the hot loop, and the search needs only the cost).
    fn score(
        &self,
        cloud: &Cloud<'_>,
        models: &[Self::Model],
        threshold: f64,
        count_inliers: bool,
        out: &mut [Score],
    );

    /// Refuses clouds on which no model of this type is determined (checked before sampling).
    fn check_cloud(&self, points: &[Point3<f64>]) -> Result<()>;
}

/// Root-mean-square distance of `points[indices]` to `model` (0 for no indices).
pub fn rms<E: Estimator>(
    estimator: &E,
    points: &[Point3<f64>],
    model: &E::Model,
    indices: &[usize],
) -> f64 {
    if indices.is_empty() {
        return 0.0;
    }
    let sum: f64 = indices
        .iter()
        .filter_map(|&i| points.get(i))
        .map(|p| estimator.squared_distance(model, p))
        .sum();
    (sum / indices.len() as f64).sqrt()
}

/// Indices of the points within `threshold` of `model` (strictly), ascending. Parallel with the
/// `parallel` feature; the order (and so the result) is the same for any thread count.
pub fn inliers<E: Estimator>(
    estimator: &E,
    points: &[Point3<f64>],
    model: &E::Model,
    threshold: f64,
) -> Vec<usize> {
    let t2 = threshold * threshold;
    let inside =
        |(i, p): (usize, &Point3<f64>)| (estimator.squared_distance(model, p) < t2).then_some(i);
    #[cfg(feature = "parallel")]
    if points.len() >= PARALLEL_MIN_POINTS {
        use rayon::prelude::*;
        return points.par_iter().enumerate().filter_map(inside).collect();
    }
    points.iter().enumerate().filter_map(inside).collect()
}

/// The indices among `among` (ascending, as given) of the points within `threshold` of `model`:
/// [`inliers`] of the points `points[among]` without a copy of them, by index into `points`.
pub(crate) fn inliers_among<E: Estimator>(
    estimator: &E,
    points: &[Point3<f64>],
    among: &[usize],
    model: &E::Model,
    threshold: f64,
) -> Vec<usize> {
    let t2 = threshold * threshold;
    let inside = |&i: &usize| {
        points
            .get(i)
            .is_some_and(|p| estimator.squared_distance(model, p) < t2)
            .then_some(i)
    };
    #[cfg(feature = "parallel")]
    if among.len() >= PARALLEL_MIN_POINTS {
        use rayon::prelude::*;
        return among.par_iter().filter_map(inside).collect();
    }
    among.iter().filter_map(inside).collect()
}

/// Per-point passes (inliers, joint assignment) run in parallel only from this many points: below
/// it, handing the work to the thread pool costs more than it saves (measured on 10k-point clouds).
/// The output is the same either way.
#[cfg(feature = "parallel")]
const PARALLEL_MIN_POINTS: usize = 16_384;
