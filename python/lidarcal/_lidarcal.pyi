"""Type stubs of the compiled extension module ``lidarcal._lidarcal``."""

from collections.abc import Sequence
from os import PathLike
from typing import Any, Literal, TypedDict, overload

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike
F64Array = npt.NDArray[np.float64]
I64Array = npt.NDArray[np.int64]
Frame = Literal["target", "reference"]
LossName = Literal["squared", "linear", "huber", "cauchy"]

__version__: str
#: Names an intensity field may have in a file, compared without case; the first is canonical.
INTENSITY_NAMES: tuple[str, ...]

class CalibrationError(RuntimeError):
    """A calibration could not produce a trustworthy result; the message says why.

    ``kind`` is one of "ambiguous", "unobservable", "too_few_features", "no_agreement",
    "out_of_range", "time_budget" or "inconsistent_methods" (raised by the library; absent on an
    instance made by hand).
    """

    kind: FailureKind

FailureKind = Literal[
    "ambiguous",
    "unobservable",
    "too_few_features",
    "no_agreement",
    "out_of_range",
    "time_budget",
    "inconsistent_methods",
]

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
    def aligned(self) -> F64Array: ...
    @property
    def correction_rotation_deg(self) -> float: ...
    @property
    def correction_translation_m(self) -> float: ...
    @property
    def weakest_translation(self) -> F64Array: ...
    @property
    def weakest_translation_share(self) -> float: ...
    @property
    def weakest_rotation(self) -> F64Array: ...
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
) -> CheckReport: ...

class FileFormatError(ValueError):
    """A file is not a valid point cloud of its format; the message names the file and why."""

class ReadInfo(TypedDict):
    path: str
    fields: list[str]
    available: list[str]
    points: int
    dropped_non_finite: int

FieldsArg = Literal["all"] | Sequence[str] | None

@overload
def read_points(
    path: str | PathLike[str], fields: FieldsArg = None, *, with_info: Literal[False] = False
) -> F64Array: ...
@overload
def read_points(
    path: str | PathLike[str], fields: FieldsArg = None, *, with_info: Literal[True]
) -> tuple[F64Array, ReadInfo]: ...
def write_points(
    path: str | PathLike[str],
    points: ArrayLike,
    fields: Sequence[str] | None = None,
    *,
    pcd_format: Literal["binary", "binary_compressed", "ascii"] = "binary",
) -> None: ...

class RefineResult:
    """The result of a refinement: the transform and the solver's report."""

    @property
    def transform(self) -> F64Array:
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
    def hessian(self) -> F64Array: ...
    @property
    def covariance(self) -> F64Array | None: ...

