"""Drift detection by ``lidarcal.check`` on the real pairs with their references.

Run from the repository root after installing the wheel:
    python benches/drift.py [--trials 20] [--eval-data ../shared/eval_data] [--seed 0]

For every real pair (the 6 road pairs, the 4 hesai QT units to the P64, small_gicp's two sweeps):
the verdict on the reference itself (it must be "consistent": no false alarm), then the share of
perturbations flagged "inconsistent" (or "unverifiable": either way the pose is not certified),
for rotations about random axes (through the target sensor) and translations in random directions
of several sizes, and the smallest size flagged in >= 95 % of the trials over all pairs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import lidarcal

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "eval_data"
ROTATIONS_DEG = (0.1, 0.2, 0.3, 0.5, 1.0)
TRANSLATIONS_M = (0.01, 0.02, 0.03, 0.05, 0.1)


def pairs(eval_data: Path) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """(name, reference, target, reference_from_target) of every real pair with a reference."""
    base = eval_data / "SensorsCalibration"
    refs = json.loads((base / "reference_extrinsics.json").read_text())
    out = []
    for scene in sorted(refs["real_world"]):
        d = base / "real_world" / scene
        top = np.load(d / "top.npy")[:, :3].astype(np.float64)
        for side in ("left", "right"):
            truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
            tgt = np.load(d / f"{side}.npy")[:, :3].astype(np.float64)
            out.append((f"{scene} {side}->top", top, tgt, truth))
    h = base / "hesai_scene1"
    p64 = np.load(h / "p64.npy")[:, :3].astype(np.float64)
    for qt in ("qt_201", "qt_202", "qt_203", "qt_204"):
        truth = np.array(refs["hesai_scene1"][f"{qt}_to_p64"]["matrix_4x4"])
        out.append(
            (f"hesai {qt}->p64", p64, np.load(h / f"{qt}.npy")[:, :3].astype(np.float64), truth)
        )
    g = eval_data / "small_gicp"
    source = np.load(g / "source.npy")[:, :3].astype(np.float64)
    target = np.load(g / "target.npy")[:, :3].astype(np.float64)
    source = source[np.linalg.norm(source, axis=1) > 0.5]  # invalid returns at the origin
    target = target[np.linalg.norm(target, axis=1) > 0.5]
    out.append(("small_gicp target<-source", target, source, np.loadtxt(g / "T_target_source.txt")))
    return out


def perturbation(rng: np.random.Generator, rotation_deg: float, translation_m: float) -> np.ndarray:
    """A 4x4 target-side perturbation: a rotation about a random axis, a random-direction shift."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    angle = np.radians(rotation_deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    p = np.eye(4)
    p[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    p[:3, 3] = direction * translation_m
    return p


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="perturbations per size and pair")
    parser.add_argument("--eval-data", type=Path, default=DEFAULT)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    sizes = [("rot", r, 0.0) for r in ROTATIONS_DEG] + [("trans", 0.0, t) for t in TRANSLATIONS_M]
    flagged: dict[tuple[str, float, float], list[bool]] = {s: [] for s in sizes}
    times: list[float] = []
    columns = ("pair", "verdict on the reference", "correction (deg / cm)", "detects (deg / cm)")
    print("| " + " | ".join(columns) + " | 1 deg flagged | 10 cm flagged |")
    print("|---|---|---|---|---|---|")
    false_alarms = 0
    all_pairs = pairs(args.eval_data)
    for name, reference, target, truth in all_pairs:
        t0 = time.perf_counter()
        report = lidarcal.check(reference, target, truth)
        times.append(time.perf_counter() - t0)
        false_alarms += report.verdict != "consistent"
        row: dict[tuple[str, float, float], list[bool]] = {}
        for size in sizes:
            _, rot, trans = size
            row[size] = []
            for _ in range(args.trials):
                perturbed = truth @ perturbation(rng, rot, trans)
                t0 = time.perf_counter()
                verdict = lidarcal.check(reference, target, perturbed).verdict
                times.append(time.perf_counter() - t0)
                row[size].append(verdict != "consistent")
            flagged[size].extend(row[size])
        print(
            f"| {name} | {report.verdict} | {report.correction_rotation_deg:.3f} / "
            f"{report.correction_translation_m * 100:.1f} | {report.detectable_rotation_deg:.2f} / "
            f"{report.detectable_translation_m * 100:.1f} | "
            f"{np.mean(row[('rot', 1.0, 0.0)]) * 100:.0f} % | "
            f"{np.mean(row[('trans', 0.0, 0.1)]) * 100:.0f} % |"
        )
        if report.verdict != "consistent":
            print(f"|   reason | {report.reason} | | | | |")
    print()
    print(f"False alarms on the references: {false_alarms} of {len(all_pairs)}")
    print("Share of perturbed poses flagged (not consistent), over all pairs:")
    print("| perturbation | flagged |")
    print("|---|---|")
    smallest = {"rot": None, "trans": None}
    for size in sizes:
        kind, rot, trans = size
        share = float(np.mean(flagged[size]))
        label = f"{rot:g} deg" if kind == "rot" else f"{trans * 100:g} cm"
        print(f"| {label} | {share * 100:.1f} % ({sum(flagged[size])} of {len(flagged[size])}) |")
        if share >= 0.95 and smallest[kind] is None:
            smallest[kind] = label
    print()
    print(f"Smallest rotation flagged in >= 95 %: {smallest['rot'] or 'none of those tried'}")
    print(f"Smallest translation flagged in >= 95 %: {smallest['trans'] or 'none of those tried'}")
    print(f"check runtime: median {np.median(times) * 1e3:.0f} ms over {len(times)} calls")


if __name__ == "__main__":
    main()
