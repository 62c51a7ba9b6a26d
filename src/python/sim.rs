//! Python wrappers of the scan simulator (`lidarcal.sim`) and the PCD writer.

use nalgebra::{Isometry3, Point3};
use numpy::ndarray::{Array1, Ix1, Ix2, Ix3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PySequence};

use super::arrays::{self, row_major, to_numpy};
use super::defaults::table;
use super::run;
use crate::geometry;
use crate::sim::scenes::{
    corner_scene, corridor_scene, drive_scene, paper_scene, poles_scene, street_scene,
    CornerOptions, DriveOptions, PaperConfiguration, PaperOptions, PolesOptions, Side,
    StreetOptions, POLES_RANGE_NOISE,
};
use crate::sim::shapes::{self, IntensityRange};
use crate::sim::{self as core_sim, BeamSettings, Preset, Scan, ScanOptions};

/// The intensity ranges the `Shape` constructors default to.
const RECTANGLE_INTENSITY: IntensityRange = IntensityRange::WALL;
const CUBOID_INTENSITY: IntensityRange = IntensityRange::CLUTTER;
const CYLINDER_INTENSITY: IntensityRange = IntensityRange::POLE;
const BAND_INTENSITY: IntensityRange = IntensityRange::RETROREFLECTIVE;

/// An `intensity=(min, max)` argument, or `default` for None.
fn intensity_arg(value: Option<(f64, f64)>, default: IntensityRange) -> PyResult<IntensityRange> {
    value.map_or(Ok(default), |(min, max)| Ok(IntensityRange::new(min, max)?))
}

fn intensity_tuple(range: IntensityRange) -> (f64, f64) {
    (range.min, range.max)
}

fn pose_arg(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Isometry3<f64>> {
    obj.map_or(Ok(Isometry3::identity()), |m| {
        geometry::isometry_from_matrix(&arrays::matrix4(m, name)?)
            .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
    })
}

fn point_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Point3<f64>> {
    Ok(Point3::from(arrays::vector3(obj, name)?))
}

/// A multi-beam LiDAR model: a preset by name ("vlp16", "hdl32", "hdl64", "os128") or
/// BeamModel.custom(...).
#[pyclass(frozen, module = "lidarcal", name = "BeamModel")]
#[derive(Clone)]
pub(crate) struct BeamModel {
    inner: core_sim::BeamModel,
}

#[pymethods]
impl BeamModel {
    #[new]
    fn new(name: &str) -> PyResult<Self> {
        Ok(BeamModel {
            inner: core_sim::BeamModel::from_name(name)?,
        })
    }
    /// A custom model from beam elevations in degrees. A setting left None takes the Rust
    /// `BeamSettings::default()`: columns=1800, min_range=0.5, max_range=100, range_noise=0.01.
    #[staticmethod]
    #[pyo3(signature = (elevations_deg, *, columns=None, min_range=None, max_range=None, range_noise=None, name="custom"))]
    fn custom(
        elevations_deg: &Bound<'_, PyAny>,
        columns: Option<usize>,
        min_range: Option<f64>,
        max_range: Option<f64>,
        range_noise: Option<f64>,
        name: &str,
    ) -> PyResult<Self> {
        let e = arrays::vector(elevations_deg, "elevations_deg", None)?;
        let d = BeamSettings::default();
        Ok(BeamModel {
            inner: core_sim::BeamModel::custom(
                name,
                &e,
                columns.unwrap_or(d.columns),
                min_range.unwrap_or(d.min_range),
                max_range.unwrap_or(d.max_range),
                range_noise.unwrap_or(d.range_noise),
            )?,
        })
    }
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_string()
    }
    #[getter]
    fn beams(&self) -> usize {
        self.inner.beams()
    }
    #[getter]
    fn columns(&self) -> usize {
        self.inner.columns()
    }
    #[getter]
    fn elevations_deg<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let e: Vec<f64> = self
            .inner
            .elevations()
            .iter()
            .map(|e| e.to_degrees())
            .collect();
        to_numpy(py, Ix1(e.len()), e)
    }
    #[getter]
    fn min_range(&self) -> f64 {
        self.inner.min_range()
    }
    #[getter]
    fn max_range(&self) -> f64 {
        self.inner.max_range()
    }
    #[getter]
    fn range_noise(&self) -> f64 {
        self.inner.range_noise()
    }
    fn __repr__(&self) -> String {
        format!(
            "BeamModel(name='{}', beams={}, columns={}, range=[{}, {}], range_noise={})",
            self.inner.name(),
            self.inner.beams(),
            self.inner.columns(),
            self.inner.min_range(),
            self.inner.max_range(),
            self.inner.range_noise()
        )
    }
}

