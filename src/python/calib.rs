//! Python wrappers of the calibration methods, the rig and the pose graph (their result object
//! is in `result.rs`).

use nalgebra::{Isometry3, Vector3};
use numpy::PyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::arrays;
use super::defaults::table;
use super::kernels::loss_name;
use super::result::{matrix4, CalibrationResult};
use super::run;
use crate::calib::method::{self, Cloud, Method, MethodOptions};
use crate::calib::planes::{calibrate_planes as rs_calibrate_planes, PlanarOptions};
use crate::calib::poles::{calibrate_poles as rs_calibrate_poles, AxisFit, PoleOptions, Vendor};
use crate::calib::rig::{self, RigOptions};
use crate::calib::targetless::{
    calibrate_targetless as rs_calibrate_targetless, TargetlessOptions,
};
use crate::lm::{LmOptions, Loss};
use crate::pose_graph::{
    refine_pose_graph as rs_refine_pose_graph, PoseGraphEdge, PoseGraphOptions,
};

fn up_arg(up: Option<&Bound<'_, PyAny>>) -> PyResult<Option<(Vector3<f64>, Vector3<f64>)>> {
    let Some(up) = up else {
        return Ok(None);
    };
    let d = arrays::dense(up, "up")?;
    let pair = match d.shape.as_slice() {
        [3] => (
            Vector3::from_column_slice(&d.data),
            Vector3::from_column_slice(&d.data),
        ),
        [2, 3] => (
            Vector3::from_column_slice(&d.data[..3]),
            Vector3::from_column_slice(&d.data[3..]),
        ),
        _ => {
            return Err(PyValueError::new_err(format!(
                "up must be a (3,) vector (same in both frames) or a (2, 3) array \
                 [up_reference, up_target], got shape {:?}",
                d.shape
            )))
        }
    };
    for v in [pair.0, pair.1] {
        if !(v.iter().all(|x| x.is_finite()) && v.norm() > 0.0) {
            return Err(PyValueError::new_err(
                "up vectors must be finite and non-zero",
            ));
        }
    }
    Ok(Some(pair))
}

/// Calibrates reference_from_target from a wall corner (three planes) seen by both sensors.
///
/// reference, target: (N, 3) or (N, 4) clouds in their sensors' frames (float32 or float64).
/// distance_threshold: plane inlier distance in metres; None estimates 3 sigma of each cloud's noise.
/// up: gravity direction, (3,) for both frames or (2, 3) [reference, target]; used only to break
///     a tie between plane correspondences (e.g. a cube corner).
/// refine: run the Levenberg–Marquardt refinement. loss: "auto" (Cauchy at the estimated noise
///     level, 1/3 of the threshold), "squared" (fastest: exact per-plane statistics), "huber" or
///     "cauchy" with loss_scale in metres.
/// time_budget_s: wall-clock limit in seconds; past it CalibrationError ("time budget ...
///     exhausted during <stage>") instead of running on. None: no limit.
/// Left None, refine, loss, min_inliers and max_iterations take the Rust
///     `PlanarOptions::default()`: refine=True, loss='auto', min_inliers=50, max_iterations=100.
/// Raises CalibrationError with the reason when no trustworthy result exists.
#[pyfunction]
#[pyo3(signature = (reference, target, *, distance_threshold=None, seed=0, up=None, refine=None, loss=None, loss_scale=None, min_inliers=None, max_iterations=None, time_budget_s=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_planes(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    distance_threshold: Option<f64>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    refine: Option<bool>,
    loss: Option<&str>,
    loss_scale: Option<f64>,
    min_inliers: Option<usize>,
    max_iterations: Option<usize>,
    time_budget_s: Option<f64>,
) -> PyResult<CalibrationResult> {
    let time_budget = crate::budget::budget_from_secs(time_budget_s)?;
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let needs_scale = |name: &str| {
        loss_scale.ok_or_else(|| {
            PyValueError::new_err(format!("loss={name:?} needs loss_scale (metres)"))
        })
    };
    let defaults = PlanarOptions::default();
    let loss = match loss {
        None => defaults.loss,
        Some("auto") => None,
        Some("squared" | "linear") => Some(Loss::Squared),
        Some("huber") => Some(Loss::Huber {
            delta: needs_scale("huber")?,
        }),
        Some("cauchy") => Some(Loss::Cauchy {
            scale: needs_scale("cauchy")?,
        }),
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "loss must be 'auto', 'squared', 'huber' or 'cauchy', got {other:?}"
            )))
        }
    };
    let options = PlanarOptions {
        distance_threshold,
        seed,
        up: up_arg(up)?,
        refine: refine.unwrap_or(defaults.refine),
        loss,
        min_inliers: min_inliers.unwrap_or(defaults.min_inliers),
        lm: LmOptions {
            max_iterations: max_iterations.unwrap_or(defaults.lm.max_iterations),
            ..defaults.lm
        },
        time_budget,
        ..defaults
    };
    let inner = run(py, move || {
        rs_calibrate_planes(&reference, &target, &options)
    })?;
    Ok(inner.into())
}

