"""Pictures of a calibration (needs matplotlib: ``pip install lidarcal[plot]``).

:func:`overlay` draws both clouds in the reference frame before (target taken as it is, or at an
initial guess) and after calibration, from the top and from the side, the reference in blue and the
target in orange; the planes or poles the method matched are highlighted; a histogram shows the
target's residuals against the matched reference planes (or pole surfaces) after calibration.

:func:`trajectories` draws a calibration from a drive (:class:`~lidarcal.SequenceResult`): both
sensors' paths from the top, the target's mapped into the reference's world by the result.

>>> import numpy as np, lidarcal
>>> from lidarcal import sim
>>> from lidarcal.plot import overlay
>>> scene = sim.corner_scene("vlp16", seed=0)
>>> result = lidarcal.calibrate_planes(scene.reference, scene.target, up=[0, 0, 1])
>>> figure = overlay(scene.reference, scene.target, result)
>>> len(figure.axes)
6
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import CalibrationResult, PoleDetails, SequenceResult
from lidarcal.export import rpy

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

F64Array = npt.NDArray[np.float64]

REFERENCE_COLOUR = "#1f77b4"
TARGET_COLOUR = "#ff7f0e"
HIGHLIGHTS = ["#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22"]
MAX_POINTS = 40_000

__all__ = ["overlay", "residuals", "target_in_reference_world", "trajectories"]


def _figure_class() -> Any:
    # The object-oriented API: no pyplot state, no backend switch in the caller's session.
    try:
        from matplotlib.figure import Figure
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("lidarcal.plot needs matplotlib: pip install 'lidarcal[plot]'") from e
    return Figure


def _xyz(points: npt.ArrayLike, name: str) -> F64Array:
    a = np.asarray(points, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 3 or len(a) == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) or (N, 4) array, got shape {a.shape}")
    return a[:, :3]


def _apply(transform: F64Array, points: F64Array) -> F64Array:
    out: F64Array = points @ transform[:3, :3].T + transform[:3, 3]
    return out


def residuals(
    reference: npt.ArrayLike, target: npt.ArrayLike, result: CalibrationResult
) -> F64Array:
    """Signed distances (m) of the target's matched points, mapped by ``result.transform``, to
    the matched reference planes; for poles, distances to the pole surfaces (axis distance minus
    radius). Empty when the method reports neither."""
    tgt = _xyz(target, "target")
    _xyz(reference, "reference")
    moved = _apply(np.asarray(result.transform), tgt)
    details = result.details
    features = (
        details.poles_reference if isinstance(details, PoleDetails) else details.planes_reference
    )
    out: list[F64Array] = []
    for k, idx in enumerate(result.inliers_target):
        pts = moved[np.asarray(idx, dtype=np.int64)]
        if isinstance(details, PoleDetails):
            p, u = features[k, :3], features[k, 3:] / np.linalg.norm(features[k, 3:])
            rel = pts - p
            out.append(np.linalg.norm(rel - np.outer(rel @ u, u), axis=1) - details.radii[k])
        else:
            out.append(pts @ features[k, :3] + features[k, 3])
    return np.concatenate(out) if out else np.zeros(0)


def _subsample(n: int, rng: np.random.Generator) -> npt.NDArray[np.int64]:
    if n <= MAX_POINTS:
        return np.arange(n)
    return np.sort(rng.choice(n, MAX_POINTS, replace=False))


def _around(
    points: F64Array, targets: list[F64Array], margin: float = 5.0
) -> npt.NDArray[np.bool_]:
    """Which ``points`` lie in the box spanning the targets' 1-99 % extent plus ``margin``."""
    both = np.concatenate(targets)
    lo = np.percentile(both, 1, axis=0) - margin
    hi = np.percentile(both, 99, axis=0) + margin
    inside: npt.NDArray[np.bool_] = np.all((points >= lo) & (points <= hi), axis=1)
    return inside


