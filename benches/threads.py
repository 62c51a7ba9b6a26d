"""Eight Python threads calibrating eight different scenes against the same eight in a loop.

Usage: python benches/threads.py [--model hdl64] [--repeats 3]

The calibrations release the GIL, so threads overlap; each calibration also uses rayon inside,
so the gain over serial depends on how much of a single calibration is already parallel and on
the core count (printed). Results must be identical either way (checked here, and in
tests/python/test_properties.py). Best of `repeats` wall times.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import lidarcal
from lidarcal import sim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--model", default="hdl64")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenes = [sim.corner_scene(args.model, seed=s, wall_angle_deg=70 + s) for s in range(8)]

    def calibrate(i: int) -> np.ndarray:
        s = scenes[i]
        return lidarcal.calibrate_planes(s.reference, s.target, seed=i).transform

    serial_t, threaded_t = [], []
    for _ in range(args.repeats):
        t = time.perf_counter()
        serial = [calibrate(i) for i in range(8)]
        serial_t.append(time.perf_counter() - t)
        t = time.perf_counter()
        with ThreadPoolExecutor(max_workers=8) as pool:
            threaded = list(pool.map(calibrate, range(8)))
        threaded_t.append(time.perf_counter() - t)
        assert all(np.array_equal(a, b) for a, b in zip(serial, threaded, strict=True))
    s, p = min(serial_t), min(threaded_t)
    # Direct evidence that the GIL is released: a pure-Python counter thread keeps counting while
    # the main thread is inside a calibration; with the GIL held it would stall for the whole call.
    stop = threading.Event()
    ticks = [0]

    def count() -> None:
        while not stop.is_set():
            ticks[0] += 1

    counter = threading.Thread(target=count)
    counter.start()
    time.sleep(0.05)
    before, t = ticks[0], time.perf_counter()
    for i in range(8):
        calibrate(i)
    during, busy = ticks[0] - before, time.perf_counter() - t
    before, t = ticks[0], time.perf_counter()
    time.sleep(busy)
    idle = ticks[0] - before
    stop.set()
    counter.join()
    points = sum(len(x.reference) + len(x.target) for x in scenes)
    print(f"cores: {os.cpu_count()}, RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', '-')}")
    print(f"8 {args.model} corner scenes, {points:,} points in all; identical results: yes")
    print("| run | wall time (s) |\n|---|---|")
    print(f"| serial loop | {s:.3f} |\n| 8 Python threads | {p:.3f} |")
    print(f"| speed-up (serial / threads) | {s / p:.2f}x |")
    print(
        f"GIL probe: a Python counter thread advanced {during:,} times during {busy:.3f} s of "
        f"calibrations and {idle:,} times during as long a sleep ({during / max(idle, 1):.0%})"
    )


if __name__ == "__main__":
    main()