/// A model name or a BeamModel; None is the default preset (the VLP-16).
fn model_arg(obj: Option<&Bound<'_, PyAny>>) -> PyResult<core_sim::BeamModel> {
    let Some(obj) = obj else {
        return Ok(core_sim::BeamModel::preset(Preset::default()));
    };
    if let Ok(m) = obj.cast::<BeamModel>() {
        return Ok(m.get().inner.clone());
    }
    let name: String = obj.extract().map_err(|_| {
        PyValueError::new_err(
            "model must be a model name (vlp16, hdl32, hdl64, os128) or a BeamModel",
        )
    })?;
    Ok(core_sim::BeamModel::from_name(&name)?)
}

/// A shape in the world frame; build it with Shape.rectangle, Shape.cuboid or Shape.cylinder.
#[pyclass(frozen, module = "lidarcal", name = "Shape")]
#[derive(Clone)]
pub(crate) struct Shape {
    inner: shapes::Shape,
}

#[pymethods]
impl Shape {
    /// A rectangle corner + s * edge_u + t * edge_v, s, t in [0, 1] (edges orthogonal).
    /// intensity None is the Rust `IntensityRange::WALL`: intensity=(20, 70).
    #[staticmethod]
    #[pyo3(signature = (corner, edge_u, edge_v, *, intensity=None))]
    fn rectangle(
        corner: &Bound<'_, PyAny>,
        edge_u: &Bound<'_, PyAny>,
        edge_v: &Bound<'_, PyAny>,
        intensity: Option<(f64, f64)>,
    ) -> PyResult<Self> {
        let r = shapes::Rectangle::new(
            point_arg(corner, "corner")?,
            arrays::vector3(edge_u, "edge_u")?,
            arrays::vector3(edge_v, "edge_v")?,
        )?;
        Ok(Shape {
            inner: shapes::Shape::rectangle(r, intensity_arg(intensity, RECTANGLE_INTENSITY)?),
        })
    }
    /// A box of full size (sx, sy, sz) centred at the origin of pose (4x4 world_from_box).
    /// intensity None is the Rust `IntensityRange::CLUTTER`: intensity=(10, 90).
    #[staticmethod]
    #[pyo3(signature = (size, pose=None, *, intensity=None))]
    fn cuboid(
        size: &Bound<'_, PyAny>,
        pose: Option<&Bound<'_, PyAny>>,
        intensity: Option<(f64, f64)>,
    ) -> PyResult<Self> {
        let b = shapes::Cuboid::new(pose_arg(pose, "pose")?, arrays::vector3(size, "size")?)?;
        Ok(Shape {
            inner: shapes::Shape::cuboid(b, intensity_arg(intensity, CUBOID_INTENSITY)?),
        })
    }
    /// A finite cylinder from its base centre, axis direction, length and radius, with an optional
    /// band (start, end) in metres from the base returning band_intensity. None intensities are the
    /// Rust `IntensityRange::POLE` and `RETROREFLECTIVE`: intensity=(30, 80),
    /// band_intensity=(235, 255).
    #[staticmethod]
    #[pyo3(signature = (base, direction, length, radius, *, intensity=None, band=None, band_intensity=None))]
    fn cylinder(
        base: &Bound<'_, PyAny>,
        direction: &Bound<'_, PyAny>,
        length: f64,
        radius: f64,
        intensity: Option<(f64, f64)>,
        band: Option<(f64, f64)>,
        band_intensity: Option<(f64, f64)>,
    ) -> PyResult<Self> {
        let mut c = shapes::Cylinder::new(
            point_arg(base, "base")?,
            arrays::vector3(direction, "direction")?,
            length,
            radius,
        )?;
        if let Some((start, end)) = band {
            c = c.with_band(start, end, intensity_arg(band_intensity, BAND_INTENSITY)?)?;
        }
        Ok(Shape {
            inner: shapes::Shape::cylinder(c, intensity_arg(intensity, CYLINDER_INTENSITY)?),
        })
    }
    /// "rectangle", "cuboid" or "cylinder".
    #[getter]
    fn kind(&self) -> &'static str {
        match self.inner.geometry {
            shapes::Geometry::Rectangle(_) => "rectangle",
            shapes::Geometry::Cuboid(_) => "cuboid",
            shapes::Geometry::Cylinder(_) => "cylinder",
        }
    }
    fn __repr__(&self) -> String {
        format!("Shape(kind='{}')", self.kind())
    }
}