def _view(
    ax: Axes,
    ref: F64Array,
    tgt: F64Array,
    axes: tuple[int, int],
    title: str,
    highlights: list[tuple[F64Array, str]],
) -> None:
    i, j = axes
    ax.scatter(ref[:, i], ref[:, j], s=0.3, c=REFERENCE_COLOUR, alpha=0.5, linewidths=0)
    ax.scatter(tgt[:, i], tgt[:, j], s=0.3, c=TARGET_COLOUR, alpha=0.5, linewidths=0)
    for pts, colour in highlights:
        ax.scatter(pts[:, i], pts[:, j], s=1.2, c=colour, alpha=0.8, linewidths=0)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("xyz"[i] + " (m)")
    ax.set_ylabel("xyz"[j] + " (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, linewidth=0.3)


def overlay(
    reference: npt.ArrayLike,
    target: npt.ArrayLike,
    result: CalibrationResult | npt.ArrayLike,
    *,
    initial: npt.ArrayLike | None = None,
    path: str | Path | None = None,
    title: str | None = None,
    seed: int = 0,
) -> Figure:
    """Before/after top and side views and a residual histogram; returns the figure and writes
    it to ``path`` (PNG, 150 dpi) when given.

    ``result`` is a :class:`~lidarcal.CalibrationResult` or a bare 4x4 ``reference_from_target``
    (then nothing is highlighted and no histogram is drawn). ``initial`` is the transform of the
    "before" views (default: identity, the clouds as recorded). Clouds larger than 40,000 points
    are subsampled (seeded) for drawing.
    """
    figure_class = _figure_class()
    ref = _xyz(reference, "reference")
    tgt = _xyz(target, "target")
    calibration = result if isinstance(result, CalibrationResult) else None
    transform = np.asarray(
        calibration.transform if calibration is not None else result, dtype=np.float64
    )
    if transform.shape != (4, 4):
        raise ValueError(f"the transform must be 4x4, got shape {transform.shape}")
    before = np.eye(4) if initial is None else np.asarray(initial, dtype=np.float64)
    if before.shape != (4, 4):
        raise ValueError(f"initial must be 4x4, got shape {before.shape}")

    rng = np.random.default_rng(seed)
    ri, ti = _subsample(len(ref), rng), _subsample(len(tgt), rng)
    tgt_before = _apply(before, tgt)
    tgt_after = _apply(transform, tgt)

    highlights: list[tuple[F64Array, str]] = []
    if calibration is not None:
        for k, (a, b) in enumerate(
            zip(calibration.inliers_reference, calibration.inliers_target, strict=False)
        ):
            colour = HIGHLIGHTS[k % len(HIGHLIGHTS)]
            a_idx = np.asarray(a, dtype=np.int64)[:: max(1, len(a) // 5000)]
            b_idx = np.asarray(b, dtype=np.int64)[:: max(1, len(b) // 5000)]
            highlights.append((ref[a_idx], colour))
            highlights.append((tgt_after[b_idx], colour))

    fig: Figure = figure_class(figsize=(15, 9), layout="constrained")
    grid = fig.add_gridspec(2, 3)
    method = calibration.method if calibration is not None else "given transform"
    angles = np.degrees(rpy(transform[:3, :3]))
    pose = (
        f"t = [{', '.join(f'{v:+.3f}' for v in transform[:3, 3])}] m, "
        f"roll-pitch-yaw = [{', '.join(f'{v:+.2f}' for v in angles)}] deg"
    )
    fig.suptitle(
        f"{title or 'lidarcal'} ({method}): {pose}\nreference blue, target orange", fontsize=11
    )
    # A roof unit sees 100 m around while a side unit sees 20: show the reference only around
    # the target (its 1-99 % extent plus a margin), where the alignment can be judged.
    ref_before = ref[ri][_around(ref[ri], [tgt_before[ti], tgt_after[ti]])]
    ref_after = ref[ri][_around(ref[ri], [tgt_after[ti]])]
    _view(fig.add_subplot(grid[0, 0]), ref_before, tgt_before[ti], (0, 1), "before, top (x-y)", [])
    _view(fig.add_subplot(grid[1, 0]), ref_before, tgt_before[ti], (0, 2), "before, side (x-z)", [])
    _view(fig.add_subplot(grid[0, 1]), ref_after, tgt_after[ti], (0, 1), "after, top (x-y)", [])
    _view(fig.add_subplot(grid[1, 1]), ref_after, tgt_after[ti], (0, 2), "after, side (x-z)", [])
    ax = fig.add_subplot(grid[0, 2])
    if highlights:
        kind = "poles" if calibration is not None and calibration.method == "poles" else "planes"
        box = [tgt_after[ti]]
        _view(
            ax,
            ref_after[:: max(1, len(ref_after) // 10000)],
            tgt_after[ti[:: max(1, len(ti) // 10000)]],
            (0, 1),
            f"matched {kind} after calibration, one colour each",
            [(pts[_around(pts, box)], colour) for pts, colour in highlights],
        )
    else:
        ax.set_axis_off()
    ax = fig.add_subplot(grid[1, 2])
    res = residuals(ref, tgt, calibration) if calibration is not None else np.zeros(0)
    if len(res):
        limit = max(float(np.percentile(np.abs(res), 99)), 1e-3)
        ax.hist(np.clip(res, -limit, limit) * 100, bins=80, color=TARGET_COLOUR)
        rms = float(np.sqrt(np.mean(res**2)))
        ax.set_title(
            f"target residuals: RMS {rms * 100:.2f} cm, n = {len(res)}\n"
            f"(clipped at the 99th percentile, {limit * 100:.1f} cm)",
            fontsize=10,
        )
        ax.set_xlabel("signed distance to the matched reference feature (cm)")
        ax.set_ylabel("points")
    else:
        ax.set_axis_off()
        ax.set_title("no matched features to show residuals for", fontsize=10)
    if path is not None:
        fig.savefig(path, dpi=150)
    return fig


def target_in_reference_world(result: SequenceResult) -> tuple[F64Array, F64Array]:
    """The target's odometry carried into the reference's world by ``result.transform`` (``T``):
    ``(target, predicted)``, two ``(K, 4, 4)`` pose arrays. ``target[k]`` is the target sensor's
    pose, ``R0 T inv(G0) G_k`` with ``R`` the reference's and ``G`` the target's poses: it runs
    beside the reference's path, offset by the mounting. ``predicted[k] = target[k] inv(T)`` is
    where the target's motion puts the reference sensor: on a good calibration it lies on the
    reference's own path, and the gap between them is the two odometries' disagreement."""
    t = np.asarray(result.transform, dtype=np.float64)
    ref = np.asarray(result.reference_poses, dtype=np.float64)
    tgt = np.asarray(result.target_poses, dtype=np.float64)
    world = ref[0] @ t @ np.linalg.inv(tgt[0])
    target: F64Array = world @ tgt
    predicted: F64Array = target @ np.linalg.inv(t)
    return target, predicted


def trajectories(
    result: SequenceResult,
    *,
    times: npt.ArrayLike | None = None,
    path: str | Path | None = None,
    title: str | None = None,
) -> Figure:
    """A calibration from a drive: both sensors' paths from the top (x-y of the reference's
    world, its first frame), the reference in blue, the target in orange (mapped by
    :func:`target_in_reference_world`, offset by the mounting) and, dashed, the reference's path
    as the target's motion predicts it; beside it the gap between the reference's poses and that
    prediction, frame by frame (against ``times`` in seconds when given). Returns the figure and
    writes it to ``path`` (PNG, 150 dpi) when given."""
    figure_class = _figure_class()
    ref = np.asarray(result.reference_poses, dtype=np.float64)
    target, predicted = target_in_reference_world(result)
    x = np.arange(len(ref), dtype=np.float64) if times is None else np.asarray(times, np.float64)
    if x.shape != (len(ref),):
        raise ValueError(f"times must hold one time per frame ({len(ref)}), got shape {x.shape}")

    fig: Figure = figure_class(figsize=(14, 6), layout="constrained")
    grid = fig.add_gridspec(1, 3)
    transform = np.asarray(result.transform, dtype=np.float64)
    angles = np.degrees(rpy(transform[:3, :3]))
    pose = (
        f"t = [{', '.join(f'{v:+.3f}' for v in transform[:3, 3])}] m, "
        f"roll-pitch-yaw = [{', '.join(f'{v:+.2f}' for v in angles)}] deg"
    )
    fig.suptitle(
        f"{title or 'lidarcal'} (sequence, {len(ref)} frames, {result.distance:.0f} m): {pose}\n"
        f"map fitness {100 * result.fitness:.0f} %, rmse {100 * result.rmse:.1f} cm",
        fontsize=11,
    )
    ax = fig.add_subplot(grid[0, :2])
    ax.plot(ref[:, 0, 3], ref[:, 1, 3], color=REFERENCE_COLOUR, label="reference")
    ax.plot(target[:, 0, 3], target[:, 1, 3], color=TARGET_COLOUR, label="target")
    ax.plot(
        predicted[:, 0, 3],
        predicted[:, 1, 3],
        color=TARGET_COLOUR,
        linestyle="--",
        linewidth=0.8,
        label="reference, from the target's motion",
    )
    ax.scatter(ref[:1, 0, 3], ref[:1, 1, 3], c="k", s=12, zorder=3, label="start")
    ax.set_title("trajectories, top (x-y of the reference's first frame)", fontsize=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, linewidth=0.3)
    ax.legend(fontsize=8, loc="best")
    ax = fig.add_subplot(grid[0, 2])
    gap = np.linalg.norm(ref[:, :3, 3] - predicted[:, :3, 3], axis=1)
    ax.plot(x, 100 * gap, color=TARGET_COLOUR)
    ax.set_title("reference path minus its prediction from the target", fontsize=10)
    ax.set_xlabel("time (s)" if times is not None else "frame")
    ax.set_ylabel("distance (cm)")
    ax.grid(True, linewidth=0.3)
    if path is not None:
        fig.savefig(path, dpi=150)
    return fig
