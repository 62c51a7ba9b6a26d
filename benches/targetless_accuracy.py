"""Must-show numbers of the targetless method (issue 8) on the real road data.

Run from the repository root after installing the wheel:
    python benches/targetless_accuracy.py [path/to/shared/eval_data/SensorsCalibration]

Prints, for every real_world scene, left->top and right->top against the reference (rotation
error = angle of R_true R^T, translation error = |t_true - t|), the spread of our own results
across the three scenes, the four hesai QT units against the P64 (weaker reference), and what
calibrate_rig (pairwise edges and the pose graph) makes of each real_world scene and of hesai,
and two held-out real pairs never used to tune the method (small_gicp, the RS-16 corner).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

import lidarcal

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "eval_data" / "SensorsCalibration"

#: The RS-16 corner's reference (data -> ref), from its README (eps_opt.csv).
RS16_REFERENCE = np.array(
    [
        [0.997512, -0.067092, -0.011511, 0.269294],
        [0.066503, 0.996650, -0.042584, 0.007977],
        [0.014533, 0.041649, 0.998956, -1.299193],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def held_out(eval_data: Path) -> None:
    """Real pairs the targetless method was never tuned on."""
    print()
    print("Held out (never used for tuning): targetless and auto against the reference")
    print("| pair | method | rot err (deg) | trans err (m) | time (s) | notes |")
    print("|---|---|---|---|---|---|")
    g = eval_data / "small_gicp"
    source = np.load(g / "source.npy")[:, :3].astype(np.float64)
    target = np.load(g / "target.npy")[:, :3].astype(np.float64)
    source = source[np.linalg.norm(source, axis=1) > 0.5]  # invalid returns at the origin
    target = target[np.linalg.norm(target, axis=1) > 0.5]
    a = eval_data / "lidar_appearance_calibration"
    pairs = [
        ("small_gicp (HDL-32E, two sweeps)", target, source, np.loadtxt(g / "T_target_source.txt")),
        (
            "RS-16 corner (top <- front)",
            np.load(a / "ref_filter.npy").astype(np.float64),
            np.load(a / "data_filter.npy").astype(np.float64),
            RS16_REFERENCE,
        ),
    ]
    for name, reference, tgt, truth in pairs:
        est, note, dt = run(reference, tgt)
        if est is None:
            print(f"| {name} | targetless | - | - | {dt:.2f} | {note} |")
        else:
            a_err, t_err = errors(truth, est)
            print(f"| {name} | targetless | {a_err:.3f} | {t_err:.3f} | {dt:.2f} | {note} |")
        t0 = time.perf_counter()
        auto = lidarcal.calibrate(reference, tgt)
        a_err, t_err = errors(truth, auto.transform)
        print(
            f"| {name} | auto ({auto.method}) | {a_err:.3f} | {t_err:.3f} | "
            f"{time.perf_counter() - t0:.2f} | |"
        )


def errors(truth: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    r = truth[:3, :3] @ est[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))
    return angle, float(np.linalg.norm(truth[:3, 3] - est[:3, 3]))


def run(reference: np.ndarray, target: np.ndarray) -> tuple[np.ndarray | None, str, float]:
    t0 = time.perf_counter()
    try:
        r = lidarcal.calibrate_targetless(reference, target)
        d = r.details
        assert isinstance(d, lidarcal.TargetlessDetails)
        note = (
            f"planes={len(d.planes_reference)} best={d.best_score:.3f} "
            f"second={d.second_score:.3f} weakest={d.weakest_translation[1]:.3f} "
            f"{r.timings['total']:.0f}ms"
        )
        return r.transform, note, time.perf_counter() - t0
    except lidarcal.CalibrationError as e:
        return None, f"refused: {e}", time.perf_counter() - t0


def main() -> None:
    base = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    refs = json.loads((base / "reference_extrinsics.json").read_text())
    print("| scene | pair | rot err (deg) | trans err (m) | time (s) | notes |")
    print("|---|---|---|---|---|---|")
    ours: dict[str, list[np.ndarray]] = {"left": [], "right": []}
    for scene in sorted(refs["real_world"]):
        d = base / "real_world" / scene
        top = np.load(d / "top.npy")[:, :3]
        for side in ("left", "right"):
            truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
            est, note, dt = run(top, np.load(d / f"{side}.npy")[:, :3])
            if est is None:
                print(f"| {scene} | {side}->top | - | - | {dt:.2f} | {note} |")
                continue
            ours[side].append(est)
            a, t = errors(truth, est)
            print(f"| {scene} | {side}->top | {a:.3f} | {t:.3f} | {dt:.2f} | {note} |")
    print()
    print("Spread of our results across the scenes (max pairwise difference):")
    for side, poses in ours.items():
        if len(poses) < 2:
            print(f"  {side}: fewer than two results")
            continue
        diffs = [errors(a, b) for i, a in enumerate(poses) for b in poses[i + 1 :]]
        print(
            f"  {side}: {max(d[0] for d in diffs):.3f} deg, {max(d[1] for d in diffs):.3f} m "
            f"({len(poses)} results)"
        )
    print()
    h = base / "hesai_scene1"
    p64 = np.load(h / "p64.npy")[:, :3]
    print("| hesai QT | rot err (deg) | trans err (m) | time (s) | notes |")
    print("|---|---|---|---|---|")
    for qt in ("qt_201", "qt_202", "qt_203", "qt_204"):
        truth = np.array(refs["hesai_scene1"][f"{qt}_to_p64"]["matrix_4x4"])
        est, note, dt = run(p64, np.load(h / f"{qt}.npy")[:, :3])
        if est is None:
            print(f"| {qt} | - | - | {dt:.2f} | {note} |")
            continue
        a, t = errors(truth, est)
        print(f"| {qt} | {a:.3f} | {t:.3f} | {dt:.2f} | {note} |")
    print()
    print("calibrate_rig(method='targetless', require_all=False): pose-graph result vs reference")
    print("| rig | target | rot err (deg) | trans err (m) | kept edges |")
    print("|---|---|---|---|---|")
    rigs: list[tuple[str, np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]] = []
    for scene in sorted(refs["real_world"]):
        d = base / "real_world" / scene
        rigs.append(
            (
                scene,
                np.load(d / "top.npy")[:, :3],
                {side: np.load(d / f"{side}.npy")[:, :3] for side in ("left", "right")},
                {
                    side: np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
                    for side in ("left", "right")
                },
            )
        )
    qts = ("qt_201", "qt_202", "qt_203", "qt_204")
    rigs.append(
        (
            "hesai_scene1",
            p64,
            {qt: np.load(h / f"{qt}.npy")[:, :3] for qt in qts},
            {qt: np.array(refs["hesai_scene1"][f"{qt}_to_p64"]["matrix_4x4"]) for qt in qts},
        )
    )
    for name, reference, targets, truths in rigs:
        rig = lidarcal.calibrate_rig(reference, targets, method="targetless", require_all=False)
        edges = ", ".join(f"{e.a}-{e.b}" for e in rig.edges)
        for target, truth in truths.items():
            if target not in rig.transforms:
                print(f"| {name} | {target} | - | - | unconnected |")
                continue
            a, t = errors(truth, rig.transforms[target])
            print(f"| {name} | {target} | {a:.3f} | {t:.3f} | {edges} |")
    held_out(base.parent)


if __name__ == "__main__":
    main()
