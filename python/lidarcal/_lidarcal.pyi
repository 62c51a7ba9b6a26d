"""Type stubs of the compiled extension module ``lidarcal._lidarcal``.

Checked against the built module by ``python -m mypy.stubtest`` (``scripts/check.sh``). Names
that exist only here (type aliases, ``TypedDict`` shapes) start with ``_`` so that nobody imports
them at runtime, and a default the extension cannot show at runtime (PyO3 renders a tuple or
``Some(..)`` default as ``...``) is written ``...`` here rather than copied from the Rust
signature, where it lives. A keyword whose default lives in the Rust core takes ``None``; the
docstring says the value, and ``tests/python/test_defaults.py`` holds it to ``_defaults()``.
"""

from collections.abc import Sequence
from os import PathLike
from typing import Any, Literal, TypedDict, final, overload

import numpy as np
import numpy.typing as npt

# What src/python/mod.rs registers (PyO3 makes the runtime `__all__`); stubtest checks both agree.
__all__ = [
    "AGREEMENT_DISTANCE",
    "AUTO_TIE",
    "INTENSITY_NAMES",
    "MAX_BRIGHT_FRACTION",
    "MIN_PAIR_OVERLAP",
    "BeamModel",
    "CalibrationError",
    "CalibrationResult",
    "CheckReport",
    "DriveScene",
    "FileFormatError",
    "Line",
    "PlanarDetails",
    "Plane",
    "PoleDetails",
    "RefineResult",
    "Refinement",
    "Scene",
    "SequenceResult",
    "Shape",
    "TargetlessDetails",
    "__version__",
    "_defaults",
    "calibrate_auto",
    "calibrate_planes",
    "calibrate_poles",
    "calibrate_rig",
    "calibrate_sequence",
    "calibrate_targetless",
    "check",
    "extract_planes",
    "kabsch",
    "odometry",
    "overlap",
    "point_to_line_residuals",
    "point_to_plane_residuals",
    "ransac_line",
    "ransac_plane",
    "read_points",
    "refine_point_to_line",
    "refine_point_to_plane",
    "refine_pose_graph",
    "rqe",
    "score_lines",
    "score_planes",
    "se3_exp",
    "se3_log",
    "sim_corner_scene",
    "sim_corridor_scene",
    "sim_drive_scene",
    "sim_paper_scene",
    "sim_pole_axis_trial",
    "sim_poles_scene",
    "sim_scan",
    "sim_street_scene",
    "so3_exp",
    "so3_log",
    "write_pcd",
    "write_points",
]

_ArrayLike = npt.ArrayLike
_F64Array = npt.NDArray[np.float64]
_I64Array = npt.NDArray[np.int64]
_Frame = Literal["target", "reference"]
_LossName = Literal["squared", "linear", "huber", "cauchy"]

__version__: str
#: Names an intensity field may have in a file, compared without case; the first is canonical.
INTENSITY_NAMES: tuple[str, ...]

class CalibrationError(RuntimeError):
    """A calibration could not produce a trustworthy result; the message says why.

    ``kind`` is one of "ambiguous", "unobservable", "too_few_features", "no_agreement",
    "out_of_range", "time_budget" or "inconsistent_methods" (raised by the library; absent on an
    instance made by hand).
    """

    kind: _FailureKind

_FailureKind = Literal[
    "ambiguous",
    "unobservable",
    "too_few_features",
    "no_agreement",
    "out_of_range",
    "time_budget",
    "inconsistent_methods",
]

