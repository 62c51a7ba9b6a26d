"""One entry point over the calibration methods, and the calibration of a whole rig.

* :func:`calibrate` -- ``method="auto"`` tries the wall-corner method, the targetless plane
  matching and (when both clouds carry intensity) the taped poles, and keeps the result under
  which most target points land on the reference cloud; ``result.method`` says which.
* :func:`calibrate_rig` -- every target to the reference, every pair of targets that overlaps,
  and a small pose-graph refinement that makes the set consistent.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import (
    CalibrationError,
    CalibrationResult,
    calibrate_planes,
    calibrate_poles,
    calibrate_targetless,
    overlap,
    se3_exp,
    se3_log,
)

Method = Literal["auto", "planes", "targetless", "poles"]
Vendor = Literal["velodyne", "hesai", "leishen", "robosense"]
F64Array = npt.NDArray[np.float64]

#: Distance (m) within which a mapped target point counts as agreeing with the reference cloud
#: when ``method="auto"`` compares the methods' results.
AGREEMENT_DISTANCE = 0.25

#: ``method="auto"`` prefers the earlier method (corner, targetless, poles) when its agreement is
#: within this fraction of the best.
AUTO_TIE = 0.01

#: A target pair is calibrated directly in :func:`calibrate_rig` only when the result brings at
#: least this fraction of its points onto the other cloud.
MIN_PAIR_OVERLAP = 0.2


def _cloud(points: npt.ArrayLike, name: str) -> F64Array:
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"{name} must have shape (N, 3) or (N, 4), got {a.shape}")
    return a


def calibrate(
    reference: npt.ArrayLike,
    target: npt.ArrayLike,
    method: Method = "auto",
    *,
    seed: int = 0,
    up: npt.ArrayLike | None = None,
    distance_threshold: float | None = None,
    intensity_threshold: float | None = None,
    vendor: Vendor | None = None,
) -> CalibrationResult:
    """Calibrates ``reference_from_target`` with one method, or the best of all for ``"auto"``.

    The options go to the methods that take them: ``up`` to the corner method,
    ``distance_threshold`` to the corner and targetless methods, ``intensity_threshold`` and
    ``vendor`` to the poles.

    ``"planes"`` is :func:`lidarcal.calibrate_planes` (a wall corner), ``"targetless"``
    :func:`lidarcal.calibrate_targetless` (the planes of any scene, e.g. a street), ``"poles"``
    :func:`lidarcal.calibrate_poles` (needs ``(N, 4)`` clouds with intensity). ``"auto"`` runs
    every applicable method and returns the result with the largest fraction of target points
    within 25 cm of a reference point; results within 0.01 of the best count as a tie, which the
    earlier method in that order wins. The result's ``method`` names it. Raises
    :class:`CalibrationError` listing each method's reason when none succeeds, ``ValueError`` for
    malformed input or an unknown method.
    """
    ref = _cloud(reference, "reference")
    tgt = _cloud(target, "target")
    if method == "planes":
        return calibrate_planes(ref, tgt, seed=seed, up=up, distance_threshold=distance_threshold)
    if method == "targetless":
        return calibrate_targetless(ref, tgt, seed=seed, distance_threshold=distance_threshold)
    if method == "poles":
        return calibrate_poles(
            ref, tgt, seed=seed, intensity_threshold=intensity_threshold, vendor=vendor
        )
    if method != "auto":
        raise ValueError(
            f"method must be 'auto', 'planes', 'targetless' or 'poles', got {method!r}"
        )
    tried: list[tuple[str, CalibrationResult | str]] = []
    candidates: list[str] = ["planes", "targetless"]
    if ref.shape[1] == 4 and tgt.shape[1] == 4:
        candidates.append("poles")
    for name in candidates:
        try:
            result = calibrate(
                ref,
                tgt,
                name,  # type: ignore[arg-type]
                seed=seed,
                up=up,
                distance_threshold=distance_threshold,
                intensity_threshold=intensity_threshold,
                vendor=vendor,
            )
            tried.append((name, result))
        except CalibrationError as e:
            tried.append((name, str(e)))
    results = [(n, r) for n, r in tried if isinstance(r, CalibrationResult)]
    if not results:
        reasons = "; ".join(f"{n}: {r}" for n, r in tried)
        raise CalibrationError(f"no method calibrated this pair ({reasons})")
    scores = [overlap(ref, tgt, r.transform, AGREEMENT_DISTANCE) for _, r in results]
    # Within AUTO_TIE of the best, the earlier (more specific) method wins: a 25 cm agreement
    # cannot tell a corner calibration from a whole-scene one that is 0.2 deg different.
    best = max(scores)
    return next(r for (_, r), s in zip(results, scores, strict=True) if s >= best - AUTO_TIE)


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
    #: Targets no calibration connects to the reference (only with ``require_all=False``).
    unconnected: list[str] = field(default_factory=list)


def _edge_error(a_from_b: F64Array, ref_from_a: F64Array, ref_from_b: F64Array) -> F64Array:
    """Tangent of the disagreement between a measured edge and the rig's poses."""
    predicted = np.linalg.inv(ref_from_a) @ ref_from_b
    return np.asarray(se3_log(np.linalg.inv(a_from_b) @ predicted), dtype=np.float64)


