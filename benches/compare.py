"""Side-by-side timing of lidarcal's plane extraction against Open3D's chained segment_plane.

Part 2 (``--only pipeline``) times the whole planar calibration against the same method built
from Open3D ``segment_plane``, NumPy Kabsch and SciPy ``least_squares`` (the NumPy reference in
``tests/python/reference.py``), on the seed's 9.5k-point protocol scene and a 64-beam corner.

Both libraries run in this one process on the same clouds: a wall corner (three planes sampled
up to their intersection lines) with 20 % uniform clutter and 3 cm noise, for 10k, 100k and 1M
points. Open3D is chained as a user would: ``segment_plane`` with 1000 iterations, its inliers
removed, three times. lidarcal runs ``extract_planes`` (sequential RANSAC plus the joint
refinement) and, for the like-for-like figure, the sequential part alone. The script prints the
median times, their ratio, the worst normal error against the truth, and lidarcal's raw scoring
throughput in point-tests per second per core.

Usage (set the thread count before the libraries start their pools):

    pip install open3d
    python benches/compare.py --threads 1
    python benches/compare.py --threads 2
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def parse() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    p.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--threshold", type=float, default=0.09, help="inlier distance (3 sigma)")
    p.add_argument(
        "--only",
        choices=["ransac", "pipeline", "all"],
        default="all",
        help="ransac: plane extraction; pipeline: the whole planar calibration",
    )
    return p.parse_args()


ARGS = parse()
os.environ["RAYON_NUM_THREADS"] = str(ARGS.threads)
os.environ["OMP_NUM_THREADS"] = str(ARGS.threads)
# Open3D's OpenMP workers otherwise keep spinning after each call and steal the cores from the
# next measurement in this process.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np  # noqa: E402

import lidarcal  # noqa: E402
from lidarcal import _lidarcal  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "python"))
import reference as ref  # noqa: E402

try:
    import open3d as o3d
except ImportError:  # pragma: no cover - the comparison needs it
    sys.exit("benches/compare.py needs Open3D: pip install open3d")


def median_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    out = fn()  # warm-up (and the result we report)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def worst_normal_error(found: list[np.ndarray], truth: np.ndarray) -> float:
    errs = []
    for t in truth:
        errs.append(min(np.degrees(np.arccos(min(1.0, abs(float(f @ t[:3]))))) for f in found))
    return max(errs)


def open3d_chain(points: np.ndarray, threshold: float) -> list[np.ndarray]:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    normals = []
    for _ in range(3):
        model, inliers = pcd.segment_plane(
            distance_threshold=threshold, ransac_n=3, num_iterations=1000
        )
        n = np.asarray(model[:3], dtype=float)
        normals.append(n / np.linalg.norm(n))
        pcd = pcd.select_by_index(inliers, invert=True)
    return normals


def compare_size(n: int) -> str:
    """One table row: both libraries on the same n-point cloud."""
    clutter = n // 5
    rng = np.random.default_rng(n)
    points, truth = ref.corner_cloud(rng, (n - clutter) // 3, clutter, 0.03)
    repeats = ARGS.repeats if n < 1_000_000 else max(3, ARGS.repeats // 2)
    t = ARGS.threshold
    t_o3d, o3d_normals = median_time(lambda: open3d_chain(points, t), repeats)
    t_seq, _ = median_time(
        lambda: lidarcal.extract_planes(points, 3, t, refinement_rounds=0), repeats
    )
    t_joint, planes = median_time(lambda: lidarcal.extract_planes(points, 3, t), repeats)
    err_o3d = worst_normal_error(o3d_normals, truth)
    err_lc = worst_normal_error([p.normal for p in planes], truth)
    return (
        f"| {n:,} | {t_o3d * 1e3:.1f} | {t_seq * 1e3:.2f} | {t_o3d / t_seq:.1f}x "
        f"| {t_joint * 1e3:.2f} | {t_o3d / t_joint:.1f}x | {err_o3d:.3f} / {err_lc:.3f} |"
    )


def open3d_planes(points: np.ndarray, threshold: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Three planes by chained segment_plane, normals toward the sensor, with their inliers."""
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    index = np.arange(len(points))
    planes, inliers = [], []
    for _ in range(3):
        model, inl = pcd.segment_plane(
            distance_threshold=threshold, ransac_n=3, num_iterations=1000
        )
        coeffs = np.asarray(model, dtype=float)
        coeffs /= np.linalg.norm(coeffs[:3])
        if coeffs[3] < 0:
            coeffs = -coeffs
        planes.append(coeffs)
        inliers.append(points[index[inl]])
        keep = np.setdiff1d(np.arange(len(index)), inl)
        index = index[keep]
        pcd = pcd.select_by_index(inl, invert=True)
    return np.array(planes), inliers