class CalibrationResult:
    """The result of a calibration: ``transform`` maps target points into the reference frame.

    Common to all methods: ``method`` ("planes", "poles" or "targetless"), ``transform``,
    ``initial_transform``, ``converged``, ``iterations``, ``cost``, ``termination``, ``rmse``,
    ``inlier_counts``, ``inliers_reference``, ``inliers_target``, ``covariance``, ``timings``.
    Attributes of one method are None for the others (``planes_reference``,
    ``planes_target`` and ``distance_thresholds`` serve the corner and the targetless method).
    """

    @property
    def method(self) -> Literal["planes", "poles", "targetless"]: ...
    @property
    def check(self) -> CheckReport: ...
    @property
    def transform(self) -> F64Array:
        """(4, 4) ``reference_from_target``."""
    @property
    def initial_transform(self) -> F64Array: ...
    @property
    def converged(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    @property
    def cost(self) -> float: ...
    @property
    def termination(self) -> str: ...
    @property
    def rmse(self) -> F64Array:
        """(3,) per plane or (K,) per pole, metres."""
    @property
    def inlier_counts(self) -> I64Array: ...
    @property
    def inliers_reference(self) -> list[I64Array]: ...
    @property
    def inliers_target(self) -> list[I64Array]: ...
    @property
    def covariance(self) -> F64Array | None: ...
    @property
    def timings(self) -> dict[str, float]: ...
    # Planes only (None for poles).
    @property
    def planes_reference(self) -> F64Array | None: ...
    @property
    def planes_target(self) -> F64Array | None: ...
    @property
    def ordering_scores(self) -> F64Array | None: ...
    @property
    def ordering_margin(self) -> float | None: ...
    @property
    def used_up(self) -> bool | None: ...
    @property
    def corners(self) -> F64Array | None: ...
    @property
    def distance_thresholds(self) -> F64Array | None: ...
    # Poles only (None for planes).
    @property
    def poles_reference(self) -> F64Array | None:
        """(K, 6) matched axes [point, direction] in the reference frame."""
    @property
    def poles_target(self) -> F64Array | None: ...
    @property
    def pole_radii(self) -> F64Array | None: ...
    @property
    def intensity_thresholds(self) -> F64Array | None: ...
    @property
    def hypothesis_scores(self) -> F64Array | None:
        """(H,) score of every correspondence/sign hypothesis, lower is better."""
    @property
    def hypotheses(self) -> list[dict[str, Any]] | None: ...
    @property
    def chosen_hypothesis(self) -> int | None: ...
    @property
    def hypothesis_margin(self) -> float | None: ...
    @property
    def ambiguous(self) -> bool | None: ...
    # Targetless only (None for the others).
    @property
    def matched_planes(self) -> int | None: ...
    @property
    def plane_counts(self) -> tuple[int, int] | None: ...
    @property
    def hypothesis_counts(self) -> tuple[int, int] | None: ...
    @property
    def best_score(self) -> float | None: ...
    @property
    def second_score(self) -> float | None: ...
    @property
    def agreement(self) -> float | None: ...
    @property
    def violations(self) -> tuple[float, float] | None:
        """(target points in the reference's free space, reference points in the target's)."""
    @property
    def sweep(self) -> bool | None: ...
    @property
    def triplet(self) -> bool | None: ...
    @property
    def weakest_translation(self) -> tuple[F64Array, float] | None:
        """(direction in the reference frame, share of the translation information)."""
    @property
    def icp_fitness(self) -> float | None: ...

def calibrate_targetless(
    reference: ArrayLike,
    target: ArrayLike,
    *,
    distance_threshold: float | None = None,
    voxel_size: float = 0.1,
    max_planes: int = 10,
    max_translation: float = 5.0,
    challenger_range: float = 2.0,
    icp: bool = True,
    min_information_share: float = 0.01,
    ground_sweep: bool = True,
    refuse_ambiguous: bool = True,
    seed: int = 0,
) -> CalibrationResult: ...
def overlap(
    reference: ArrayLike, target: ArrayLike, transform: ArrayLike, distance: float = 0.25
) -> float: ...

AGREEMENT_DISTANCE: float
AUTO_TIE: float
MIN_PAIR_OVERLAP: float
MAX_BRIGHT_FRACTION: float

def calibrate_auto(
    reference: ArrayLike,
    target: ArrayLike,
    *,
    seed: int = 0,
    up: ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: str | None = None,
    max_bright_fraction: float | None = None,
) -> CalibrationResult: ...

PoseGraphTermination = Literal[
    "step_tolerance", "no_further_decrease", "nothing_to_refine", "max_iterations"
]

class PoseGraphReportDict(TypedDict):
    """How the pose-graph refinement of ``calibrate_rig`` went."""

    converged: bool
    termination: PoseGraphTermination
    iterations: int
    initial_cost: float
    final_cost: float

class RigDict(TypedDict):
    """What ``calibrate_rig`` returns (``lidarcal.calibrate_rig`` builds its result from it)."""

    transforms: dict[str, F64Array]
    direct: dict[str, F64Array]
    #: (a, b, method, a_from_b, rotation_residual_deg, translation_residual_m, result)
    edges: list[tuple[str, str, str, F64Array, float, float, CalibrationResult]]
    failures: dict[tuple[str, str], str]
    failure_kinds: dict[tuple[str, str], FailureKind | None]
    unconnected: list[str]
    pose_graph: PoseGraphReportDict

def calibrate_rig(
    reference: ArrayLike,
    targets: list[tuple[str, ArrayLike]],
    *,
    method: str = "auto",
    pairwise: bool = True,
    require_all: bool = True,
    seed: int = 0,
    up: ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: str | None = None,
    max_bright_fraction: float | None = None,
) -> RigDict: ...
def refine_pose_graph(
    poses: list[F64Array],
    edges: list[tuple[int, int, F64Array, F64Array]],
    iterations: int = 20,
) -> list[F64Array]: ...
def calibrate_planes(
    reference: ArrayLike,
    target: ArrayLike,
    *,
    distance_threshold: float | None = None,
    seed: int = 0,
    up: ArrayLike | None = None,
    refine: bool = True,
    loss: Literal["auto", "squared", "linear", "huber", "cauchy"] = "auto",
    loss_scale: float | None = None,
    min_inliers: int = 50,
    max_iterations: int = 100,
    time_budget_s: float | None = None,
) -> CalibrationResult: ...
def calibrate_poles(
    reference: ArrayLike,
    target: ArrayLike,
    *,
    intensity_threshold: float | None = None,
    vendor: Literal["velodyne", "hesai", "leishen", "robosense"] | None = None,
    pole_radius: float | None = None,
    seed: int = 0,
    axis_fit: Literal["cylinder", "line"] = "cylinder",
    cluster_tolerance: float = 0.5,
    min_points: int = 15,
    max_iterations: int = 100,
    time_budget_s: float | None = None,
    max_bright_fraction: float = 0.25,
) -> CalibrationResult: ...
def rqe(points: ArrayLike, sigma: float) -> float: ...

class Plane:
    """A plane ``normal . p + offset = 0`` found in a point cloud, with its inliers."""

    @property
    def normal(self) -> F64Array:
        """(3,) unit normal, pointing toward the sensor."""
    @property
    def offset(self) -> float: ...
    @property
    def coefficients(self) -> F64Array:
        """(4,) ``[nx, ny, nz, d]``."""
    @property
    def inliers(self) -> I64Array:
        """int64 indices of the inlier points, ascending."""
    @property
    def rms(self) -> float: ...
    @property
    def hypotheses(self) -> int: ...

class Line:
    """A 3D line through ``point`` along the unit ``direction``, with its inliers."""

    @property
    def point(self) -> F64Array: ...
    @property
    def direction(self) -> F64Array: ...
    @property
    def inliers(self) -> I64Array: ...
    @property
    def rms(self) -> float: ...
    @property
    def hypotheses(self) -> int: ...

def ransac_plane(
    points: ArrayLike,
    distance_threshold: float,
    *,
    confidence: float = 0.999,
    max_iterations: int = 10000,
    seed: int = 0,
) -> Plane: ...
def ransac_line(
    points: ArrayLike,
    distance_threshold: float,
    *,
    confidence: float = 0.999,
    max_iterations: int = 10000,
    seed: int = 0,
) -> Line: ...
def extract_planes(
    points: ArrayLike,
    count: int = 3,
    distance_threshold: float = 0.05,
    *,
    min_inliers: int = 50,
    refinement_rounds: int = 3,
    min_angle_deg: float | None = None,
    confidence: float = 0.999,
    max_iterations: int = 10000,
    seed: int = 0,
) -> list[Plane]: ...
def score_planes(
    points: ArrayLike, planes: ArrayLike, distance_threshold: float
) -> tuple[F64Array, I64Array]: ...
def score_lines(
    points: ArrayLike, lines: ArrayLike, distance_threshold: float
) -> tuple[F64Array, I64Array]: ...
def kabsch(a: ArrayLike, b: ArrayLike, weights: ArrayLike | None = None) -> F64Array:
    """The rotation ``R`` minimising ``sum w_i |R b_i - a_i|^2``."""

def so3_exp(phi: ArrayLike) -> F64Array: ...
def so3_log(rotation: ArrayLike) -> F64Array: ...
def se3_exp(xi: ArrayLike) -> F64Array: ...
def se3_log(transform: ArrayLike) -> F64Array: ...
def refine_point_to_plane(
    planes: ArrayLike,
    points: Sequence[ArrayLike],
    initial_transform: ArrayLike | None = None,
    *,
    frames: Sequence[Frame] | None = None,
    loss: LossName = "squared",
    loss_scale: float = 0.1,
    max_iterations: int = 100,
) -> RefineResult: ...
def refine_point_to_line(
    lines: ArrayLike,
    points: Sequence[ArrayLike],
    initial_transform: ArrayLike | None = None,
    *,
    frames: Sequence[Frame] | None = None,
    loss: LossName = "squared",
    loss_scale: float = 0.1,
    max_iterations: int = 100,
) -> RefineResult: ...
def point_to_plane_residuals(
    points: ArrayLike, plane: ArrayLike, transform: ArrayLike, frame: Frame = "target"
) -> tuple[F64Array, F64Array]: ...
def point_to_line_residuals(
    points: ArrayLike, line: ArrayLike, transform: ArrayLike, frame: Frame = "target"
) -> tuple[F64Array, F64Array]: ...

# --- scan simulator (wrapped by lidarcal.sim) ---

class BeamModel:
    """A multi-beam LiDAR model: a preset by name or ``BeamModel.custom(...)``."""

    def __init__(self, name: str) -> None: ...
    @staticmethod
    def custom(
        elevations_deg: ArrayLike,
        *,
        columns: int = 1800,
        min_range: float = 0.5,
        max_range: float = 100.0,
        range_noise: float = 0.01,
        name: str = "custom",
    ) -> BeamModel: ...
    @property
    def name(self) -> str: ...
    @property
    def beams(self) -> int: ...
    @property
    def columns(self) -> int: ...
    @property
    def elevations_deg(self) -> F64Array: ...
    @property
    def min_range(self) -> float: ...
    @property
    def max_range(self) -> float: ...
    @property
    def range_noise(self) -> float: ...

class Shape:
    """A shape in the world frame."""

    @staticmethod
    def rectangle(
        corner: ArrayLike,
        edge_u: ArrayLike,
        edge_v: ArrayLike,
        *,
        intensity: tuple[float, float] = (20.0, 70.0),
    ) -> Shape: ...
    @staticmethod
    def cuboid(
        size: ArrayLike,
        pose: ArrayLike | None = None,
        *,
        intensity: tuple[float, float] = (10.0, 90.0),
    ) -> Shape: ...
    @staticmethod
    def cylinder(
        base: ArrayLike,
        direction: ArrayLike,
        length: float,
        radius: float,
        *,
        intensity: tuple[float, float] = (30.0, 80.0),
        band: tuple[float, float] | None = None,
        band_intensity: tuple[float, float] = (235.0, 255.0),
    ) -> Shape: ...
    @property
    def kind(self) -> str: ...

class Scene:
    """Two sensors' points in their own frames and the ground truth."""

    @property
    def kind(self) -> str: ...
    @property
    def reference(self) -> F64Array: ...
    @property
    def target(self) -> F64Array: ...
    @property
    def reference_rings(self) -> npt.NDArray[np.int64]: ...
    @property
    def target_rings(self) -> npt.NDArray[np.int64]: ...
    @property
    def reference_labels(self) -> npt.NDArray[np.int64]: ...
    @property
    def target_labels(self) -> npt.NDArray[np.int64]: ...
    @property
    def reference_from_target(self) -> F64Array: ...
    @property
    def world_from_reference(self) -> F64Array: ...
    @property
    def planes(self) -> F64Array: ...
    @property
    def pole_axes(self) -> F64Array: ...
    @property
    def pole_radii(self) -> F64Array: ...

def sim_scan(
    shapes: Sequence[Shape],
    model: str | BeamModel | None = None,
    sensor_pose: ArrayLike | None = None,
    *,
    seed: int = 0,
    noise: float | None = None,
    dropout: float = 0.0,
    with_ring: bool = False,
) -> F64Array: ...
def sim_corner_scene(
    model: str | BeamModel | None = None,
    *,
    seed: int = 0,
    clutter_boxes: int = 4,
    extra_walls: int = 0,
    noise: float | None = None,
    dropout: float = 0.0,
    wall_angle_deg: float = 90.0,
    target_tilt_deg: float = 10.0,
    target_relative_yaw_deg: float | None = None,
) -> Scene: ...
def sim_poles_scene(
    model: str | BeamModel | None = None,
    *,
    seed: int = 0,
    radius: float = 0.1,
    distance: float = 5.0,
    distractor: bool = False,
    noise: float | None = None,
    dropout: float = 0.0,
    max_tilt_deg: float = 15.0,
    target_upside_down: bool = False,
) -> Scene: ...
def sim_street_scene(
    *,
    seed: int = 0,
    side: Literal["left", "right"] = "left",
    target_tilt_deg: float = 45.0,
    clutter: bool = True,
    cross_wall: bool = False,
    noise: float | None = None,
    target_offset: float = 0.0,
) -> Scene: ...
def sim_corridor_scene(*, seed: int = 0) -> Scene: ...
def sim_paper_scene(
    *, alpha_deg: float = 90.0, configuration: int | None = 1, seed: int = 0
) -> Scene: ...
def sim_pole_axis_trial(
    distance: float, radius: float, seed: int
) -> tuple[int, float, float, float, float]: ...
def write_pcd(path: str | PathLike[str], points: ArrayLike, *, ascii: bool = False) -> None: ...