fn shapes_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<shapes::Shape>> {
    let seq = obj
        .cast::<PySequence>()
        .map_err(|_| PyValueError::new_err("shapes must be a sequence of lidarcal.sim.Shape"))?;
    (0..seq.len()?)
        .map(|i| {
            let item = seq.get_item(i)?;
            let shape = item.cast::<Shape>().map_err(|_| {
                PyValueError::new_err(format!("shapes[{i}] is not a lidarcal.sim.Shape"))
            })?;
            Ok(shape.get().inner)
        })
        .collect()
}

fn scan_rows(scan: &Scan, with_ring: bool) -> (usize, usize, Vec<f64>) {
    let cols = if with_ring { 5 } else { 4 };
    let mut data = Vec::with_capacity(scan.len() * cols);
    for p in &scan.points {
        data.extend_from_slice(&[p.position.x, p.position.y, p.position.z, p.intensity]);
        if with_ring {
            data.push(f64::from(p.ring));
        }
    }
    (scan.len(), cols, data)
}

fn scan_array<'py>(
    py: Python<'py>,
    scan: &Scan,
    with_ring: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (n, cols, data) = scan_rows(scan, with_ring);
    to_numpy(py, Ix2(n, cols), data)
}

/// Simulates one revolution; returns (N, 4) [x, y, z, intensity] (or (N, 5) with the ring) in the
/// sensor frame, ring-major. dropout None is the Rust `ScanOptions::default()`: dropout=0.
#[pyfunction]
#[pyo3(signature = (shapes, model=None, sensor_pose=None, *, seed=0, noise=None, dropout=None, with_ring=false))]
#[allow(clippy::too_many_arguments)]
fn sim_scan<'py>(
    py: Python<'py>,
    shapes: &Bound<'py, PyAny>,
    model: Option<&Bound<'py, PyAny>>,
    sensor_pose: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    noise: Option<f64>,
    dropout: Option<f64>,
    with_ring: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let shapes = shapes_arg(shapes)?;
    let model = model_arg(model)?;
    let pose = pose_arg(sensor_pose, "sensor_pose")?;
    let d = ScanOptions::default();
    let options = ScanOptions {
        seed,
        range_noise: noise.or(d.range_noise),
        dropout: dropout.unwrap_or(d.dropout),
    };
    let scan = run(py, move || core_sim::scan(&model, &shapes, &pose, &options))?;
    scan_array(py, &scan, with_ring)
}

/// A simulated scene: two sensors' points in their own frames and the ground truth.
#[pyclass(frozen, module = "lidarcal", name = "Scene")]
pub(crate) struct Scene {
    kind: &'static str,
    inner: core_sim::Scene,
}

fn matrix<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    to_numpy(py, Ix2(4, 4), row_major(&pose.to_homogeneous()))
}

fn rings<'py>(py: Python<'py>, scan: &Scan) -> Bound<'py, PyArray1<i64>> {
    let r: Vec<i64> = scan.points.iter().map(|p| i64::from(p.ring)).collect();
    Array1::from_vec(r).into_pyarray(py)
}

fn labels<'py>(py: Python<'py>, scan: &Scan) -> Bound<'py, PyArray1<i64>> {
    let r: Vec<i64> = scan
        .points
        .iter()
        .map(|p| p.shape.map_or(-1, |s| i64::try_from(s).unwrap_or(-1)))
        .collect();
    Array1::from_vec(r).into_pyarray(py)
}