def baseline_pipeline(reference: np.ndarray, target: np.ndarray, threshold: float) -> np.ndarray:
    """The same method from Open3D (planes), NumPy (Kabsch) and SciPy (least_squares)."""
    planes_ref, pts_ref = open3d_planes(reference, threshold)
    planes_tgt, pts_tgt = open3d_planes(target, threshold)
    _, refined, _ = ref.planar_pipeline(planes_ref, planes_tgt, pts_ref, pts_tgt)
    return refined


def rotation_translation_error(truth: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    return (
        ref.rotation_angle(truth[:3, :3] @ estimate[:3, :3].T),
        float(np.linalg.norm(truth[:3, 3] - estimate[:3, 3])),
    )


def compare_pipeline() -> None:
    """The whole planar calibration, lidarcal against Open3D + NumPy + SciPy, same clouds."""
    from lidarcal import sim

    scenes = [
        ("paper scene, alpha 100 (9.5k pts)", sim.paper_scene(alpha_deg=100.0, seed=0), 0.3),
        (
            "HDL-64 corner, walls 100 deg",
            sim.corner_scene("hdl64", seed=0, wall_angle_deg=100.0, clutter_boxes=4),
            0.05,
        ),
    ]
    print(
        "\n| scene | points | Open3D+NumPy+SciPy (ms) | lidarcal (ms) | ratio "
        "| lidarcal squared loss (ms) | ratio | errors baseline / lidarcal (mrad, mm) |"
    )
    print("|" + "---|" * 8)
    for name, scene, threshold in scenes:
        print(pipeline_row(name, scene, threshold))


def pipeline_row(name: str, scene: Any, threshold: float) -> str:
    """One row of the pipeline table: both pipelines on one scene."""
    reference = np.ascontiguousarray(scene.reference[:, :3])
    target = np.ascontiguousarray(scene.target[:, :3])
    truth = scene.reference_from_target
    repeats = max(3, ARGS.repeats // 2)
    t_base, base = median_time(lambda: baseline_pipeline(reference, target, threshold), repeats)
    t_lc, res = median_time(lambda: lidarcal.calibrate_planes(reference, target), ARGS.repeats)
    t_sq, _ = median_time(
        lambda: lidarcal.calibrate_planes(reference, target, loss="squared"), ARGS.repeats
    )
    eb = rotation_translation_error(truth, base)
    el = rotation_translation_error(truth, res.transform)
    return (
        f"| {name} | {len(reference) + len(target):,} | {t_base * 1e3:.1f} | {t_lc * 1e3:.2f} "
        f"| {t_base / t_lc:.0f}x | {t_sq * 1e3:.2f} | {t_base / t_sq:.0f}x "
        f"| {1e3 * eb[0]:.2f}, {1e3 * eb[1]:.1f} / {1e3 * el[0]:.2f}, {1e3 * el[1]:.1f} |"
    )


def main() -> None:
    o3d.utility.random.seed(0)
    print(
        f"threads={ARGS.threads}  lidarcal {lidarcal.__version__}  open3d {o3d.__version__}  "
        f"threshold={ARGS.threshold} m, noise 0.03 m, 20 % clutter"
    )
    if ARGS.only == "pipeline":
        compare_pipeline()
        return
    header = (
        "| points | Open3D 3x segment_plane (ms) | lidarcal sequential (ms) | ratio "
        "| lidarcal + joint refit (ms) | ratio | worst normal error Open3D / lidarcal (deg) |"
    )
    print(header)
    print("|" + "---|" * 7)
    for n in ARGS.sizes:
        print(compare_size(n))

    # Raw scoring throughput: 256 hypotheses over 1M points, per core.
    points, truth = ref.corner_cloud(np.random.default_rng(1), 266_667, 200_000, 0.03)
    rng = np.random.default_rng(2)
    hyps = np.vstack([truth + rng.normal(0, 0.05, truth.shape) for _ in range(86)])[:256]
    t, _ = median_time(lambda: _lidarcal.score_planes(points, hyps, ARGS.threshold), 5)
    rate = len(hyps) * len(points) / t
    print(
        f"\nscoring throughput (score_planes, 256 planes x {len(points):,} points, inlier counts"
        f" on, including the f32 copy): {rate:.3g} point-tests/s"
        f" = {rate / ARGS.threads:.3g} per core"
    )
    if ARGS.only == "all":
        compare_pipeline()


if __name__ == "__main__":
    main()
