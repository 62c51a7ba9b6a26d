"""Wall time of the targetless method on the real pairs, for comparing two builds.

Usage (from the repository root, with the wheel of the build under test installed):

    python benches/targetless_time.py [--repeats 5] [--eval-data PATH]

Times ``calibrate(method="targetless")`` on the six road pairs of SensorsCalibration (left->top
and right->top of each scene) and the hesai units qt_201 and qt_204 against the P64. Prints
each pair's median over ``--repeats`` runs and their sum. A machine shared with other work moves
these figures by 10-15 %: compare two builds by running this script for each in turn, several
times, alternating (two virtual environments, or reinstalling the wheel in between).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import lidarcal

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "eval_data" / "SensorsCalibration"


def pairs(base: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, reference, target) of the road pairs and two hesai units."""
    out = []
    for scene in sorted((base / "real_world").iterdir()):
        if not (scene / "top.npy").exists():
            continue
        top = np.load(scene / "top.npy")[:, :3].astype(np.float64)
        for side in ("left", "right"):
            target = np.load(scene / f"{side}.npy")[:, :3].astype(np.float64)
            out.append((f"{scene.name} {side}->top", top, target))
    hesai = base / "hesai_scene1"
    p64 = np.load(hesai / "p64.npy")[:, :3].astype(np.float64)
    for qt in ("qt_201", "qt_204"):
        target = np.load(hesai / f"{qt}.npy")[:, :3].astype(np.float64)
        out.append((f"hesai {qt}->p64", p64, target))
    return out


def median_ms(reference: np.ndarray, target: np.ndarray, repeats: int) -> float:
    """Median wall time (ms) of the targetless method on one pair (refusals timed too)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        try:
            lidarcal.calibrate(reference, target, method="targetless")
        except lidarcal.CalibrationError:
            pass
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--eval-data", type=Path, default=DEFAULT, help="SensorsCalibration folder")
    args = p.parse_args()
    total = 0.0
    print("| pair | targetless (ms, median) |")
    print("|---|---|")
    for name, reference, target in pairs(args.eval_data):
        ms = median_ms(reference, target, args.repeats)
        total += ms
        print(f"| {name} | {ms:.0f} |")
    print(f"| **sum** | **{total:.0f}** |")


if __name__ == "__main__":
    main()