#[pymethods]
impl Scene {
    /// "corner", "poles" or "paper".
    #[getter]
    fn kind(&self) -> &'static str {
        self.kind
    }
    /// (N, 4) reference points [x, y, z, intensity] in the reference frame.
    #[getter]
    fn reference<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        scan_array(py, &self.inner.reference, false)
    }
    /// (M, 4) target points in the target frame.
    #[getter]
    fn target<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        scan_array(py, &self.inner.target, false)
    }
    /// (N,) ring index of each reference point.
    #[getter]
    fn reference_rings<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        rings(py, &self.inner.reference)
    }
    /// (M,) ring index of each target point.
    #[getter]
    fn target_rings<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        rings(py, &self.inner.target)
    }
    /// (N,) index of the shape each reference point hit (-1: clutter of the paper protocol).
    #[getter]
    fn reference_labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        labels(py, &self.inner.reference)
    }
    /// (M,) index of the shape each target point hit.
    #[getter]
    fn target_labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        labels(py, &self.inner.target)
    }
    /// (4, 4) true reference_from_target.
    #[getter]
    fn reference_from_target<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, &self.inner.reference_from_target)
    }
    /// (4, 4) pose of the reference sensor in the scene's world frame.
    #[getter]
    fn world_from_reference<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, &self.inner.world_from_reference)
    }
    /// (K, 4) true planes [nx, ny, nz, d] in the reference frame, normals toward the reference sensor.
    #[getter]
    fn planes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data: Vec<f64> = self
            .inner
            .planes
            .iter()
            .flat_map(|p| [p.normal.x, p.normal.y, p.normal.z, p.offset])
            .collect();
        to_numpy(py, Ix2(self.inner.planes.len(), 4), data)
    }
    /// (K, 6) true pole axes [px, py, pz, dx, dy, dz] in the reference frame (base point, up).
    #[getter]
    fn pole_axes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data: Vec<f64> = self
            .inner
            .poles
            .iter()
            .flat_map(|p| {
                let (q, d) = (p.axis.point, p.axis.direction);
                [q.x, q.y, q.z, d.x, d.y, d.z]
            })
            .collect();
        to_numpy(py, Ix2(self.inner.poles.len(), 6), data)
    }
    /// (K,) pole radii.
    #[getter]
    fn pole_radii<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let r: Vec<f64> = self.inner.poles.iter().map(|p| p.radius).collect();
        to_numpy(py, Ix1(r.len()), r)
    }
    fn __repr__(&self) -> String {
        format!(
            "Scene(kind='{}', reference={} points, target={} points, planes={}, poles={})",
            self.kind,
            self.inner.reference.len(),
            self.inner.target.len(),
            self.inner.planes.len(),
            self.inner.poles.len()
        )
    }
}

/// The building-corner scene; a keyword left None takes the Rust `CornerOptions::default()`.
#[pyfunction]
#[pyo3(signature = (model=None, *, seed=0, clutter_boxes=None, extra_walls=None, noise=None, dropout=None, wall_angle_deg=None, target_tilt_deg=None, target_relative_yaw_deg=None))]
#[allow(clippy::too_many_arguments)]
fn sim_corner_scene<'py>(
    py: Python<'py>,
    model: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    clutter_boxes: Option<usize>,
    extra_walls: Option<usize>,
    noise: Option<f64>,
    dropout: Option<f64>,
    wall_angle_deg: Option<f64>,
    target_tilt_deg: Option<f64>,
    target_relative_yaw_deg: Option<f64>,
) -> PyResult<Scene> {
    let model = model_arg(model)?;
    let d = CornerOptions::default();
    let options = CornerOptions {
        seed,
        clutter_boxes: clutter_boxes.unwrap_or(d.clutter_boxes),
        extra_walls: extra_walls.unwrap_or(d.extra_walls),
        range_noise: noise.or(d.range_noise),
        dropout: dropout.unwrap_or(d.dropout),
        wall_angle_deg: wall_angle_deg.unwrap_or(d.wall_angle_deg),
        target_tilt_deg: target_tilt_deg.unwrap_or(d.target_tilt_deg),
        target_relative_yaw_deg: target_relative_yaw_deg.or(d.target_relative_yaw_deg),
    };
    let inner = run(py, move || corner_scene(&model, &options))?;
    Ok(Scene {
        kind: "corner",
        inner,
    })
}

fn side_name(side: Side) -> &'static str {
    match side {
        Side::Left => "left",
        Side::Right => "right",
    }
}

/// The street scene: a roof HDL-64E (reference) and a tilted wide-angle side unit (target); a
/// keyword left None takes the Rust `StreetOptions::default()`.
// One argument per keyword of `lidarcal.sim.street_scene`.
#[allow(clippy::too_many_arguments)]
#[pyfunction]
#[pyo3(signature = (*, seed=0, side=None, target_tilt_deg=None, clutter=None, cross_wall=None, noise=None, target_offset=None))]
fn sim_street_scene(
    py: Python<'_>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    side: Option<&str>,
    target_tilt_deg: Option<f64>,
    clutter: Option<bool>,
    cross_wall: Option<bool>,
    noise: Option<f64>,
    target_offset: Option<f64>,
) -> PyResult<Scene> {
    let d = StreetOptions::default();
    let side = match side {
        None => d.side,
        Some(name) => [Side::Left, Side::Right]
            .into_iter()
            .find(|s| side_name(*s) == name)
            .ok_or_else(|| {
                PyValueError::new_err(format!("side must be 'left' or 'right', got {name:?}"))
            })?,
    };
    let options = StreetOptions {
        seed,
        side,
        target_tilt_deg: target_tilt_deg.unwrap_or(d.target_tilt_deg),
        clutter: clutter.unwrap_or(d.clutter),
        cross_wall: cross_wall.unwrap_or(d.cross_wall),
        range_noise: noise.or(d.range_noise),
        target_offset: target_offset.unwrap_or(d.target_offset),
    };
    let inner = run(py, move || street_scene(&options))?;
    Ok(Scene {
        kind: "street",
        inner,
    })
}