@final
class CheckReport:
    """What ``check`` found: a verdict, its one-line reason and the evidence."""

    @property
    def verdict(self) -> Literal["consistent", "inconsistent", "unverifiable"]: ...
    @property
    def reason(self) -> str: ...
    @property
    def overlap(self) -> float: ...
    @property
    def reverse_overlap(self) -> float: ...
    @property
    def agreement(self) -> float: ...
    @property
    def reverse_agreement(self) -> float: ...
    @property
    def agreement_gain(self) -> float: ...
    @property
    def violations(self) -> float: ...
    @property
    def reverse_violations(self) -> float: ...
    @property
    def rmse(self) -> float: ...
    @property
    def noise(self) -> float: ...
    @property
    def overlap_points(self) -> int: ...
    @property
    def aligned(self) -> _F64Array: ...
    @property
    def correction_rotation_deg(self) -> float: ...
    @property
    def correction_translation_m(self) -> float: ...
    @property
    def weakest_translation(self) -> _F64Array: ...
    @property
    def weakest_translation_share(self) -> float: ...
    @property
    def weakest_rotation(self) -> _F64Array: ...
    @property
    def weakest_rotation_share(self) -> float: ...
    @property
    def detectable_rotation_deg(self) -> float: ...
    @property
    def detectable_translation_m(self) -> float: ...
    def to_dict(self) -> dict[str, Any]: ...
    def __bool__(self) -> bool: ...

def check(
    reference: npt.ArrayLike,
    target: npt.ArrayLike,
    transform: npt.ArrayLike,
    *,
    noise: float | None = None,
    voxel_size: float | None = None,
    samples: int | None = None,
    rotation_tolerance_deg: float | None = None,
    translation_tolerance_m: float | None = None,
) -> CheckReport:
    """Checks ``transform`` (``reference_from_target``) against the two clouds.

    ``noise`` None measures the range noise. Defaults (Rust ``CheckOptions::default()``):
    ``voxel_size=0.1``, ``samples=4000``, ``rotation_tolerance_deg=0.5``,
    ``translation_tolerance_m=0.06``.
    """

