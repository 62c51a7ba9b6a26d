"""The targetless method on simulated streets with exact ground truth: how many pairs it solves,
refuses, or gets wrong, and the worst error of the ones it accepts.

Run from the repository root after installing the wheel:
    python benches/targetless_sim.py [--seeds 8] [--challenger-range 2.0]

Every street seed (left and right side unit) is calibrated with the side unit moved along the
vehicle by each offset (0 = beside the roof unit, -3 = at the back of a car), once with the
default planes per cloud and once with two (road and one facade: every hypothesis is a pair,
whose translation along the street comes from the slide and ICP alone). A result counts as
solved within 0.1 deg / 2 cm of the truth; any other accepted result is "wrong" (the method
must refuse rather than return it).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import lidarcal
from lidarcal import sim

OFFSETS = (0.0, -1.0, 1.0, -2.0, 2.0, -3.0, 3.0, -4.0, 4.0)


def errors(truth: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    r = truth[:3, :3] @ est[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))
    return angle, float(np.linalg.norm(truth[:3, 3] - est[:3, 3]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument(
        "--challenger-range",
        type=float,
        default=2.0,
        help="calibrate_targetless's challenger_range (1.0 trusts max_translation)",
    )
    args = parser.parse_args()
    print(
        "| planes per cloud | offset (m) | solved | refused | wrong | worst accepted "
        "| median time |"
    )
    print("|---|---|---|---|---|---|---|")
    totals = [0, 0, 0]
    for max_planes in (10, 2):
        for offset in OFFSETS:
            solved = refused = 0
            wrong: list[str] = []
            worst = (0.0, 0.0)
            times: list[float] = []
            for seed in range(args.seeds):
                for side in ("left", "right"):
                    scene = sim.street_scene(seed=seed, side=side, target_offset=offset)
                    t0 = time.perf_counter()
                    try:
                        r = lidarcal.calibrate_targetless(
                            scene.reference,
                            scene.target,
                            max_planes=max_planes,
                            challenger_range=args.challenger_range,
                        )
                    except lidarcal.CalibrationError:
                        refused += 1
                        continue
                    finally:
                        times.append(time.perf_counter() - t0)
                    a, t = errors(scene.reference_from_target, r.transform)
                    if a < 0.1 and t < 0.02:
                        solved += 1
                        worst = (max(worst[0], a), max(worst[1], t))
                    else:
                        wrong.append(f"{seed}/{side}: {a:.2f} deg {t:.2f} m")
            totals = [totals[0] + solved, totals[1] + refused, totals[2] + len(wrong)]
            print(
                f"| {max_planes} | {offset:+.0f} | {solved} | {refused} | {len(wrong)} "
                f"{'(' + '; '.join(wrong) + ')' if wrong else ''}| "
                f"{worst[0]:.3f} deg / {1000 * worst[1]:.1f} mm | {np.median(times):.2f} s |"
            )
    print(f"\nAll: {totals[0]} solved, {totals[1]} refused, {totals[2]} wrong")


if __name__ == "__main__":
    main()