/// The corridor scene (floor and two parallel walls): translation along it is unobservable.
#[pyfunction]
#[pyo3(signature = (*, seed=0))]
fn sim_corridor_scene(
    py: Python<'_>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<Scene> {
    let inner = run(py, move || corridor_scene(seed))?;
    Ok(Scene {
        kind: "corridor",
        inner,
    })
}

/// The two-poles scene; a keyword left None takes the Rust `PolesOptions::default()` (noise: the
/// scene's own `POLES_RANGE_NOISE`).
#[pyfunction]
#[pyo3(signature = (model=None, *, seed=0, radius=None, distance=None, distractor=None, noise=None, dropout=None, max_tilt_deg=None, target_upside_down=None))]
#[allow(clippy::too_many_arguments)]
fn sim_poles_scene<'py>(
    py: Python<'py>,
    model: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    radius: Option<f64>,
    distance: Option<f64>,
    distractor: Option<bool>,
    noise: Option<f64>,
    dropout: Option<f64>,
    max_tilt_deg: Option<f64>,
    target_upside_down: Option<bool>,
) -> PyResult<Scene> {
    let model = model_arg(model)?;
    let d = PolesOptions::default();
    let options = PolesOptions {
        seed,
        radius: radius.unwrap_or(d.radius),
        distance: distance.unwrap_or(d.distance),
        distractor: distractor.unwrap_or(d.distractor),
        range_noise: noise.or(d.range_noise),
        dropout: dropout.unwrap_or(d.dropout),
        max_tilt_deg: max_tilt_deg.unwrap_or(d.max_tilt_deg),
        target_upside_down: target_upside_down.unwrap_or(d.target_upside_down),
    };
    let inner = run(py, move || poles_scene(&model, &options))?;
    Ok(Scene {
        kind: "poles",
        inner,
    })
}

/// A paper configuration as Python names it: 1, 2 or None (random).
fn configuration_number(configuration: PaperConfiguration) -> Option<u8> {
    match configuration {
        PaperConfiguration::One => Some(1),
        PaperConfiguration::Two => Some(2),
        PaperConfiguration::Random => None,
    }
}

/// The paper's synthetic protocol; configuration 1 or 2 (Table II) or None (random). alpha_deg
/// None takes the Rust `PaperOptions::default()`: alpha_deg=90.
#[pyfunction]
#[pyo3(signature = (*, alpha_deg=None, configuration=Some(1), seed=0))]
fn sim_paper_scene(
    py: Python<'_>,
    alpha_deg: Option<f64>,
    configuration: Option<u8>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<Scene> {
    let configuration = [
        PaperConfiguration::One,
        PaperConfiguration::Two,
        PaperConfiguration::Random,
    ]
    .into_iter()
    .find(|c| configuration_number(*c) == configuration)
    .ok_or_else(|| {
        PyValueError::new_err(format!(
            "configuration must be 1, 2 or None (random), got {}",
            configuration.map_or("None".into(), |c| c.to_string())
        ))
    })?;
    let options = PaperOptions {
        alpha_deg: alpha_deg.unwrap_or(PaperOptions::default().alpha_deg),
        configuration,
        seed,
    };
    let inner = run(py, move || paper_scene(&options))?;
    Ok(Scene {
        kind: "paper",
        inner,
    })
}

/// One frame of a drive as numpy data: the (N, 4) rows and the (N,) shape labels.
struct FrameRows {
    rows: Vec<f64>,
    labels: Vec<i64>,
}

impl FrameRows {
    fn new(scan: &Scan) -> FrameRows {
        let (_, _, rows) = scan_rows(scan, false);
        let labels = scan
            .points
            .iter()
            .map(|p| p.shape.map_or(-1, |s| i64::try_from(s).unwrap_or(-1)))
            .collect();
        FrameRows { rows, labels }
    }
}

/// A read-only numpy array (the frames are shared by every access to a DriveScene's lists).
fn frozen<'py, D: numpy::ndarray::Dimension, T: numpy::Element>(
    array: Bound<'py, numpy::PyArray<T, D>>,
) -> PyResult<Py<numpy::PyArray<T, D>>> {
    let kwargs = PyDict::new(array.py());
    kwargs.set_item("write", false)?;
    array.call_method("setflags", (), Some(&kwargs))?;
    Ok(array.unbind())
}

