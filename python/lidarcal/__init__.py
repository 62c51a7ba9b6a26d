"""lidarcal: extrinsic calibration between LiDARs.

Transforms are 4x4 float64 matrices ``reference_from_target`` (``p_ref = R @ p_tgt + t``);
point clouds are ``(N, 3)`` or ``(N, 4)`` arrays of float32 or float64.

Calibration:

* :func:`calibrate_planes` -- from a wall corner (three planes) seen by both sensors, with no
  initial guess and any mounting; returns a :class:`CalibrationResult`.
* :func:`calibrate_poles` -- from two (or more) non-parallel poles wrapped in retro-reflective
  tape, from ``(N, 4)`` clouds with intensity; returns the same :class:`CalibrationResult`.
* :func:`calibrate_targetless` -- from the planes of an ordinary scene (a street with facades),
  no target and no initial guess: plane pairs/triplets matched by their angles, verified and
  refined by point-to-plane ICP; refuses scenes that leave a direction unobserved.
* Every method returns a :class:`CalibrationResult`: the fields all methods fill (``transform``,
  ``check``, ``rmse``, ``inliers_reference``/``inliers_target`` per matched plane or pole,
  ``covariance``, ``refinement`` -- a :class:`Refinement` -- and ``timings``) and the method's own
  in ``details``, a :class:`PlanarDetails`, :class:`PoleDetails` or :class:`TargetlessDetails`;
  the names are those of the Rust ``Calibration``.
* :func:`calibrate` -- one entry point: ``method="auto"`` tries the corner, the targetless and
  (with intensity) the pole method and keeps the best; ``result.method`` names it.
* :func:`calibrate_rig` -- several targets to one reference plus target-to-target edges, made
  consistent by a pose-graph refinement; returns a :class:`RigCalibration`, whose ``pose_graph``
  (a :class:`PoseGraphReport`) says how the refinement went.
* :func:`check` -- certifies any ``reference_from_target`` (from this library, a file or another
  tool) against the two clouds: a :class:`CheckReport` with the verdict ``"consistent"``,
  ``"inconsistent"`` or ``"unverifiable"``, its reason and the evidence. Every calibration passes
  its result through it and returns only consistent ones (``result.check``).
* :func:`calibrate_sequence` -- from a drive: lists of synchronized frames of both sensors, which
  need not see the same thing at the same time (front and rear units); each sensor's odometry,
  hand-eye calibration of the motions, then the target's frames aligned to the reference's map.
  Returns a :class:`SequenceResult`. :func:`odometry` gives one sensor's ``(K, 4, 4)`` poses.
* :mod:`lidarcal.metrics` -- :func:`lidarcal.metrics.rqe`, the Renyi quadratic entropy
  crispness for comparing calibrations without ground truth.

The numerical kernels it builds on:

* :func:`kabsch` -- the rotation best aligning two sets of vectors;
* :func:`so3_exp`, :func:`so3_log`, :func:`se3_exp`, :func:`se3_log` -- the Lie group maps;
* :func:`refine_point_to_plane`, :func:`refine_point_to_line` -- Levenberg-Marquardt refinement
  of a transform from point-to-plane or point-to-line residuals, returning a :class:`RefineResult`;
* :func:`ransac_plane`, :func:`ransac_line`, :func:`extract_planes` -- deterministic parallel
  RANSAC, returning :class:`Plane` and :class:`Line` objects with their inliers.

Files: :func:`read_points` reads PCD (ascii, binary, binary_compressed), PLY, KITTI ``.bin``,
``.npy`` and CSV/TXT into an ``(N, K)`` float64 array (``x y z`` and the intensity when the file
has one, or the fields you name); :func:`write_points` writes them. A malformed file raises
:class:`FileFormatError` (a ``ValueError``) naming the file and the problem.

The scan simulator lives in :mod:`lidarcal.sim` (``from lidarcal import sim``) and the command
line in ``lidarcal simulate``.

Bad input raises ``ValueError`` naming the problem; a calibration that cannot be trusted raises
:class:`CalibrationError` whose ``kind`` says which way it failed: ``"ambiguous"``,
``"unobservable"``, ``"too_few_features"``, ``"no_agreement"``, ``"out_of_range"``,
``"time_budget"`` or ``"inconsistent_methods"``.
"""

from lidarcal import metrics, sim  # `from lidarcal import sim` / `metrics`
from lidarcal._lidarcal import (
    CalibrationError,
    CalibrationResult,
    CheckReport,
    FileFormatError,
    Line,
    PlanarDetails,
    Plane,
    PoleDetails,
    Refinement,
    RefineResult,
    SequenceResult,
    TargetlessDetails,
    __version__,
    calibrate_planes,
    calibrate_poles,
    calibrate_sequence,
    calibrate_targetless,
    check,
    extract_planes,
    kabsch,
    odometry,
    ransac_line,
    ransac_plane,
    read_points,
    refine_point_to_line,
    refine_point_to_plane,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
    write_points,
)
from lidarcal.calibrate import (
    PoseGraphReport,
    RigCalibration,
    RigEdge,
    calibrate,
    calibrate_rig,
    refine_pose_graph,
)

__all__ = [
    "CalibrationError",
    "CalibrationResult",
    "CheckReport",
    "FileFormatError",
    "Line",
    "PlanarDetails",
    "Plane",
    "PoleDetails",
    "PoseGraphReport",
    "RefineResult",
    "Refinement",
    "RigCalibration",
    "RigEdge",
    "SequenceResult",
    "TargetlessDetails",
    "__version__",
    "calibrate",
    "calibrate_planes",
    "calibrate_poles",
    "calibrate_rig",
    "calibrate_sequence",
    "calibrate_targetless",
    "check",
    "extract_planes",
    "kabsch",
    "metrics",
    "odometry",
    "ransac_line",
    "ransac_plane",
    "read_points",
    "refine_point_to_line",
    "refine_point_to_plane",
    "refine_pose_graph",
    "se3_exp",
    "se3_log",
    "sim",
    "so3_exp",
    "so3_log",
    "write_points",
]
