"""Peak memory of calibrating two 1M-point clouds, against the size of the input.

Usage: python benches/memory.py [--points 1000000] [--method planes|poles|both]

A first subprocess simulates a corner scene (and a pole scene) with a dense custom beam model and
saves two (N, 3) float64 clouds of exactly N points to .npy files; a second loads them and measures
its resident set before and after the calibration: the peak the calibration adds (ru_maxrss after
minus the RSS before) is reported against the input size (two float64 (N, 3) arrays, or (N, 4) for
poles). Linux only (ru_maxrss in KiB, /proc/self/statm).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile

MAKE = r"""
import sys, numpy as np
from lidarcal import sim
n, out = int(sys.argv[1]), sys.argv[2]
model = sim.BeamModel.custom(np.linspace(-35.0, 20.0, 400), columns=6000, range_noise=0.01)
c = sim.corner_scene(model, seed=1, wall_angle_deg=75)
p = sim.poles_scene(model, seed=1)
def exactly(a, n):
    # Evenly strided rows; a scan with fewer than n points repeats some (duplicates are harmless).
    return np.ascontiguousarray(a[np.linspace(0, len(a) - 1, n).astype(int)])
np.save(out + "/c_ref.npy", exactly(c.reference[:, :3], n))
np.save(out + "/c_tgt.npy", exactly(c.target[:, :3], n))
np.save(out + "/p_ref.npy", exactly(p.reference[:, :4], n))
np.save(out + "/p_tgt.npy", exactly(p.target[:, :4], n))
print(len(c.reference), len(c.target), len(p.reference), len(p.target))
"""

MEASURE = r"""
import json, os, resource, sys, time
import numpy as np, lidarcal
method, d = sys.argv[1], sys.argv[2]
page = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page
prefix = "c" if method == "planes" else "p"
ref, tgt = np.load(d + f"/{prefix}_ref.npy"), np.load(d + f"/{prefix}_tgt.npy")
# Warm up the extension (imports, thread pool) on a small call so that it does not count.
try:
    lidarcal.kabsch(np.eye(3), np.eye(3))
    lidarcal.ransac_plane(ref[::100, :3], 0.05)
except ValueError:
    pass
before = rss()
t = time.perf_counter()
if method == "planes":
    r = lidarcal.calibrate_planes(ref, tgt)
else:
    r = lidarcal.calibrate_poles(ref, tgt)
elapsed = time.perf_counter() - t
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
json.dump({"input": ref.nbytes + tgt.nbytes, "before": before, "peak": peak,
           "added": peak - before, "seconds": elapsed, "points": len(ref)}, sys.stdout)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--method", choices=["planes", "poles", "both"], default="both")
    args = parser.parse_args()
    methods = ["planes", "poles"] if args.method == "both" else [args.method]
    with tempfile.TemporaryDirectory() as d:
        made = subprocess.run(
            [sys.executable, "-c", MAKE, str(args.points), d],
            check=True,
            capture_output=True,
            text=True,
        )
        print(f"simulated scans (points before resampling): {made.stdout.strip()}")
        print("| method | points per cloud | input (MB) | RSS before (MB) | peak added (MB) | "
              "added / input | time (s) |")  # fmt: skip
        print("|---|---|---|---|---|---|---|")
        for method in methods:
            done = subprocess.run(
                [sys.executable, "-c", MEASURE, method, d], capture_output=True, text=True
            )
            if done.returncode != 0:
                print(f"| {method} | failed: {done.stderr.strip().splitlines()[-1]} |")
                continue
            r = json.loads(done.stdout)
            mb = 1 / 2**20
            print(
                f"| {method} | {r['points']:,} | {r['input'] * mb:.1f} | {r['before'] * mb:.1f} | "
                f"{r['added'] * mb:.1f} | {r['added'] / r['input']:.2f}x | {r['seconds']:.2f} |"
            )


if __name__ == "__main__":
    main()