/// A simulated drive: each unit's frames in its own frame and the true poses (see
/// `lidarcal.sim.drive_scene`). The frames are converted once, read-only.
#[pyclass(frozen, module = "lidarcal", name = "DriveScene")]
pub(crate) struct DriveScene {
    reference_frames: Vec<Py<PyArray2<f64>>>,
    target_frames: Vec<Py<PyArray2<f64>>>,
    reference_labels: Vec<Py<PyArray1<i64>>>,
    target_labels: Vec<Py<PyArray1<i64>>>,
    reference_from_target: Isometry3<f64>,
    world_from_reference: Vec<Isometry3<f64>>,
    times: Vec<f64>,
    shapes: usize,
    field_of_view_deg: f64,
    /// Total points of the reference and the target frames.
    points: (usize, usize),
}

/// A drive's frames of one unit as numpy arrays: the points and the shape labels.
type FrameArrays = (Vec<Py<PyArray2<f64>>>, Vec<Py<PyArray1<i64>>>);

fn frame_arrays(py: Python<'_>, frames: Vec<FrameRows>) -> PyResult<FrameArrays> {
    let mut points = Vec::with_capacity(frames.len());
    let mut labels = Vec::with_capacity(frames.len());
    for f in frames {
        let n = f.labels.len();
        points.push(frozen(to_numpy(py, Ix2(n, 4), f.rows)?)?);
        labels.push(frozen(Array1::from_vec(f.labels).into_pyarray(py))?);
    }
    Ok((points, labels))
}

fn poses<'py>(py: Python<'py>, poses: &[Isometry3<f64>]) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let data: Vec<f64> = poses
        .iter()
        .flat_map(|p| row_major(&p.to_homogeneous()))
        .collect();
    to_numpy(py, Ix3(poses.len(), 4, 4), data)
}

fn clone_all<T>(py: Python<'_>, items: &[Py<T>]) -> Vec<Py<T>> {
    items.iter().map(|a| a.clone_ref(py)).collect()
}

#[pymethods]
impl DriveScene {
    /// K read-only (N_k, 4) arrays [x, y, z, intensity]: the reference (front) unit's frames, each
    /// in its own frame.
    #[getter]
    fn reference_frames(&self, py: Python<'_>) -> Vec<Py<PyArray2<f64>>> {
        clone_all(py, &self.reference_frames)
    }
    /// K read-only (M_k, 4) arrays: the target (rear) unit's frames, each in its own frame.
    #[getter]
    fn target_frames(&self, py: Python<'_>) -> Vec<Py<PyArray2<f64>>> {
        clone_all(py, &self.target_frames)
    }
    /// K read-only (N_k,) arrays: the index of the shape each reference point hit (0: the ground).
    #[getter]
    fn reference_labels(&self, py: Python<'_>) -> Vec<Py<PyArray1<i64>>> {
        clone_all(py, &self.reference_labels)
    }
    /// K read-only (M_k,) arrays: the index of the shape each target point hit (0: the ground).
    #[getter]
    fn target_labels(&self, py: Python<'_>) -> Vec<Py<PyArray1<i64>>> {
        clone_all(py, &self.target_labels)
    }
    /// (4, 4) true reference_from_target.
    #[getter]
    fn reference_from_target<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, &self.reference_from_target)
    }
    /// (K, 4, 4) true pose of the reference unit in the world at each frame.
    #[getter]
    fn world_from_reference<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        poses(py, &self.world_from_reference)
    }
    /// (K, 4, 4) true pose of the target unit in the world at each frame.
    #[getter]
    fn world_from_target<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let t: Vec<Isometry3<f64>> = self
            .world_from_reference
            .iter()
            .map(|w| w * self.reference_from_target)
            .collect();
        poses(py, &t)
    }
    /// (K,) time of each frame, seconds.
    #[getter]
    fn times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        to_numpy(py, Ix1(self.times.len()), self.times.clone())
    }
    fn __len__(&self) -> usize {
        self.times.len()
    }
    fn __repr__(&self) -> String {
        let k = self.times.len();
        let (r, t) = self.points;
        let per_frame = |n: usize| n / k.max(1);
        format!(
            "DriveScene(frames={k}, duration={:.1} s, field_of_view_deg={}, reference={r} points \
             (~{}/frame), target={t} points (~{}/frame), shapes={})",
            self.times.last().copied().unwrap_or(0.0),
            self.field_of_view_deg,
            per_frame(r),
            per_frame(t),
            self.shapes
        )
    }
}

