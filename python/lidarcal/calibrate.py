"""One entry point over the calibration methods, and the calibration of a whole rig.

* :func:`calibrate` -- ``method="auto"`` tries the wall-corner method, the targetless plane
  matching and (when both clouds carry intensity) the taped poles, and keeps the result under
  which most target points land on the reference cloud; ``result.method`` says which.
* :func:`calibrate_rig` -- every target to the reference, every pair of targets that overlaps,
  and a small pose-graph refinement that makes the set consistent.
* :func:`refine_pose_graph` -- that refinement on poses and edges of your own.

The work is in the Rust crate (``lidarcal::calib::method``, ``lidarcal::calib::rig`` and
``lidarcal::pose_graph``), with the GIL released; this module checks arguments and builds the
result objects.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
import numpy.typing as npt

from lidarcal import _lidarcal
from lidarcal._lidarcal import (
    CalibrationResult,
    calibrate_planes,
    calibrate_poles,
    calibrate_targetless,
)

Method = Literal["auto", "planes", "targetless", "poles"]
#: The method names (``Method``'s values), for the checks and the command line.
METHOD_NAMES: tuple[Method, ...] = get_args(Method)
Vendor = Literal["velodyne", "hesai", "leishen", "robosense"]
F64Array = npt.NDArray[np.float64]

#: Distance (m) within which a mapped target point counts as agreeing with the reference cloud
#: when ``method="auto"`` compares the methods' results.
AGREEMENT_DISTANCE: float = _lidarcal.AGREEMENT_DISTANCE

#: ``method="auto"`` prefers the earlier method (corner, targetless, poles) when its agreement is
#: within this fraction of the best.
AUTO_TIE: float = _lidarcal.AUTO_TIE

#: Default share of a cloud above the intensity threshold beyond which the poles are refused.
MAX_BRIGHT_FRACTION: float = _lidarcal.MAX_BRIGHT_FRACTION

# ``method`` of :func:`calibrate` left None: the Rust ``Method::default()`` (``calibrate_rig``'s).
_DEFAULT_METHOD: Method = _lidarcal._defaults()["calibrate_rig"]["method"]

#: A target pair is calibrated directly in :func:`calibrate_rig` only when the result brings at
#: least this fraction of its points onto the other cloud.
MIN_PAIR_OVERLAP: float = _lidarcal.MIN_PAIR_OVERLAP


def _unknown_method(method: object) -> str:
    """The message of the Rust ``Method::from_name`` for an unknown name."""
    *first, last = (repr(m) for m in METHOD_NAMES)
    return f"method must be {', '.join(first)} or {last}, got {method!r}"


def _cloud(points: npt.ArrayLike, name: str) -> F64Array:
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"{name} must have shape (N, 3) or (N, 4), got {a.shape}")
    return a


def calibrate(
    reference: npt.ArrayLike,
    target: npt.ArrayLike,
    method: Method | None = None,
    *,
    seed: int = 0,
    up: npt.ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: Vendor | None = None,
    max_bright_fraction: float | None = None,
) -> CalibrationResult:
    """Calibrates ``reference_from_target`` with one method, or the best of all for ``"auto"``.

    The options go to the methods that take them: ``up`` to the corner method,
    ``distance_threshold`` to the corner and targetless methods, ``intensity_threshold``,
    ``vendor`` and ``max_bright_fraction`` to the poles (None: that method's default).
    Left None, ``method`` is the Rust ``Method::default()`` and ``max_bright_fraction`` that of
    ``PoleOptions::default()``: ``method='auto'``, ``max_bright_fraction=0.25``.

    ``"planes"`` is :func:`lidarcal.calibrate_planes` (a wall corner), ``"targetless"``
    :func:`lidarcal.calibrate_targetless` (the planes of any scene, e.g. a street), ``"poles"``
    :func:`lidarcal.calibrate_poles` (needs ``(N, 4)`` clouds with intensity). Every method's
    result has passed :func:`lidarcal.check` (``result.check``). ``"auto"`` runs every applicable
    method and ranks the certified results by their certificate (agreement with the other cloud's
    surface at the noise scale, less free-space violations, both ways); within 0.01 of the best
    the earlier method wins. When two certified results disagree beyond their tolerance and
    their certificates do not clearly separate them it raises :class:`CalibrationError` of kind
    ``"inconsistent_methods"``, unless the corner method's result keeps the other sensor's free
    space clearly clearer than every result it disagrees with (it is returned). The result's
    ``method`` names the method. Raises :class:`CalibrationError` (with ``kind``) listing each
    method's reason when none succeeds, ``ValueError`` for malformed input or an unknown method.
    """
    ref = _cloud(reference, "reference")
    tgt = _cloud(target, "target")
    if method is None:
        method = _DEFAULT_METHOD
    if method == "planes":
        return calibrate_planes(ref, tgt, seed=seed, up=up, distance_threshold=distance_threshold)
    if method == "targetless":
        return calibrate_targetless(ref, tgt, seed=seed, distance_threshold=distance_threshold)
    if method == "poles":
        return calibrate_poles(
            ref,
            tgt,
            seed=seed,
            intensity_threshold=intensity_threshold,
            vendor=vendor,
            max_bright_fraction=max_bright_fraction,
        )
    if method != "auto":
        raise ValueError(_unknown_method(method))
    return _lidarcal.calibrate_auto(
        ref,
        tgt,
        seed=seed,
        up=up,
        distance_threshold=distance_threshold,
        intensity_threshold=intensity_threshold,
        vendor=vendor,
        max_bright_fraction=max_bright_fraction,
    )


@dataclass(frozen=True)
class RigEdge:
    """One pairwise calibration used by :func:`calibrate_rig`: ``a_from_b`` maps sensor ``b``'s
    points into sensor ``a``'s frame."""

    a: str
    b: str
    method: str
    a_from_b: F64Array
    #: Disagreement of the refined rig with this edge: rotation (degrees) and translation (m).
    rotation_residual_deg: float = float("nan")
    translation_residual_m: float = float("nan")
    #: The method's full result (diagnostics, covariance); ``result.transform`` is ``a_from_b``.
    result: CalibrationResult | None = None


@dataclass(frozen=True)
class PoseGraphReport:
    """How the pose-graph refinement of :func:`calibrate_rig` went.

    ``converged`` is False only when the iteration cap ran out first; ``termination`` says why it
    stopped (``"step_tolerance"``, ``"no_further_decrease"``, ``"nothing_to_refine"`` or
    ``"max_iterations"``); ``iterations`` counts the Gauss-Newton iterations run; the cost
    ``sum(e^T W e)`` over the edges never rises, so ``final_cost <= initial_cost``."""

    converged: bool
    termination: str
    iterations: int
    initial_cost: float
    final_cost: float


@dataclass(frozen=True)
class RigCalibration:
    """The calibrated rig: ``transforms[name]`` is ``reference_from_<name>`` (4x4) after the
    pose-graph refinement; ``direct[name]`` the direct calibration to the reference (missing
    when it failed: the target was reached through another target); ``edges`` every pairwise
    result used, with its residual against the refined rig; ``failures`` the pairs that could
    not be calibrated, with the reason."""

    transforms: dict[str, F64Array]
    direct: dict[str, F64Array]
    edges: list[RigEdge]
    failures: dict[tuple[str, str], str] = field(default_factory=dict)
    #: The :class:`CalibrationError` kind of each failure (None: calibrated but barely overlapping).
    failure_kinds: dict[tuple[str, str], str | None] = field(default_factory=dict)
    #: Targets no calibration connects to the reference (only with ``require_all=False``).
    unconnected: list[str] = field(default_factory=list)
    #: How the pose-graph refinement went (always set by :func:`calibrate_rig`).
    pose_graph: PoseGraphReport | None = None


def refine_pose_graph(
    poses: npt.ArrayLike,
    edges: Sequence[tuple[int, int, npt.ArrayLike, npt.ArrayLike]],
    iterations: int | None = None,
) -> F64Array:
    """Refines a pose graph whose node 0 (the reference) is fixed.

    ``poses`` is a ``(K, 4, 4)`` stack of ``reference_from_node``; each edge
    ``(a, b, a_from_b, information)`` is a measured transform between nodes ``a`` and ``b`` with
    its ``(6, 6)`` information matrix (inverse covariance of the tangent ``[rho, phi]``).
    Minimises the sum of ``e^T W e`` with ``e = log(a_from_b^-1 a^-1 b)`` by Gauss-Newton and
    returns the refined ``(K, 4, 4)`` stack, node 0 unchanged. Raises ``ValueError`` for an edge
    naming a missing node, a node in no edge, or a malformed matrix.

    Left None, ``iterations`` (Gauss-Newton iterations at most) takes the Rust
    ``PoseGraphOptions::default()``: ``iterations=20``.
    """
    stack = np.asarray(poses, dtype=np.float64)
    if stack.ndim != 3 or stack.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (K, 4, 4), got {stack.shape}")
    if iterations is not None and (
        isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0
    ):
        raise ValueError(f"iterations must be a non-negative integer, got {iterations!r}")
    refined = _lidarcal.refine_pose_graph(
        list(stack),
        [
            (int(a), int(b), np.asarray(z, dtype=np.float64), np.asarray(w, dtype=np.float64))
            for a, b, z, w in edges
        ],
        iterations,
    )
    return np.stack(refined) if refined else np.zeros((0, 4, 4))


def calibrate_rig(
    reference: npt.ArrayLike,
    targets: Mapping[str, npt.ArrayLike] | Sequence[npt.ArrayLike],
    *,
    method: Method | None = None,
    pairwise: bool | None = None,
    require_all: bool | None = None,
    seed: int = 0,
    up: npt.ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: Vendor | None = None,
    max_bright_fraction: float | None = None,
) -> RigCalibration:
    """Calibrates several target LiDARs against one reference and makes the set consistent.

    ``targets`` maps names to clouds (a sequence is named ``"target0"``, ``"target1"``, ...).
    Each target is calibrated to the reference with :func:`calibrate`; with ``pairwise``, every
    pair of targets too, kept when the result brings at least 20 % of the points of one onto the
    other (the units overlap). A pose graph over all kept edges, each weighted by its covariance,
    is then refined by Gauss-Newton with the reference fixed, so that ``a_from_b`` of every pair
    agrees with ``reference_from_a`` and ``reference_from_b``. A target that fails against the
    reference but overlaps a calibrated target is reached through it. Raises
    :class:`CalibrationError` when some target cannot be connected to the reference, unless
    ``require_all=False``: then the others are returned and that target is listed in
    ``unconnected`` (with its reasons in ``failures``). Raises :class:`CalibrationError` of kind
    ``"inconsistent_methods"`` when the kept edges contradict each other (an edge disagrees with
    the refined rig by more than 1 degree or 10 cm: a cycle that does not close has a wrong edge,
    and the rig cannot tell which). The method options go to every edge's calibration as in
    :func:`calibrate`.

    Left None, ``method``, ``pairwise`` and ``require_all`` take the Rust ``RigOptions::default()``
    and ``max_bright_fraction`` that of ``PoleOptions::default()``: ``method='auto'``,
    ``pairwise=True``, ``require_all=True``, ``max_bright_fraction=0.25``.
    """
    ref = _cloud(reference, "reference")
    if isinstance(targets, Mapping):
        clouds = {str(k): _cloud(v, str(k)) for k, v in targets.items()}
    else:
        clouds = {f"target{i}": _cloud(v, f"target{i}") for i, v in enumerate(targets)}
    if not clouds:
        raise ValueError("targets is empty")
    if method is not None and method not in METHOD_NAMES:
        raise ValueError(_unknown_method(method))
    out = _lidarcal.calibrate_rig(
        ref,
        list(clouds.items()),
        method=method,
        pairwise=pairwise,
        require_all=require_all,
        seed=seed,
        up=up,
        distance_threshold=distance_threshold,
        intensity_threshold=intensity_threshold,
        vendor=vendor,
        max_bright_fraction=max_bright_fraction,
    )
    return RigCalibration(
        transforms=dict(out["transforms"]),
        direct=dict(out["direct"]),
        edges=[
            RigEdge(
                a=a,
                b=b,
                method=m,
                a_from_b=z,
                rotation_residual_deg=rot,
                translation_residual_m=trans,
                result=result,
            )
            for a, b, m, z, rot, trans, result in out["edges"]
        ],
        failures=dict(out["failures"]),
        failure_kinds=dict(out["failure_kinds"]),
        unconnected=list(out["unconnected"]),
        pose_graph=PoseGraphReport(**out["pose_graph"]),
    )