/// Calibrates reference_from_target from two (or more) non-parallel taped poles.
///
/// reference, target: (N, 4) clouds [x, y, z, intensity] in their sensors' frames.
/// intensity_threshold: returns at or above it are tape; wins over vendor.
/// vendor: "velodyne" (230), "hesai", "leishen" or "robosense" (200); with neither, the threshold
///     is the middle of the highest wide intensity gap above the median (tape is the brightest).
/// pole_radius: metres, or None to estimate it per pole. axis_fit: "cylinder" or "line" (the
///     centroid line of Xue et al., biased by up to a radius; for comparison).
/// Raises ValueError for malformed input and CalibrationError with the reason (no bright points,
/// fewer than two poles, parallel poles, indistinguishable hypotheses). time_budget_s: as for
/// calibrate_planes (a huge cluster_tolerance on a dense cloud makes the clustering quadratic).
/// max_bright_fraction: refuse when more of a cloud's returns than this share are at or above the
///     threshold (tape is a small part of a scene; a threshold of 0 makes everything "tape");
///     raise it to 1.0 for a cloud cropped to the poles.
/// Left None, axis_fit, cluster_tolerance, min_points, max_iterations and max_bright_fraction take
///     the Rust `PoleOptions::default()`: axis_fit='cylinder', cluster_tolerance=0.5,
///     min_points=15, max_iterations=100, max_bright_fraction=0.25.
#[pyfunction]
#[pyo3(signature = (reference, target, *, intensity_threshold=None, vendor=None, pole_radius=None, seed=0, axis_fit=None, cluster_tolerance=None, min_points=None, max_iterations=None, time_budget_s=None, max_bright_fraction=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_poles(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    pole_radius: Option<f64>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    axis_fit: Option<&str>,
    cluster_tolerance: Option<f64>,
    min_points: Option<usize>,
    max_iterations: Option<usize>,
    time_budget_s: Option<f64>,
    max_bright_fraction: Option<f64>,
) -> PyResult<CalibrationResult> {
    let time_budget = crate::budget::budget_from_secs(time_budget_s)?;
    let (reference, ref_intensity) = arrays::points_with_intensity(reference, "reference")?;
    let (target, tgt_intensity) = arrays::points_with_intensity(target, "target")?;
    let vendor = vendor.map(Vendor::from_name).transpose()?;
    let defaults = PoleOptions::default();
    let axis_fit = match axis_fit {
        None => defaults.axis_fit,
        Some("cylinder") => AxisFit::Cylinder,
        Some("line") => AxisFit::Line,
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "axis_fit must be 'cylinder' or 'line', got {other:?}"
            )))
        }
    };
    let options = PoleOptions {
        intensity_threshold,
        vendor,
        pole_radius,
        seed,
        axis_fit,
        cluster_tolerance: cluster_tolerance.unwrap_or(defaults.cluster_tolerance),
        min_points: min_points.unwrap_or(defaults.min_points),
        lm: LmOptions {
            max_iterations: max_iterations.unwrap_or(defaults.lm.max_iterations),
            ..defaults.lm
        },
        time_budget,
        max_bright_fraction: max_bright_fraction.unwrap_or(defaults.max_bright_fraction),
        ..defaults
    };
    let inner = run(py, move || {
        rs_calibrate_poles(
            &reference,
            &ref_intensity,
            &target,
            &tgt_intensity,
            &options,
        )
    })?;
    Ok(inner.into())
}