/// A drive through a town by a vehicle with a forward-looking unit at its front (the reference)
/// and a backward-looking one at its rear (the target); keywords as `lidarcal.sim.drive_scene`.
// One argument per keyword of `lidarcal.sim.drive_scene`.
#[allow(clippy::too_many_arguments)]
#[pyfunction]
#[pyo3(signature = (seed=0, *, frames=None, rate_hz=None, body_motion=None, ground=None, field_of_view_deg=None, range_noise=None))]
fn sim_drive_scene(
    py: Python<'_>,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
    frames: Option<usize>,
    rate_hz: Option<f64>,
    body_motion: Option<bool>,
    ground: Option<bool>,
    field_of_view_deg: Option<f64>,
    range_noise: Option<f64>,
) -> PyResult<DriveScene> {
    let d = DriveOptions::default();
    let options = DriveOptions {
        seed,
        frames: frames.unwrap_or(d.frames),
        rate_hz: rate_hz.unwrap_or(d.rate_hz),
        speed: d.speed,
        body_motion: body_motion.unwrap_or(d.body_motion),
        ground: ground.unwrap_or(d.ground),
        field_of_view_deg: field_of_view_deg.unwrap_or(d.field_of_view_deg),
        range_noise: range_noise.or(d.range_noise),
    };
    // Scan and lay the frames out as rows without the GIL; only the numpy wrapping needs it.
    let (drive, reference, target) = run(py, move || {
        let mut drive = drive_scene(&options)?;
        let reference: Vec<FrameRows> = drive.reference_frames.iter().map(FrameRows::new).collect();
        drive.reference_frames = Vec::new();
        let target: Vec<FrameRows> = drive.target_frames.iter().map(FrameRows::new).collect();
        drive.target_frames = Vec::new();
        Ok((drive, reference, target))
    })?;
    let total = |frames: &[FrameRows]| frames.iter().map(|f| f.labels.len()).sum();
    let points = (total(&reference), total(&target));
    let (reference_frames, reference_labels) = frame_arrays(py, reference)?;
    let (target_frames, target_labels) = frame_arrays(py, target)?;
    Ok(DriveScene {
        reference_frames,
        target_frames,
        reference_labels,
        target_labels,
        reference_from_target: drive.reference_from_target,
        world_from_reference: drive.world_from_reference,
        times: drive.times,
        shapes: drive.shapes.len(),
        field_of_view_deg: options.field_of_view_deg,
        points,
    })
}

/// Writes (N, 4) [x, y, z, intensity] or (N, 5) [..., ring] points as a PCD v0.7 file.
#[pyfunction]
#[pyo3(signature = (path, points, *, ascii=false))]
fn write_pcd(
    py: Python<'_>,
    path: std::path::PathBuf,
    points: &Bound<'_, PyAny>,
    ascii: bool,
) -> PyResult<()> {
    let d = arrays::dense(points, "points")?;
    let cols = match d.shape.as_slice() {
        [_, c @ (4 | 5)] => *c,
        _ => {
            return Err(PyValueError::new_err(format!(
                "points must have shape (N, 4) or (N, 5), got {:?}",
                d.shape
            )))
        }
    };
    let with_ring = cols == 5;
    let mut records = Vec::with_capacity(d.data.len() / cols);
    for (i, row) in d.data.chunks_exact(cols).enumerate() {
        let ring = if with_ring {
            let r = row[4];
            if !(r.fract() == 0.0 && (0.0..=f64::from(u16::MAX)).contains(&r)) {
                return Err(PyValueError::new_err(format!(
                    "points[{i}, 4] (ring) must be an integer in [0, 65535], got {r}"
                )));
            }
            r as u16
        } else {
            0
        };
        records.push(crate::io::pcd::PcdPoint {
            position: Point3::new(row[0], row[1], row[2]),
            intensity: row[3],
            ring,
        });
    }
    let format = if ascii {
        crate::io::pcd::PcdFormat::Ascii
    } else {
        crate::io::pcd::PcdFormat::Binary
    };
    run(py, move || {
        crate::io::pcd::write_pcd_file(&path, &records, with_ring, format)
    })
}