@final
class SequenceResult:
    """What ``calibrate_sequence`` found: the extrinsic, the hand-eye start, the map alignment's
    evidence and both trajectories."""

    @property
    def method(self) -> Literal["sequence"]: ...
    @property
    def transform(self) -> _F64Array: ...
    @property
    def hand_eye_transform(self) -> _F64Array: ...
    @property
    def unobserved_by_motion(self) -> _F64Array | None: ...
    @property
    def fitness(self) -> float: ...
    @property
    def rmse(self) -> float: ...
    @property
    def converged(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    @property
    def reference_poses(self) -> _F64Array: ...
    @property
    def target_poses(self) -> _F64Array: ...
    @property
    def distance(self) -> float: ...
    @property
    def covariance(self) -> _F64Array | None: ...
    @property
    def weakest_translation(self) -> tuple[_F64Array, float]: ...
    @property
    def weakest_rotation(self) -> tuple[_F64Array, float]: ...
    @property
    def timings(self) -> dict[str, float]: ...

def odometry(
    frames: Sequence[_ArrayLike],
    *,
    voxel: float | None = None,
    min_range: float | None = None,
    max_range: float | None = None,
) -> _F64Array:
    """One sensor's ``(K, 4, 4)`` ``world_from_sensor`` poses from its frames (the world is the
    first frame). Defaults (Rust ``OdometryOptions::default()``): ``voxel=1.0``,
    ``min_range=0.5``, ``max_range=100.0``."""

def calibrate_sequence(
    reference_frames: Sequence[_ArrayLike],
    target_frames: Sequence[_ArrayLike],
    *,
    seed: int = 0,
    voxel: float | None = None,
    min_range: float | None = None,
    max_range: float | None = None,
    strides: Sequence[int] | None = None,
) -> SequenceResult:
    """``reference_from_target`` from a drive: frame ``k`` of both lists at the same time.
    ``strides`` default ``[5, 10, 20]``; the odometry's defaults as in ``odometry``."""

class FileFormatError(ValueError):
    """A file is not a valid point cloud of its format; the message names the file and why."""

class _ReadInfo(TypedDict):
    path: str
    fields: list[str]
    available: list[str]
    points: int
    dropped_non_finite: int

_FieldsArg = Literal["all"] | Sequence[str] | None

@overload
def read_points(
    path: str | PathLike[str], fields: _FieldsArg = None, *, with_info: Literal[False] = False
) -> _F64Array: ...
@overload
def read_points(
    path: str | PathLike[str], fields: _FieldsArg = None, *, with_info: Literal[True]
) -> tuple[_F64Array, _ReadInfo]: ...
def write_points(
    path: str | PathLike[str],
    points: _ArrayLike,
    fields: Sequence[str] | None = None,
    *,
    pcd_format: Literal["binary", "binary_compressed", "ascii"] = "binary",
) -> None: ...

@final
class RefineResult:
    """The result of a refinement: the transform and the solver's report."""

    @property
    def transform(self) -> _F64Array:
        """(4, 4) ``reference_from_target``."""
    @property
    def initial_cost(self) -> float: ...
    @property
    def cost(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def evaluations(self) -> int: ...
    @property
    def termination(self) -> str: ...
    @property
    def converged(self) -> bool: ...
    @property
    def residual_count(self) -> int: ...
    @property
    def hessian(self) -> _F64Array: ...
    @property
    def covariance(self) -> _F64Array | None: ...

_Solver = Literal["closed_form", "levenberg_marquardt", "icp", "verification", "scene_alignment"]

@final
class Refinement:
    """The solver that produced the returned pose, and how it ended (Rust
    ``calib::Refinement``)."""

    @property
    def solver(self) -> _Solver: ...
    @property
    def converged(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    @property
    def cost(self) -> float:
        """Final cost of Levenberg-Marquardt; NaN for the other solvers."""
    @property
    def termination(self) -> str: ...

class _LmReport(TypedDict):
    initial_cost: float
    final_cost: float
    iterations: int
    evaluations: int
    termination: str
    hessian: _F64Array
    residual_count: int

class _IcpResult(TypedDict):
    pose: _F64Array
    iterations: int
    converged: bool
    correspondences: int
    fitness: float
    rmse: float
    information: _F64Array
    covariance: _F64Array | None

class _Ordering(TypedDict):
    scores: _F64Array
    chosen: int
    margin: float
    used_up: bool

class _Hypothesis(TypedDict):
    matches: list[tuple[int, int, int]]
    reference_from_target: _F64Array
    axis_rms: float
    ground_angle: float | None
    ground_offset: float | None
    overlap: float
    score: float

class _DetectedPole(TypedDict):
    axis: _F64Array
    radius: float
    rms: float
    indices: _I64Array
    extent: tuple[float, float]

class _RejectedCluster(TypedDict):
    size: int
    reason: str

class _PoleExtraction(TypedDict):
    intensity_threshold: float
    bright_points: int
    poles: list[_DetectedPole]
    rejected: list[_RejectedCluster]

class _PlaneFeature(TypedDict):
    plane: _F64Array
    voxels: _I64Array
    centroid: _F64Array
    extent: _F64Array

@final
class PlanarDetails:
    """The corner method's own diagnostics (Rust ``calib::planes::PlanarDetails``)."""

    @property
    def planes_reference(self) -> _F64Array:
        """(3, 4) matched planes ``[nx, ny, nz, d]`` in the reference frame."""
    @property
    def planes_target(self) -> _F64Array: ...
    @property
    def corners(self) -> _F64Array:
        """(2, 3) the corner in the reference and in the target frame."""
    @property
    def ordering(self) -> _Ordering: ...
    @property
    def distance_thresholds(self) -> _F64Array: ...
    @property
    def report(self) -> _LmReport | None: ...

@final
class PoleDetails:
    """The pole method's own diagnostics (Rust ``calib::poles::PoleDetails``)."""

    @property
    def poles_reference(self) -> _F64Array:
        """(K, 6) matched axes ``[point, direction]`` in the reference frame."""
    @property
    def poles_target(self) -> _F64Array: ...
    @property
    def radii(self) -> _F64Array: ...
    @property
    def extractions(self) -> list[_PoleExtraction]: ...
    @property
    def hypotheses(self) -> list[_Hypothesis]:
        """Every correspondence/sign hypothesis, in enumeration order; lower score is better."""
    @property
    def chosen(self) -> int: ...
    @property
    def margin(self) -> float: ...
    @property
    def ambiguous(self) -> bool: ...
    @property
    def report(self) -> _LmReport | None: ...

@final
class TargetlessDetails:
    """The targetless method's own diagnostics (Rust ``calib::targetless::TargetlessDetails``)."""

    @property
    def planes_reference(self) -> _F64Array:
        """(K, 4) matched planes ``[nx, ny, nz, d]`` in the reference frame."""
    @property
    def planes_target(self) -> _F64Array: ...
    @property
    def features(self) -> list[list[_PlaneFeature]]: ...
    @property
    def hypothesis_counts(self) -> tuple[int, int]: ...
    @property
    def verified(self) -> int: ...
    @property
    def triplet(self) -> bool: ...
    @property
    def sweep(self) -> bool: ...
    @property
    def best_score(self) -> float: ...
    @property
    def second_score(self) -> float: ...
    @property
    def agreement(self) -> float: ...
    @property
    def violations(self) -> tuple[float, float]:
        """(target points in the reference's free space, reference points in the target's)."""
    @property
    def ambiguous(self) -> bool: ...
    @property
    def distance_thresholds(self) -> _F64Array: ...
    @property
    def report(self) -> _LmReport | None: ...
    @property
    def icp(self) -> _IcpResult | None: ...
    @property
    def weakest_translation(self) -> tuple[_F64Array, float]:
        """(direction in the reference frame, share of the translation information)."""
    @property
    def weakest_rotation(self) -> tuple[_F64Array, float]: ...
    @property
    def plane_translation_share(self) -> float: ...

@final
class CalibrationResult:
    """The result of a calibration: ``transform`` maps target points into the reference frame.

    The fields every method fills, under the names of the Rust ``calib::Calibration`` (its
    ``reference_from_target`` is ``transform`` here), and the method's own in ``details``
    (see the results page of the documentation).
    """

    @property
    def method(self) -> Literal["planes", "poles", "targetless"]: ...
    @property
    def transform(self) -> _F64Array:
        """(4, 4) ``reference_from_target``."""
    @property
    def initial_transform(self) -> _F64Array: ...
    @property
    def check(self) -> CheckReport: ...
    @property
    def rmse(self) -> _F64Array:
        """(K,) per matched plane or pole, metres."""
    @property
    def inliers_reference(self) -> list[_I64Array]: ...
    @property
    def inliers_target(self) -> list[_I64Array]: ...
    @property
    def covariance(self) -> _F64Array | None: ...
    @property
    def refinement(self) -> Refinement: ...
    @property
    def timings(self) -> dict[str, float]: ...
    @property
    def details(self) -> PlanarDetails | PoleDetails | TargetlessDetails: ...

def calibrate_targetless(
    reference: _ArrayLike,
    target: _ArrayLike,
    *,
    distance_threshold: float | None = None,
    voxel_size: float | None = None,
    max_planes: int | None = None,
    max_translation: float | None = None,
    challenger_range: float | None = None,
    icp: bool | None = None,
    min_information_share: float | None = None,
    min_agreement: float | None = None,
    ground_sweep: bool | None = None,
    refuse_ambiguous: bool | None = None,
    seed: int = 0,
) -> CalibrationResult:
    """Calibrates ``reference_from_target`` from the planes of an ordinary scene, no initial guess.

    Defaults (Rust ``TargetlessOptions::default()``): ``voxel_size=0.1``, ``max_planes=10``,
    ``max_translation=5``, ``challenger_range=2``, ``icp=True``, ``min_information_share=0.01``,
    ``min_agreement=0.1``, ``ground_sweep=True``, ``refuse_ambiguous=True``.
    """

def overlap(
    reference: _ArrayLike,
    target: _ArrayLike,
    transform: _ArrayLike,
    distance: float | None = None,
) -> float:
    """Fraction of target points within ``distance`` of a reference point under ``transform``.

    Default (Rust ``MethodOptions::default().agreement_distance``, :data:`AGREEMENT_DISTANCE`):
    ``distance=0.25``.
    """

AGREEMENT_DISTANCE: float
AUTO_TIE: float
MIN_PAIR_OVERLAP: float
MAX_BRIGHT_FRACTION: float

def calibrate_auto(
    reference: _ArrayLike,
    target: _ArrayLike,
    *,
    seed: int = 0,
    up: _ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: str | None = None,
    max_bright_fraction: float | None = None,
) -> CalibrationResult:
    """``calibrate(method="auto")`` in Rust: every applicable method, the best certified result.

    Default (Rust ``PoleOptions::default()``): ``max_bright_fraction=0.25``.
    """

_PoseGraphTermination = Literal[
    "step_tolerance", "no_further_decrease", "nothing_to_refine", "max_iterations"
]

class _PoseGraphReportDict(TypedDict):
    """How the pose-graph refinement of ``calibrate_rig`` went."""

    converged: bool
    termination: _PoseGraphTermination
    iterations: int
    initial_cost: float
    final_cost: float

class _RigDict(TypedDict):
    """What ``calibrate_rig`` returns (``lidarcal.calibrate_rig`` builds its result from it)."""

    transforms: dict[str, _F64Array]
    direct: dict[str, _F64Array]
    #: (a, b, method, a_from_b, rotation_residual_deg, translation_residual_m, result)
    edges: list[tuple[str, str, str, _F64Array, float, float, CalibrationResult]]
    failures: dict[tuple[str, str], str]
    failure_kinds: dict[tuple[str, str], _FailureKind | None]
    unconnected: list[str]
    pose_graph: _PoseGraphReportDict

def calibrate_rig(
    reference: _ArrayLike,
    targets: list[tuple[str, _ArrayLike]],
    *,
    method: str | None = None,
    pairwise: bool | None = None,
    require_all: bool | None = None,
    seed: int = 0,
    up: _ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: str | None = None,
    max_bright_fraction: float | None = None,
) -> _RigDict:
    """The rig calibration (``lidarcal.calibrate_rig`` wraps it).

    Defaults (Rust ``RigOptions::default()`` and ``PoleOptions::default()``): ``method='auto'``,
    ``pairwise=True``, ``require_all=True``, ``max_bright_fraction=0.25``.
    """

def refine_pose_graph(
    poses: list[_F64Array],
    edges: list[tuple[int, int, _F64Array, _F64Array]],
    iterations: int | None = None,
) -> list[_F64Array]:
    """Refines a pose graph whose node 0 is fixed (``lidarcal.refine_pose_graph`` wraps it).

    Default (Rust ``PoseGraphOptions::default()``): ``iterations=20``.
    """

def calibrate_planes(
    reference: _ArrayLike,
    target: _ArrayLike,
    *,
    distance_threshold: float | None = None,
    seed: int = 0,
    up: _ArrayLike | None = None,
    refine: bool | None = None,
    loss: Literal["auto", "squared", "linear", "huber", "cauchy"] | None = None,
    loss_scale: float | None = None,
    min_inliers: int | None = None,
    max_iterations: int | None = None,
    time_budget_s: float | None = None,
) -> CalibrationResult:
    """Calibrates ``reference_from_target`` from a wall corner (three planes) seen by both sensors.

    Defaults (Rust ``PlanarOptions::default()``): ``refine=True``, ``loss='auto'``,
    ``min_inliers=50``, ``max_iterations=100``.
    """

def calibrate_poles(
    reference: _ArrayLike,
    target: _ArrayLike,
    *,
    intensity_threshold: float | None = None,
    vendor: Literal["velodyne", "hesai", "leishen", "robosense"] | None = None,
    pole_radius: float | None = None,
    seed: int = 0,
    axis_fit: Literal["cylinder", "line"] | None = None,
    cluster_tolerance: float | None = None,
    min_points: int | None = None,
    max_iterations: int | None = None,
    time_budget_s: float | None = None,
    max_bright_fraction: float | None = None,
) -> CalibrationResult:
    """Calibrates ``reference_from_target`` from two (or more) non-parallel taped poles.

    Defaults (Rust ``PoleOptions::default()``): ``axis_fit='cylinder'``,
    ``cluster_tolerance=0.5``, ``min_points=15``, ``max_iterations=100``,
    ``max_bright_fraction=0.25``.
    """

def rqe(points: _ArrayLike, sigma: float) -> float: ...

@final
class Plane:
    """A plane ``normal . p + offset = 0`` found in a point cloud, with its inliers."""

    @property
    def normal(self) -> _F64Array:
        """(3,) unit normal, pointing toward the sensor."""
    @property
    def offset(self) -> float: ...
    @property
    def coefficients(self) -> _F64Array:
        """(4,) ``[nx, ny, nz, d]``."""
    @property
    def inliers(self) -> _I64Array:
        """int64 indices of the inlier points, ascending."""
    @property
    def rms(self) -> float: ...
    @property
    def hypotheses(self) -> int: ...

@final
class Line:
    """A 3D line through ``point`` along the unit ``direction``, with its inliers."""

    @property
    def point(self) -> _F64Array: ...
    @property
    def direction(self) -> _F64Array: ...
    @property
    def inliers(self) -> _I64Array: ...
    @property
    def rms(self) -> float: ...
    @property
    def hypotheses(self) -> int: ...

def ransac_plane(
    points: _ArrayLike,
    distance_threshold: float,
    *,
    confidence: float | None = None,
    max_iterations: int | None = None,
    seed: int = 0,
) -> Plane:
    """The plane with the most support among ``points`` (RANSAC, MSAC scoring, refit).

    Defaults (Rust ``RansacOptions::new``): ``confidence=0.999``, ``max_iterations=10000``.
    """

def ransac_line(
    points: _ArrayLike,
    distance_threshold: float,
    *,
    confidence: float | None = None,
    max_iterations: int | None = None,
    seed: int = 0,
) -> Line:
    """The line with the most support among ``points`` (see :func:`ransac_plane`).

    Defaults (Rust ``RansacOptions::new``): ``confidence=0.999``, ``max_iterations=10000``.
    """

def extract_planes(
    points: _ArrayLike,
    count: int = 3,
    distance_threshold: float = 0.05,
    *,
    min_inliers: int | None = None,
    refinement_rounds: int | None = None,
    min_angle_deg: float | None = None,
    confidence: float | None = None,
    max_iterations: int | None = None,
    seed: int = 0,
) -> list[Plane]:
    """``count`` planes, largest first: sequential RANSAC, then a joint reassignment and refit.

    Defaults (Rust ``ExtractOptions::new`` and ``RansacOptions::new``): ``min_inliers=50``,
    ``refinement_rounds=3``, ``confidence=0.999``, ``max_iterations=10000``.
    """

def score_planes(
    points: _ArrayLike, planes: _ArrayLike, distance_threshold: float
) -> tuple[_F64Array, _I64Array]: ...
def score_lines(
    points: _ArrayLike, lines: _ArrayLike, distance_threshold: float
) -> tuple[_F64Array, _I64Array]: ...
def kabsch(a: _ArrayLike, b: _ArrayLike, weights: _ArrayLike | None = None) -> _F64Array:
    """The rotation ``R`` minimising ``sum w_i |R b_i - a_i|^2``."""

def so3_exp(phi: _ArrayLike) -> _F64Array: ...
def so3_log(rotation: _ArrayLike) -> _F64Array: ...
def se3_exp(xi: _ArrayLike) -> _F64Array: ...
def se3_log(transform: _ArrayLike) -> _F64Array: ...
def refine_point_to_plane(
    planes: _ArrayLike,
    points: Sequence[_ArrayLike],
    initial_transform: _ArrayLike | None = None,
    *,
    frames: Sequence[_Frame] | None = None,
    loss: _LossName | None = None,
    loss_scale: float = 0.1,
    max_iterations: int | None = None,
) -> RefineResult:
    """Levenberg-Marquardt refinement of ``reference_from_target`` from point-to-plane residuals.

    Defaults (Rust ``Loss::default()`` and ``LmOptions::default()``): ``loss='squared'``,
    ``max_iterations=100``.
    """

def refine_point_to_line(
    lines: _ArrayLike,
    points: Sequence[_ArrayLike],
    initial_transform: _ArrayLike | None = None,
    *,
    frames: Sequence[_Frame] | None = None,
    loss: _LossName | None = None,
    loss_scale: float = 0.1,
    max_iterations: int | None = None,
) -> RefineResult:
    """Levenberg-Marquardt refinement of ``reference_from_target`` from point-to-line distances.

    Defaults (Rust ``Loss::default()`` and ``LmOptions::default()``): ``loss='squared'``,
    ``max_iterations=100``.
    """

def point_to_plane_residuals(
    points: _ArrayLike, plane: _ArrayLike, transform: _ArrayLike, frame: _Frame = "target"
) -> tuple[_F64Array, _F64Array]: ...
def point_to_line_residuals(
    points: _ArrayLike, line: _ArrayLike, transform: _ArrayLike, frame: _Frame = "target"
) -> tuple[_F64Array, _F64Array]: ...

# --- scan simulator (wrapped by lidarcal.sim) ---

@final
class BeamModel:
    """A multi-beam LiDAR model: a preset by name or ``BeamModel.custom(...)``."""

    def __new__(cls, name: str) -> BeamModel: ...
    @staticmethod
    def custom(
        elevations_deg: _ArrayLike,
        *,
        columns: int | None = None,
        min_range: float | None = None,
        max_range: float | None = None,
        range_noise: float | None = None,
        name: str = "custom",
    ) -> BeamModel:
        """A custom model from beam elevations in degrees.

        Defaults (Rust ``BeamSettings::default()``): ``columns=1800``, ``min_range=0.5``,
        ``max_range=100``, ``range_noise=0.01``.
        """

    @property
    def name(self) -> str: ...
    @property
    def beams(self) -> int: ...
    @property
    def columns(self) -> int: ...
    @property
    def elevations_deg(self) -> _F64Array: ...
    @property
    def min_range(self) -> float: ...
    @property
    def max_range(self) -> float: ...
    @property
    def range_noise(self) -> float: ...

@final
class Shape:
    """A shape in the world frame."""

    @staticmethod
    def rectangle(
        corner: _ArrayLike,
        edge_u: _ArrayLike,
        edge_v: _ArrayLike,
        *,
        intensity: tuple[float, float] | None = None,
    ) -> Shape:
        """A rectangle; default (Rust ``IntensityRange::WALL``): ``intensity=(20, 70)``."""

    @staticmethod
    def cuboid(
        size: _ArrayLike,
        pose: _ArrayLike | None = None,
        *,
        intensity: tuple[float, float] | None = None,
    ) -> Shape:
        """A box; default (Rust ``IntensityRange::CLUTTER``): ``intensity=(10, 90)``."""

    @staticmethod
    def cylinder(
        base: _ArrayLike,
        direction: _ArrayLike,
        length: float,
        radius: float,
        *,
        intensity: tuple[float, float] | None = None,
        band: tuple[float, float] | None = None,
        band_intensity: tuple[float, float] | None = None,
    ) -> Shape:
        """A finite cylinder with an optional taped band.

        Defaults (Rust ``IntensityRange::POLE`` and ``RETROREFLECTIVE``): ``intensity=(30, 80)``,
        ``band_intensity=(235, 255)``.
        """

    @property
    def kind(self) -> str: ...

@final
class Scene:
    """Two sensors' points in their own frames and the ground truth."""

    @property
    def kind(self) -> str: ...
    @property
    def reference(self) -> _F64Array: ...
    @property
    def target(self) -> _F64Array: ...
    @property
    def reference_rings(self) -> npt.NDArray[np.int64]: ...
    @property
    def target_rings(self) -> npt.NDArray[np.int64]: ...
    @property
    def reference_labels(self) -> npt.NDArray[np.int64]: ...
    @property
    def target_labels(self) -> npt.NDArray[np.int64]: ...
    @property
    def reference_from_target(self) -> _F64Array: ...
    @property
    def world_from_reference(self) -> _F64Array: ...
    @property
    def planes(self) -> _F64Array: ...
    @property
    def pole_axes(self) -> _F64Array: ...
    @property
    def pole_radii(self) -> _F64Array: ...

@final
class DriveScene:
    """A simulated drive: each unit's frames in its own frame and the true poses."""

    @property
    def reference_frames(self) -> list[_F64Array]: ...
    @property
    def target_frames(self) -> list[_F64Array]: ...
    @property
    def reference_labels(self) -> list[npt.NDArray[np.int64]]: ...
    @property
    def target_labels(self) -> list[npt.NDArray[np.int64]]: ...
    @property
    def reference_from_target(self) -> _F64Array: ...
    @property
    def world_from_reference(self) -> _F64Array: ...
    @property
    def world_from_target(self) -> _F64Array: ...
    @property
    def times(self) -> _F64Array: ...
    def __len__(self) -> int: ...

def sim_scan(
    shapes: Sequence[Shape],
    model: str | BeamModel | None = None,
    sensor_pose: _ArrayLike | None = None,
    *,
    seed: int = 0,
    noise: float | None = None,
    dropout: float | None = None,
    with_ring: bool = False,
) -> _F64Array: ...
def sim_corner_scene(
    model: str | BeamModel | None = None,
    *,
    seed: int = 0,
    clutter_boxes: int | None = None,
    extra_walls: int | None = None,
    noise: float | None = None,
    dropout: float | None = None,
    wall_angle_deg: float | None = None,
    target_tilt_deg: float | None = None,
    target_relative_yaw_deg: float | None = None,
) -> Scene: ...
def sim_poles_scene(
    model: str | BeamModel | None = None,
    *,
    seed: int = 0,
    radius: float | None = None,
    distance: float | None = None,
    distractor: bool | None = None,
    noise: float | None = None,
    dropout: float | None = None,
    max_tilt_deg: float | None = None,
    target_upside_down: bool | None = None,
) -> Scene: ...
def sim_street_scene(
    *,
    seed: int = 0,
    side: Literal["left", "right"] | None = None,
    target_tilt_deg: float | None = None,
    clutter: bool | None = None,
    cross_wall: bool | None = None,
    noise: float | None = None,
    target_offset: float | None = None,
) -> Scene: ...
def sim_corridor_scene(*, seed: int = 0) -> Scene: ...
def sim_drive_scene(
    seed: int = 0,
    *,
    frames: int | None = None,
    rate_hz: float | None = None,
    body_motion: bool | None = None,
    ground: bool | None = None,
    field_of_view_deg: float | None = None,
    range_noise: float | None = None,
) -> DriveScene: ...
def sim_paper_scene(
    *, alpha_deg: float | None = None, configuration: int | None = ..., seed: int = 0
) -> Scene: ...
def sim_pole_axis_trial(
    distance: float, radius: float, seed: int
) -> tuple[int, float, float, float, float]: ...
def write_pcd(path: str | PathLike[str], points: _ArrayLike, *, ascii: bool = False) -> None: ...

# --- the Rust defaults behind the keywords above that take None ---

def _defaults() -> dict[str, dict[str, Any]]:
    """``{function: {keyword: default}}``: the value a keyword left out (or None) takes, read
    from the Rust ``Default`` or constant it comes from (``Class.method`` names a method)."""