/// Calibrates reference_from_target from the planes of an ordinary scene (a street), without an
/// initial guess: plane pairs and triplets matched by their angles, verified by ICP, refined on
/// every matched plane and by point-to-plane ICP on the whole clouds.
///
/// reference, target: (N, 3) or (N, 4) clouds in their sensors' frames.
/// distance_threshold: plane inlier distance (m); None estimates it per cloud.
/// voxel_size: downsampling voxel (m). max_planes: planes per cloud. max_translation: the largest
///     distance between the sensors (m); no pose beyond it is returned. challenger_range: poses up
///     to this multiple of max_translation are verified too, and when one fits as well as or
///     better than the best within range the calibration is refused (ambiguous / out_of_range)
///     rather than answered with the best pose within range; 1.0 trusts the bound. icp: run the final
///     ICP. min_information_share: the weakest direction's share of the information below which
///     the calibration is refused as unobservable. min_agreement: the share of the target points
///     the best pose must bring within 25 cm of the reference (1.5 times it for a pose from the
///     ground sweep), below which the calibration is refused as no agreement. ground_sweep: also hypothesise from the
///     largest plane of each cloud turned about its normal (no common plane pair needed).
///     refuse_ambiguous: raise when a distinct pose verifies almost as well as the best (else
///     return it with ambiguous=True).
/// Left None, the keywords but distance_threshold and seed take the Rust
///     `TargetlessOptions::default()`: voxel_size=0.1, max_planes=10, max_translation=5,
///     challenger_range=2, icp=True, min_information_share=0.01, min_agreement=0.1,
///     ground_sweep=True, refuse_ambiguous=True.
/// Raises CalibrationError naming why (too few planes, nothing verifies, an unconstrained
/// direction such as the axis of a corridor).
#[pyfunction]
#[pyo3(signature = (reference, target, *, distance_threshold=None, voxel_size=None, max_planes=None, max_translation=None, challenger_range=None, icp=None, min_information_share=None, min_agreement=None, ground_sweep=None, refuse_ambiguous=None, seed=0))]
#[allow(clippy::too_many_arguments)]
fn calibrate_targetless(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    distance_threshold: Option<f64>,
    voxel_size: Option<f64>,
    max_planes: Option<usize>,
    max_translation: Option<f64>,
    challenger_range: Option<f64>,
    icp: Option<bool>,
    min_information_share: Option<f64>,
    min_agreement: Option<f64>,
    ground_sweep: Option<bool>,
    refuse_ambiguous: Option<bool>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<CalibrationResult> {
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let d = TargetlessOptions::default();
    let options = TargetlessOptions {
        challenger_range: challenger_range.unwrap_or(d.challenger_range),
        ground_sweep: ground_sweep.unwrap_or(d.ground_sweep),
        refuse_ambiguous: refuse_ambiguous.unwrap_or(d.refuse_ambiguous),
        distance_threshold,
        voxel_size: voxel_size.unwrap_or(d.voxel_size),
        max_planes: max_planes.unwrap_or(d.max_planes),
        max_translation: max_translation.unwrap_or(d.max_translation),
        icp: icp.unwrap_or(d.icp),
        min_information_share: min_information_share.unwrap_or(d.min_information_share),
        min_agreement: min_agreement.unwrap_or(d.min_agreement),
        seed,
        ..d
    };
    let inner = run(py, move || {
        rs_calibrate_targetless(&reference, &target, &options)
    })?;
    Ok(inner.into())
}

/// The options `calibrate(method="auto")` and `calibrate_rig` pass on: `seed` to every method,
/// `up` to the corner method, `distance_threshold` to the corner and targetless methods,
/// `intensity_threshold`, `vendor` and `max_bright_fraction` to the poles; None keeps the
/// method's `Default`.
fn method_options(
    seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<MethodOptions> {
    let mut o = MethodOptions::with_seed(seed);
    if let Some(f) = max_bright_fraction {
        o.poles.max_bright_fraction = f;
    }
    o.planes.up = up_arg(up)?;
    o.planes.distance_threshold = distance_threshold;
    o.targetless.distance_threshold = distance_threshold;
    o.poles.intensity_threshold = intensity_threshold;
    o.poles.vendor = vendor.map(Vendor::from_name).transpose()?;
    Ok(o)
}

/// Points and, for an (N, 4) array, intensities.
type OwnedCloud = (Vec<nalgebra::Point3<f64>>, Option<Vec<f64>>);

fn owned_cloud(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<OwnedCloud> {
    let d = arrays::dense(obj, name)?;
    if d.shape.len() == 2 && d.shape[1] == 4 {
        let (p, i) = arrays::points_with_intensity(obj, name)?;
        Ok((p, Some(i)))
    } else {
        Ok((arrays::points(obj, name)?, None))
    }
}

fn borrow_cloud(c: &OwnedCloud) -> crate::Result<Cloud<'_>> {
    match &c.1 {
        Some(i) => Cloud::with_intensity(&c.0, i),
        None => Ok(Cloud::new(&c.0)),
    }
}

/// calibrate(method="auto") in Rust: the corner method, the targetless method and, when both
/// clouds are (N, 4), the poles; each result certified by check, the best certificate kept
/// (within 0.01 of the best, the earlier method wins). Raises CalibrationError (with kind) listing
/// each method's reason when none succeeds, or of kind "inconsistent_methods" when two certified
/// results disagree.
/// Left None, max_bright_fraction takes the Rust `PoleOptions::default()`:
///     max_bright_fraction=0.25.
#[pyfunction]
#[pyo3(signature = (reference, target, *, seed=0, up=None, distance_threshold=None, intensity_threshold=None, vendor=None, max_bright_fraction=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_auto(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'_, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<CalibrationResult> {
    let options = method_options(
        seed,
        up,
        distance_threshold,
        intensity_threshold,
        vendor,
        max_bright_fraction,
    )?;
    let reference = owned_cloud(reference, "reference")?;
    let target = owned_cloud(target, "target")?;
    let inner = run(py, move || {
        method::calibrate(
            borrow_cloud(&reference)?,
            borrow_cloud(&target)?,
            Method::Auto,
            &options,
        )
    })?;
    Ok(CalibrationResult { inner })
}

/// The rig calibration in Rust (lidarcal.calibrate_rig wraps it). targets: a list of
/// (name, cloud); the method options as for calibrate_auto. Returns a dict: "transforms" and
/// "direct" ({name: (4, 4)}), "edges" (a list of (a, b, method, a_from_b,
/// rotation_residual_deg, translation_residual_m, CalibrationResult)), "failures"
/// ({(a, b): reason}), "unconnected" (names) and "pose_graph" (the refinement's report: a dict of
/// converged, termination, iterations, initial_cost, final_cost).
/// Left None, method, pairwise and require_all take the Rust `RigOptions::default()` and
///     max_bright_fraction `PoleOptions::default()`: method='auto', pairwise=True,
///     require_all=True, max_bright_fraction=0.25.
#[pyfunction]
#[pyo3(signature = (reference, targets, *, method=None, pairwise=None, require_all=None, seed=0, up=None, distance_threshold=None, intensity_threshold=None, vendor=None, max_bright_fraction=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate_rig<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    targets: Vec<(String, Bound<'py, PyAny>)>,
    method: Option<&str>,
    pairwise: Option<bool>,
    require_all: Option<bool>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    up: Option<&Bound<'py, PyAny>>,
    distance_threshold: Option<f64>,
    intensity_threshold: Option<f64>,
    vendor: Option<&str>,
    max_bright_fraction: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let defaults = RigOptions::default();
    let method = match method {
        Some(name) => Method::from_name(name)?,
        None => defaults.method,
    };
    let methods = method_options(
        seed,
        up,
        distance_threshold,
        intensity_threshold,
        vendor,
        max_bright_fraction,
    )?;
    let reference = owned_cloud(reference, "reference")?;
    let clouds = targets
        .iter()
        .map(|(name, obj)| Ok((name.clone(), owned_cloud(obj, name)?)))
        .collect::<PyResult<Vec<_>>>()?;
    let options = RigOptions {
        method,
        methods,
        pairwise: pairwise.unwrap_or(defaults.pairwise),
        require_all: require_all.unwrap_or(defaults.require_all),
        ..defaults
    };
    let out = run(py, move || {
        let borrowed = clouds
            .iter()
            .map(|(n, c)| Ok((n.as_str(), borrow_cloud(c)?)))
            .collect::<crate::Result<Vec<_>>>()?;
        rig::calibrate_rig(borrow_cloud(&reference)?, &borrowed, &options)
    })?;
    let d = PyDict::new(py);
    let poses = |list: &[(String, Isometry3<f64>)]| -> PyResult<Bound<'py, PyDict>> {
        let m = PyDict::new(py);
        for (name, pose) in list {
            m.set_item(name, matrix4(py, pose)?)?;
        }
        Ok(m)
    };
    d.set_item("transforms", poses(&out.transforms)?)?;
    d.set_item("direct", poses(&out.direct)?)?;
    let edges = out
        .edges
        .into_iter()
        .map(|e| {
            Ok((
                e.a,
                e.b,
                e.method.name(),
                matrix4(py, &e.a_from_b)?,
                e.rotation_residual_deg,
                e.translation_residual_m,
                Bound::new(py, CalibrationResult { inner: e.result })?,
            ))
        })
        .collect::<PyResult<Vec<_>>>()?;
    d.set_item("edges", edges)?;
    let failures = PyDict::new(py);
    let failure_kinds = PyDict::new(py);
    for f in &out.failures {
        failures.set_item((f.a.clone(), f.b.clone()), f.reason.clone())?;
        failure_kinds.set_item((f.a.clone(), f.b.clone()), f.kind.map(|k| k.name()))?;
    }
    d.set_item("failures", failures)?;
    d.set_item("failure_kinds", failure_kinds)?;
    d.set_item("unconnected", out.unconnected)?;
    let report = out.pose_graph;
    let graph = PyDict::new(py);
    graph.set_item("converged", report.converged)?;
    graph.set_item("termination", report.termination.as_str())?;
    graph.set_item("iterations", report.iterations)?;
    graph.set_item("initial_cost", report.initial_cost)?;
    graph.set_item("final_cost", report.final_cost)?;
    d.set_item("pose_graph", graph)?;
    Ok(d)
}

