"""Reading a 1M-point PCD: lidarcal against pypcd4 and Open3D, time and peak memory.

The file mimics the real recordings in ``shared/eval_data/SensorsCalibration/real_world``:
``FIELDS x y z intensity ring timestamp`` (F4 F4 F4 F4 U2 F8, 26 bytes a point), written as
``binary`` and as ``binary_compressed``. Each reader runs in its own fresh subprocess (so one
library's allocations cannot hide another's peak) and returns x, y, z and intensity as a NumPy
array, which is what a calibration needs:

* lidarcal: ``read_points(path)`` -> (N, 4) float64;
* pypcd4: ``PointCloud.from_path(path).numpy(("x", "y", "z", "intensity"))``;
* Open3D tensor API: ``o3d.t.io.read_point_cloud`` then positions and intensity to NumPy;
* Open3D legacy API: ``o3d.io.read_point_cloud`` then ``np.asarray(points)`` (x, y, z only:
  the legacy reader drops intensity).

Time is the median of ``--repeats`` reads after one warm-up read (the file is in the page
cache); peak memory is the peak resident set over the reads (``VmHWM`` after resetting it through
``/proc/self/clear_refs``, Linux) minus the resident set after importing the library. Times are
printed with their ratio to lidarcal's.

Usage:

    pip install pypcd4 open3d libusb-package
    python benches/io_compare.py [--points 1000000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = r"""
import gc, json, sys, time
import numpy as np
reader, path, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3])
if reader == "lidarcal":
    import lidarcal
    def read():
        return lidarcal.read_points(path)
elif reader == "pypcd4":
    from pypcd4 import PointCloud
    def read():
        return PointCloud.from_path(path).numpy(("x", "y", "z", "intensity"))
elif reader == "open3d-t":
    sys.path.insert(0, sys.argv[4])
    from open3d_import import import_open3d
    o3d = import_open3d()
    def read():
        pc = o3d.t.io.read_point_cloud(path)
        return np.column_stack([pc.point.positions.numpy(), pc.point.intensity.numpy()])
else:
    sys.path.insert(0, sys.argv[4])
    from open3d_import import import_open3d
    o3d = import_open3d()
    def read():
        return np.asarray(o3d.io.read_point_cloud(path).points)
def rss_kib(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1])
    raise RuntimeError(key)
gc.collect()
# ru_maxrss would carry the parent's high-water mark across fork+exec; reset the kernel's peak
# instead (Linux >= 4.0) and read VmHWM, the peak resident set since the reset.
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
base = rss_kib("VmRSS")
out = read()
shape = list(out.shape)
checksum = float(np.asarray(out, dtype=np.float64)[:, :3].sum())
del out
gc.collect()
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    out = read()
    times.append(time.perf_counter() - t0)
    del out
peak = rss_kib("VmHWM")
print(json.dumps({"median_s": sorted(times)[len(times) // 2], "peak_kib": peak - base,
                  "shape": shape, "checksum": checksum}))
"""

READERS = ["lidarcal", "pypcd4", "open3d-t", "open3d-legacy"]


def write_pcd(path: Path, n: int, compressed: bool, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    dtype = np.dtype(
        [
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("intensity", "<f4"),
            ("ring", "<u2"),
            ("timestamp", "<f8"),
        ]
    )
    rec = np.zeros(n, dtype=dtype)
    for name in ("x", "y", "z"):
        rec[name] = rng.uniform(-50, 50, n)
    rec["intensity"] = rng.integers(0, 256, n)
    rec["ring"] = np.arange(n) % 64
    rec["timestamp"] = 1.6449e9 + np.arange(n) * 1e-7
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        "FIELDS x y z intensity ring timestamp\nSIZE 4 4 4 4 2 8\nTYPE F F F F U F\n"
        f"COUNT 1 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
    )
    if not compressed:
        path.write_bytes((header + "DATA binary\n").encode() + rec.tobytes())
        return
    # binary_compressed needs an LZF encoder: lidarcal's writer, which stores every column as F4
    # (24 bytes a point instead of 26; the readers' work is the same).
    import lidarcal

    table = np.column_stack([rec[name].astype(np.float64) for name in dtype.names or ()])
    lidarcal.write_points(path, table, list(dtype.names or ()), pcd_format="binary_compressed")


def run(reader: str, path: Path, repeats: int) -> dict[str, float] | None:
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, reader, str(path), str(repeats), str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["failed"])[-1]
        print(f"  {reader}: {last}", file=sys.stderr)
        return None
    result: dict[str, float] = json.loads(proc.stdout)
    return result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--points", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for compressed in (False, True):
            kind = "binary_compressed" if compressed else "binary"
            path = Path(tmp) / f"cloud_{kind}.pcd"
            write_pcd(path, args.points, compressed)
            size_mb = path.stat().st_size / 1e6
            print(f"\n{args.points:,} points, DATA {kind}, file {size_mb:.1f} MB")
            print("| reader | output | median time (ms) | time / lidarcal | peak RSS growth (MB) |")
            print("|---|---|---|---|---|")
            base = None
            for reader in READERS:
                r = run(reader, path, args.repeats)
                if r is None:
                    continue
                if base is None:
                    base = r["median_s"]
                print(
                    f"| {reader} | {tuple(r['shape'])} | {r['median_s'] * 1e3:.1f} | "
                    f"{r['median_s'] / base:.2f} | {r['peak_kib'] / 1024:.1f} |"
                )


if __name__ == "__main__":
    main()