def _refine_graph(
    poses: dict[str, F64Array],
    edges: Sequence[tuple[str, str, F64Array, F64Array]],
    iterations: int = 20,
) -> dict[str, F64Array]:
    """Gauss-Newton on the pose graph: the reference is fixed at the identity; each edge
    ``(a, b, a_from_b, information)`` contributes ``e^T W e`` with ``e`` its tangent error."""
    names = [n for n in poses if n != "reference"]
    if not names:
        return dict(poses)
    current = {n: p.copy() for n, p in poses.items()}
    h = 1e-6
    for _ in range(iterations):
        size = 6 * len(names)
        hessian = np.zeros((size, size))
        gradient = np.zeros(size)
        for a, b, z, w in edges:
            e0 = _edge_error(z, current[a], current[b])
            jac = np.zeros((6, size))
            for k, name in enumerate(names):
                if name not in (a, b):
                    continue
                for d in range(6):
                    delta = np.zeros(6)
                    delta[d] = h
                    moved = dict(current)
                    moved[name] = se3_exp(delta) @ current[name]
                    e1 = _edge_error(z, moved[a], moved[b])
                    jac[:, 6 * k + d] = (e1 - e0) / h
            hessian += jac.T @ w @ jac
            gradient += jac.T @ w @ e0
        step = -np.linalg.solve(hessian + 1e-9 * np.eye(size), gradient)
        for k, name in enumerate(names):
            current[name] = se3_exp(step[6 * k : 6 * k + 6]) @ current[name]
        if np.linalg.norm(step) < 1e-10:
            break
    return current


def _information(result: CalibrationResult) -> F64Array:
    """Edge weight: the inverse covariance when the method gives one, else 1 cm / 0.1 deg."""
    default = np.diag([1e4] * 3 + [1.0 / np.radians(0.1) ** 2] * 3)
    cov = result.covariance
    if cov is None or not np.all(np.isfinite(cov)):
        return default
    # Floor the variances (1 mm, 0.01 deg): a covariance from thousands of points is optimistic.
    floor = np.diag([1e-6] * 3 + [np.radians(0.01) ** 2] * 3)
    return np.asarray(np.linalg.inv(cov + floor), dtype=np.float64)


def calibrate_rig(
    reference: npt.ArrayLike,
    targets: Mapping[str, npt.ArrayLike] | Sequence[npt.ArrayLike],
    *,
    method: Method = "auto",
    pairwise: bool = True,
    require_all: bool = True,
    seed: int = 0,
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
    ``unconnected`` (with its reasons in ``failures``).
    """
    ref = _cloud(reference, "reference")
    if isinstance(targets, Mapping):
        clouds = {str(k): _cloud(v, str(k)) for k, v in targets.items()}
    else:
        clouds = {f"target{i}": _cloud(v, f"target{i}") for i, v in enumerate(targets)}
    if not clouds:
        raise ValueError("targets is empty")
    if "reference" in clouds:
        raise ValueError("'reference' is reserved for the reference sensor; rename that target")
    measured: list[tuple[str, str, CalibrationResult]] = []
    failures: dict[tuple[str, str], str] = {}
    direct: dict[str, F64Array] = {}
    for name, cloud in clouds.items():
        try:
            r = calibrate(ref, cloud, method, seed=seed)
            measured.append(("reference", name, r))
            direct[name] = r.transform
        except CalibrationError as e:
            failures[("reference", name)] = str(e)
    names = list(clouds)
    if pairwise:
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                try:
                    r = calibrate(clouds[a], clouds[b], method, seed=seed)
                except CalibrationError as e:
                    failures[(a, b)] = str(e)
                    continue
                if (
                    overlap(clouds[a], clouds[b], r.transform, AGREEMENT_DISTANCE)
                    < MIN_PAIR_OVERLAP
                ):
                    failures[(a, b)] = "the two units barely overlap under the result"
                    continue
                measured.append((a, b, r))
    # Initial poses: breadth-first from the reference over the measured edges.
    poses: dict[str, F64Array] = {"reference": np.eye(4)}
    changed = True
    while changed:
        changed = False
        for a, b, r in measured:
            if a in poses and b not in poses:
                poses[b] = poses[a] @ r.transform
                changed = True
            elif b in poses and a not in poses:
                poses[a] = poses[b] @ np.linalg.inv(r.transform)
                changed = True
    missing = [n for n in names if n not in poses]
    if missing and (require_all or len(poses) == 1):
        reasons = "; ".join(f"{a}->{b}: {m}" for (a, b), m in failures.items())
        raise CalibrationError(
            f"could not connect {', '.join(missing)} to the reference ({reasons})"
        )
    # Edges between targets that nothing connects to the reference cannot be placed.
    measured = [(a, b, r) for a, b, r in measured if a in poses and b in poses]
    graph = [(a, b, r.transform, _information(r)) for a, b, r in measured]
    refined = _refine_graph(poses, graph)
    edges = []
    for a, b, r in measured:
        err = _edge_error(r.transform, refined[a], refined[b])
        edges.append(
            RigEdge(
                a=a,
                b=b,
                method=r.method,
                a_from_b=r.transform,
                rotation_residual_deg=float(np.degrees(np.linalg.norm(err[3:]))),
                translation_residual_m=float(np.linalg.norm(err[:3])),
            )
        )
    return RigCalibration(
        transforms={n: refined[n] for n in names if n in refined},
        direct=direct,
        edges=edges,
        failures=failures,
        unconnected=missing,
    )
