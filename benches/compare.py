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

Part 3 (``--only real``) times ``lidarcal.calibrate`` (auto, no initial guess) against the
no-guess pipeline a Python user would assemble from PyPI today: KISS-Matcher (global
registration from FPFH features) followed by small_gicp's GICP, on the project's real pairs (the
six road pairs of SensorsCalibration, the four Hesai units and small_gicp's two sweeps). It prints
each pair's time and error for both, the method ``auto`` picked and that method's time alone.

Usage (set the thread count before the libraries start their pools):

    pip install -e ".[bench]"          # open3d, kiss-matcher, small-gicp
    python benches/compare.py --threads 1
    python benches/compare.py --threads 2
    python benches/compare.py --only real
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
        choices=["ransac", "pipeline", "real", "all"],
        default="all",
        help="ransac: plane extraction; pipeline: the whole planar calibration; "
        "real: auto against KISS-Matcher + small_gicp on the real pairs",
    )
    p.add_argument(
        "--eval-data",
        type=Path,
        default=Path(__file__).resolve().parents[2] / "shared" / "eval_data",
        help="folder with SensorsCalibration/ and small_gicp/ (for --only real)",
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from open3d_import import import_open3d  # noqa: E402

try:
    o3d = import_open3d()
except ImportError as e:  # pragma: no cover - the comparison needs it
    sys.exit(f"benches/compare.py needs Open3D: {e}")


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


def real_pairs(eval_data: Path) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """(name, reference, target, reference_from_target) of every real pair with a reference."""
    import json

    base = eval_data / "SensorsCalibration"
    refs = json.loads((base / "reference_extrinsics.json").read_text())
    pairs = []
    for scene in sorted(refs["real_world"]):
        d = base / "real_world" / scene
        top = np.load(d / "top.npy")[:, :3].astype(np.float64)
        for side in ("left", "right"):
            truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
            target = np.load(d / f"{side}.npy")[:, :3].astype(np.float64)
            pairs.append((f"{scene} {side}->top", top, target, truth))
    h = base / "hesai_scene1"
    p64 = np.load(h / "p64.npy")[:, :3].astype(np.float64)
    for qt in ("qt_201", "qt_202", "qt_203", "qt_204"):
        truth = np.array(refs["hesai_scene1"][f"{qt}_to_p64"]["matrix_4x4"])
        pairs.append((f"hesai {qt}->p64", p64, np.load(h / f"{qt}.npy")[:, :3], truth))
    g = eval_data / "small_gicp"
    source = np.load(g / "source.npy")[:, :3].astype(np.float64)
    target = np.load(g / "target.npy")[:, :3].astype(np.float64)
    source = source[np.linalg.norm(source, axis=1) > 0.5]  # invalid returns at the origin
    target = target[np.linalg.norm(target, axis=1) > 0.5]
    pairs.append(("small_gicp sweeps", target, source, np.loadtxt(g / "T_target_source.txt")))
    return [(n, np.ascontiguousarray(r), np.ascontiguousarray(t), T) for n, r, t, T in pairs]


def kiss_matcher_gicp(reference: np.ndarray, target: np.ndarray) -> np.ndarray:
    """KISS-Matcher's global registration refined by small_gicp GICP: reference_from_target."""
    import kiss_matcher
    import small_gicp

    matcher = kiss_matcher.KISSMatcher(kiss_matcher.KISSMatcherConfig(0.3))
    solution = matcher.estimate(target.astype(np.float32), reference.astype(np.float32))
    guess = np.eye(4)
    guess[:3, :3] = np.asarray(solution.rotation)
    guess[:3, 3] = np.asarray(solution.translation).ravel()
    result = small_gicp.align(
        reference,
        target,
        guess,
        registration_type="GICP",
        downsampling_resolution=0.25,
        max_correspondence_distance=1.0,
        num_threads=ARGS.threads,
    )
    return np.asarray(result.T_target_source)


def real_row(
    name: str, reference: np.ndarray, target: np.ndarray, truth: np.ndarray, repeats: int
) -> tuple[str, float, float, bool, bool]:
    """One pair: its table row, the speed-up, auto / picked, and whether each is within 0.5 deg /
    5 cm."""
    t_base, base = median_time(lambda: kiss_matcher_gicp(reference, target), repeats)
    t_auto, res = median_time(lambda: lidarcal.calibrate(reference, target), repeats)
    picked = getattr(lidarcal, f"calibrate_{res.method}")
    t_pick, _ = median_time(lambda: picked(reference, target), repeats)
    eb = rotation_translation_error(truth, base)
    el = rotation_translation_error(truth, res.transform)
    good_b = bool(np.degrees(eb[0]) <= 0.5 and eb[1] <= 0.05)
    good_l = bool(np.degrees(el[0]) <= 0.5 and el[1] <= 0.05)
    row = (
        f"| {name} | {len(reference) + len(target):,} | {t_base:.3f} "
        f"| {np.degrees(eb[0]):.2f}, {100 * eb[1]:.1f} | {t_auto:.3f} "
        f"| {np.degrees(el[0]):.2f}, {100 * el[1]:.1f} | {t_base / t_auto:.2f}x "
        f"| {res.method} | {t_pick:.3f} | {t_auto / t_pick:.2f} |"
    )
    return row, t_base / t_auto, t_auto / t_pick, good_b, good_l


def compare_real() -> None:
    """auto against KISS-Matcher + small_gicp on the real pairs, same clouds, one process."""
    try:
        import kiss_matcher  # noqa: F401
        import small_gicp  # noqa: F401
    except ImportError:
        sys.exit('--only real needs KISS-Matcher and small_gicp: pip install -e ".[bench]"')
    repeats = max(1, ARGS.repeats // 2)
    print(
        "\n| pair | points | KISS-Matcher + GICP (s) | error (deg, cm) | lidarcal auto (s) "
        "| error (deg, cm) | speed-up | picked | picked alone (s) | auto / picked |"
    )
    print("|" + "---|" * 10)
    ratios, overheads, ok_base, ok_ours = [], [], 0, 0
    for name, reference, target, truth in real_pairs(ARGS.eval_data):
        row, ratio, overhead, good_b, good_l = real_row(name, reference, target, truth, repeats)
        print(row)
        if name.startswith("small_gicp"):
            continue  # held out of the summary: not one of the ten road and Hesai pairs
        ratios.append(ratio)
        overheads.append(overhead)
        ok_base += good_b
        ok_ours += good_l
    n = len(ratios)
    print(
        f"\nthe {n} road and Hesai pairs: median speed-up {np.median(ratios):.2f}x, "
        f"auto / picked method median {np.median(overheads):.2f} (max {max(overheads):.2f}); "
        f"within 0.5 deg / 5 cm: KISS-Matcher + GICP {ok_base} of {n}, lidarcal {ok_ours} of {n}"
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
    if ARGS.only == "real":
        compare_real()
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
        compare_real()


if __name__ == "__main__":
    main()