/// Refines a pose graph whose node 0 is fixed (see lidarcal.refine_pose_graph).
/// Left None, iterations takes the Rust `PoseGraphOptions::default()` max_iterations:
///     iterations=20.
#[pyfunction]
#[pyo3(signature = (poses, edges, iterations=None))]
fn refine_pose_graph<'py>(
    py: Python<'py>,
    poses: Vec<Bound<'py, PyAny>>,
    edges: Vec<(usize, usize, Bound<'py, PyAny>, Bound<'py, PyAny>)>,
    iterations: Option<usize>,
) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
    let poses = poses
        .iter()
        .enumerate()
        .map(|(i, p)| {
            Ok(crate::geometry::isometry_from_matrix(&arrays::matrix4(
                p,
                &format!("poses[{i}]"),
            )?)?)
        })
        .collect::<PyResult<Vec<_>>>()?;
    let edges = edges
        .iter()
        .enumerate()
        .map(|(k, (a, b, z, w))| {
            let z = crate::geometry::isometry_from_matrix(&arrays::matrix4(
                z,
                &format!("edges[{k}] a_from_b"),
            )?)?;
            let w = arrays::matrix(w, &format!("edges[{k}] information"), 6, 6)?;
            Ok(PoseGraphEdge {
                a: *a,
                b: *b,
                a_from_b: z,
                information: nalgebra::Matrix6::from_row_slice(&w),
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let d = PoseGraphOptions::default();
    let options = PoseGraphOptions {
        max_iterations: iterations.unwrap_or(d.max_iterations),
        ..d
    };
    let refined = run(py, move || rs_refine_pose_graph(&poses, &edges, &options))?;
    refined.poses.iter().map(|p| matrix4(py, p)).collect()
}

/// Fraction of target points that land within `distance` of a reference point under
/// `transform` (reference_from_target).
/// Left None, distance takes the Rust `MethodOptions::default().agreement_distance` (the rig's
///     pair overlap test, `AGREEMENT_DISTANCE`): distance=0.25.
#[pyfunction]
#[pyo3(signature = (reference, target, transform, distance=None))]
fn overlap(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    transform: &Bound<'_, PyAny>,
    distance: Option<f64>,
) -> PyResult<f64> {
    let distance = distance.unwrap_or(MethodOptions::default().agreement_distance);
    let reference = arrays::points(reference, "reference")?;
    let target = arrays::points(target, "target")?;
    let pose = crate::geometry::isometry_from_matrix(&arrays::matrix4(transform, "transform")?)?;
    if !(distance.is_finite() && distance > 0.0) {
        return Err(PyValueError::new_err(format!(
            "distance must be finite and positive, got {distance}"
        )));
    }
    run(py, move || {
        let surface = crate::icp::SurfaceCloud::new(reference)?;
        Ok(surface.overlap(&target, &pose, distance))
    })
}

/// Rényi quadratic entropy crispness of a cloud (larger is crisper); see lidarcal.metrics.rqe.
#[pyfunction]
fn rqe(py: Python<'_>, points: &Bound<'_, PyAny>, sigma: f64) -> PyResult<f64> {
    let points = arrays::points(points, "points")?;
    run(py, move || crate::metrics::rqe(&points, sigma)).map(|r| r.crispness)
}

/// The Rust defaults behind the calibration functions' keywords (see `super::defaults`).
pub(crate) fn defaults(out: &Bound<'_, PyDict>) -> PyResult<()> {
    let o = PlanarOptions::default();
    let t = table(out, "calibrate_planes")?;
    t.set_item("seed", o.seed)?;
    t.set_item("refine", o.refine)?;
    t.set_item("loss", o.loss.map_or("auto", loss_name))?;
    t.set_item("min_inliers", o.min_inliers)?;
    t.set_item("max_iterations", o.lm.max_iterations)?;

    let o = PoleOptions::default();
    let t = table(out, "calibrate_poles")?;
    t.set_item("seed", o.seed)?;
    t.set_item("axis_fit", axis_fit_name(o.axis_fit))?;
    t.set_item("cluster_tolerance", o.cluster_tolerance)?;
    t.set_item("min_points", o.min_points)?;
    t.set_item("max_iterations", o.lm.max_iterations)?;
    t.set_item("max_bright_fraction", o.max_bright_fraction)?;
    let max_bright_fraction = o.max_bright_fraction;

    let o = TargetlessOptions::default();
    let t = table(out, "calibrate_targetless")?;
    t.set_item("seed", o.seed)?;
    t.set_item("voxel_size", o.voxel_size)?;
    t.set_item("max_planes", o.max_planes)?;
    t.set_item("max_translation", o.max_translation)?;
    t.set_item("challenger_range", o.challenger_range)?;
    t.set_item("icp", o.icp)?;
    t.set_item("min_information_share", o.min_information_share)?;
    t.set_item("min_agreement", o.min_agreement)?;
    t.set_item("ground_sweep", o.ground_sweep)?;
    t.set_item("refuse_ambiguous", o.refuse_ambiguous)?;

    let t = table(out, "calibrate_auto")?;
    t.set_item("seed", MethodOptions::default().planes.seed)?;
    t.set_item("max_bright_fraction", max_bright_fraction)?;

    let o = RigOptions::default();
    let t = table(out, "calibrate_rig")?;
    t.set_item("seed", o.methods.planes.seed)?;
    t.set_item("method", o.method.name())?;
    t.set_item("pairwise", o.pairwise)?;
    t.set_item("require_all", o.require_all)?;
    t.set_item("max_bright_fraction", o.methods.poles.max_bright_fraction)?;

    let t = table(out, "refine_pose_graph")?;
    t.set_item("iterations", PoseGraphOptions::default().max_iterations)?;
    let t = table(out, "overlap")?;
    t.set_item("distance", MethodOptions::default().agreement_distance)?;
    Ok(())
}

/// The name `calibrate_poles` reads an axis fit by.
fn axis_fit_name(fit: AxisFit) -> &'static str {
    match fit {
        AxisFit::Cylinder => "cylinder",
        AxisFit::Line => "line",
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(calibrate_planes, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_poles, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_targetless, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_auto, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_rig, m)?)?;
    m.add_function(wrap_pyfunction!(refine_pose_graph, m)?)?;
    m.add_function(wrap_pyfunction!(overlap, m)?)?;
    m.add("AGREEMENT_DISTANCE", method::AGREEMENT_DISTANCE)?;
    m.add("AUTO_TIE", method::AUTO_TIE)?;
    m.add("MIN_PAIR_OVERLAP", rig::MIN_PAIR_OVERLAP)?;
    m.add(
        "MAX_BRIGHT_FRACTION",
        crate::calib::poles::MAX_BRIGHT_FRACTION,
    )?;
    m.add_function(wrap_pyfunction!(rqe, m)?)?;
    Ok(())
}
