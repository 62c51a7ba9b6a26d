"""Accuracy of ``calibrate_planes`` against ground truth: the planar seed's synthetic protocol
(Sec. IV-B, both configurations of its Table II, alpha = 60..120 deg, 10 trials each) side by side
with the paper's Table II, and simulated VLP-16 corner scenes (plain, 180 deg yaw, clutter and an
extra wall, 30 deg tilt; 10 each).

Both sensors are taken as roughly upright (``up = +z``): that only breaks the tie between plane
correspondences of a corner whose angles are all 90 deg, as the paper itself assumes.

    python benches/planar_accuracy.py
"""

from __future__ import annotations

import numpy as np

import lidarcal
from lidarcal import sim

# Seed 000, Table II (bottom): (rotation error mean rad, translation error mean m) per alpha.
PAPER_TABLE_II = {
    1: {
        60: (0.0035, 0.0107),
        70: (0.0, 0.0001),
        80: (0.0024, 0.0045),
        90: (0.0016, 0.0100),
        100: (0.0051, 0.0087),
        110: (0.0043, 0.0097),
        120: (0.0018, 0.0083),
    },
    2: {
        60: (0.0096, 0.0260),
        70: (0.0036, 0.0101),
        80: (0.0021, 0.0039),
        90: (0.0033, 0.0052),
        100: (0.0126, 0.0245),
        110: (0.0029, 0.0084),
        120: (0.0097, 0.0217),
    },
}
UP = [0.0, 0.0, 1.0]

CORNER_CASES: dict[str, dict[str, float | int]] = {
    "plain": {"clutter_boxes": 0},
    "180 deg yaw": {"clutter_boxes": 0, "target_relative_yaw_deg": 180.0},
    "clutter + extra wall": {"clutter_boxes": 6, "extra_walls": 1},
    "tilted 30 deg": {"clutter_boxes": 0, "target_tilt_deg": 30.0},
}


def errors(truth: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    """Rotation error (angle of R_true R^T, rad) and translation error (m)."""
    d = truth[:3, :3] @ estimate[:3, :3].T
    skew = 0.5 * np.linalg.norm([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]])
    angle = float(np.arctan2(skew, 0.5 * (np.trace(d) - 1.0)))
    return angle, float(np.linalg.norm(truth[:3, 3] - estimate[:3, 3]))


def paper_protocol(trials: int = 10) -> list[dict[str, float]]:
    """One row per (configuration, alpha): mean errors over `trials`, and the paper's."""
    rows = []
    for configuration in (1, 2):
        for alpha in range(60, 121, 10):
            rot, trans = [], []
            for trial in range(trials):
                scene = sim.paper_scene(
                    alpha_deg=float(alpha), configuration=configuration, seed=trial
                )
                result = lidarcal.calibrate_planes(scene.reference, scene.target, up=UP)
                r, t = errors(scene.reference_from_target, result.transform)
                rot.append(r)
                trans.append(t)
            paper_rot, paper_trans = PAPER_TABLE_II[configuration][alpha]
            rows.append(
                {
                    "configuration": configuration,
                    "alpha": alpha,
                    "rotation": float(np.mean(rot)),
                    "translation": float(np.mean(trans)),
                    "paper_rotation": paper_rot,
                    "paper_translation": paper_trans,
                }
            )
    return rows


def corner_scenes(runs: int = 10) -> dict[str, list[tuple[float, float]]]:
    """Errors of every run of each VLP-16 corner case."""
    out: dict[str, list[tuple[float, float]]] = {}
    for name, options in CORNER_CASES.items():
        out[name] = []
        for seed in range(runs):
            scene = sim.corner_scene("vlp16", seed=seed, **options)  # type: ignore[arg-type]
            result = lidarcal.calibrate_planes(scene.reference, scene.target, up=UP)
            out[name].append(errors(scene.reference_from_target, result.transform))
    return out


def main() -> None:
    rows = paper_protocol()
    print(
        "| conf | alpha | rotation err (rad) lidarcal / paper "
        "| translation err (m) lidarcal / paper |"
    )
    print("|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['configuration']} | {r['alpha']} "
            f"| {r['rotation']:.4f} / {r['paper_rotation']:.4f} "
            f"| {r['translation']:.4f} / {r['paper_translation']:.4f} |"
        )
    mean_rot = np.mean([r["rotation"] for r in rows])
    mean_trans = np.mean([r["translation"] for r in rows])
    paper_rot = np.mean([r["paper_rotation"] for r in rows])
    paper_trans = np.mean([r["paper_translation"] for r in rows])
    print(f"| mean | | {mean_rot:.5f} / {paper_rot:.4f} | {mean_trans:.5f} / {paper_trans:.4f} |\n")
    print(
        "| VLP-16 corner scene (10 runs) | worst rotation err (mrad) | worst translation err (cm) |"
    )
    print("|---|---|---|")
    for name, errs in corner_scenes().items():
        worst_r = max(e[0] for e in errs)
        worst_t = max(e[1] for e in errs)
        print(f"| {name} | {1e3 * worst_r:.3f} | {1e2 * worst_t:.3f} |")


if __name__ == "__main__":
    main()