/// The centroid-line and cylinder axis errors of one pole-axis study trial:
/// (points, line_error, cylinder_error, cylinder_free_radius_error, estimated_radius).
#[pyfunction]
fn sim_pole_axis_trial(
    py: Python<'_>,
    distance: f64,
    radius: f64,
    #[pyo3(from_py_with = arrays::seed)] seed: u64,
) -> PyResult<(usize, f64, f64, f64, f64)> {
    let t = run(py, move || {
        crate::sim::study::pole_axis_trial(distance, radius, seed)
    })?;
    Ok((
        t.points,
        t.line_error,
        t.cylinder_error,
        t.cylinder_free_radius_error,
        t.estimated_radius,
    ))
}

/// The Rust defaults behind this file's keywords (see `super::defaults`).
pub(crate) fn defaults(out: &Bound<'_, PyDict>) -> PyResult<()> {
    let model = Preset::default().name();
    let b = BeamSettings::default();
    let t = table(out, "BeamModel.custom")?;
    t.set_item("columns", b.columns)?;
    t.set_item("min_range", b.min_range)?;
    t.set_item("max_range", b.max_range)?;
    t.set_item("range_noise", b.range_noise)?;
    table(out, "Shape.rectangle")?.set_item("intensity", intensity_tuple(RECTANGLE_INTENSITY))?;
    table(out, "Shape.cuboid")?.set_item("intensity", intensity_tuple(CUBOID_INTENSITY))?;
    let t = table(out, "Shape.cylinder")?;
    t.set_item("intensity", intensity_tuple(CYLINDER_INTENSITY))?;
    t.set_item("band_intensity", intensity_tuple(BAND_INTENSITY))?;

    let o = ScanOptions::default();
    let t = table(out, "sim_scan")?;
    t.set_item("model", model)?;
    t.set_item("seed", o.seed)?;
    t.set_item("dropout", o.dropout)?;

    let o = CornerOptions::default();
    let t = table(out, "sim_corner_scene")?;
    t.set_item("model", model)?;
    t.set_item("seed", o.seed)?;
    t.set_item("clutter_boxes", o.clutter_boxes)?;
    t.set_item("extra_walls", o.extra_walls)?;
    t.set_item("dropout", o.dropout)?;
    t.set_item("wall_angle_deg", o.wall_angle_deg)?;
    t.set_item("target_tilt_deg", o.target_tilt_deg)?;

    let o = PolesOptions::default();
    let t = table(out, "sim_poles_scene")?;
    t.set_item("model", model)?;
    t.set_item("seed", o.seed)?;
    t.set_item("radius", o.radius)?;
    t.set_item("distance", o.distance)?;
    t.set_item("distractor", o.distractor)?;
    t.set_item("noise", o.range_noise.unwrap_or(POLES_RANGE_NOISE))?;
    t.set_item("dropout", o.dropout)?;
    t.set_item("max_tilt_deg", o.max_tilt_deg)?;
    t.set_item("target_upside_down", o.target_upside_down)?;

    let o = StreetOptions::default();
    let t = table(out, "sim_street_scene")?;
    t.set_item("seed", o.seed)?;
    t.set_item("side", side_name(o.side))?;
    t.set_item("target_tilt_deg", o.target_tilt_deg)?;
    t.set_item("clutter", o.clutter)?;
    t.set_item("cross_wall", o.cross_wall)?;
    t.set_item("target_offset", o.target_offset)?;

    let o = PaperOptions::default();
    let t = table(out, "sim_paper_scene")?;
    t.set_item("alpha_deg", o.alpha_deg)?;
    t.set_item("configuration", configuration_number(o.configuration))?;
    t.set_item("seed", o.seed)?;
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BeamModel>()?;
    m.add_class::<Shape>()?;
    m.add_class::<Scene>()?;
    m.add_class::<DriveScene>()?;
    m.add_function(wrap_pyfunction!(sim_scan, m)?)?;
    m.add_function(wrap_pyfunction!(sim_corner_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_poles_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_street_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_corridor_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_paper_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_drive_scene, m)?)?;
    m.add_function(wrap_pyfunction!(sim_pole_axis_trial, m)?)?;
    m.add_function(wrap_pyfunction!(write_pcd, m)?)?;
    Ok(())
}
