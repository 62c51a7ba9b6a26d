"""Must-show numbers of `lidarcal batch` (issue 18): throughput with 1 and 2 workers, per-row cost,
a fleet-scale extrapolation on paper, and the client's memory on a 10,000-row manifest.

Run from the repository root after installing the wheel with the fleet extra:
    python benches/fleet.py [--vehicles 100] [--memory-rows 10000] [--skip-memory]

1. Throughput: a simulated fleet of ``--vehicles`` street-scene vehicles (roof HDL-64E + a side unit
   tilted 45 degrees, ~120k + 27k points, binary PCD), one calibration row and one monitoring row
   each (200 rows by default), run by a LocalCluster of 1 and then 2 one-thread workers (the
   default layout of `lidarcal batch`). The clusters are started and warmed up before the clock
   starts; their start-up is printed apart. Rows per second, the 2/1 ratio, and the per-row cost
   on the workers (``runtime_s``: reading both files plus the calibration or the check) against
   the wall time per row, whose difference is the scheduling and writing overhead. The workers'
   CPU seconds split the speed-up into the cores the machine gave them (on a shared machine, less
   than the worker count) and the CPU cost of a row (which must not grow with the workers).
2. The ceiling: ``--ceiling-rows`` rows that cost nothing (a missing file: an error row at once),
   2 workers: how many rows a second one client and its scheduler drive, and the client's memory.
   On paper: what the per-row cost and that ceiling mean for a day of a 1,000-vehicle fleet on a
   100-node cluster (the assumptions are options and are printed).
3. Memory: ``--memory-rows`` monitoring rows over 10 small simulated vehicles (VLP-16 corner
   scenes, so the run takes minutes, not hours), 2 workers, Parquet output. The client's resident
   memory is sampled as rows finish, and its peak (VmHWM, reset just before the run) is printed.

Timings depend on the machine's load: the script prints the load average next to each run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from lidarcal import batch, sim, write_points


def _status(field: str) -> float:
    """A field of /proc/self/status in MB (VmRSS, VmHWM)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _reset_peak() -> None:
    """Resets VmHWM to the current RSS (Linux >= 4.0), so the peak is the run's own."""
    Path("/proc/self/clear_refs").write_text("5")


def _load() -> str:
    return "load average " + " ".join(f"{v:.1f}" for v in os.getloadavg())


def _cluster(workers: int) -> tuple[Any, Any, float]:
    t = time.perf_counter()
    client, cluster = batch._local_client(workers)
    client.run(lambda: __import__("lidarcal.batch"))  # warm: every worker has imported it
    return client, cluster, time.perf_counter() - t


def throughput(folder: Path, vehicles: int) -> dict[int, dict[str, float]]:
    t = time.perf_counter()
    manifest = batch.simulate_fleet(folder, vehicles, bumped=(3, 17, 42), calibrate=True)
    rows = 2 * vehicles
    print(f"simulated {vehicles} vehicles ({rows} rows) in {time.perf_counter() - t:.1f} s")
    print()
    print(
        "| workers | start-up (s) | wall (s) | rows/s | worker s/row: calibrate | monitor | "
        "CPU s/row | cores obtained |"
    )
    print("|---|---|---|---|---|---|---|---|")
    out: dict[int, dict[str, float]] = {}
    for workers in (1, 2):
        client, cluster, startup = _cluster(workers)
        load = _load()
        try:
            output = folder / f"results_{workers}.parquet"
            cpu = client.run(time.process_time)  # each worker process's CPU seconds so far
            summary = batch.run(manifest, output, client=client, progress=False)
            cpu_s = sum(client.run(time.process_time).values()) - sum(cpu.values())
        finally:
            client.close()
            cluster.close()
        table = batch.read_results(output).to_pylist()
        assert len(table) == rows and summary.written == rows
        cal = [r["runtime_s"] for r in table if r["job"] == "calibrate"]
        mon = [r["runtime_s"] for r in table if r["job"] == "monitor"]
        rate = rows / summary.seconds
        out[workers] = {
            "wall": summary.seconds,
            "rate": rate,
            "calibrate": statistics.mean(cal),
            "monitor": statistics.mean(mon),
            "busy": sum(cal) + sum(mon),
            "cpu": cpu_s / rows,
            "cores": cpu_s / summary.seconds,
        }
        print(
            f"| {workers} | {startup:.1f} | {summary.seconds:.1f} | {rate:.2f} | "
            f"{statistics.mean(cal):.3f} (median {statistics.median(cal):.3f}) | "
            f"{statistics.mean(mon):.3f} (median {statistics.median(mon):.3f}) | "
            f"{cpu_s / rows:.3f} | {cpu_s / summary.seconds:.2f} |  {load}"
        )
        print(
            f"    outcome: ok {summary.ok}, refused {summary.refused}, error {summary.error}, "
            f"inconsistent {summary.inconsistent}"
        )
    one, two = out[1], out[2]
    print()
    print(f"speed-up with 2 workers: {two['rate'] / one['rate']:.2f}x (goal >= 1.7x)")
    print(
        f"  = cores the workers obtained ({two['cores']:.2f} / {one['cores']:.2f} = "
        f"{two['cores'] / one['cores']:.2f}x) x CPU cost of a row ({one['cpu']:.3f} / "
        f"{two['cpu']:.3f} = {one['cpu'] / two['cpu']:.2f}x): a CPU cost that stays put means "
        "the rows scale, and the speed-up is what the machine gives"
    )
    for workers, m in out.items():
        per_row = m["wall"] * workers / rows
        print(
            f"{workers} worker(s): {per_row:.3f} worker-s of wall time per row, of which "
            f"{m['busy'] / rows:.3f} s running the row and {per_row - m['busy'] / rows:.3f} s "
            "scheduling, writing and idle"
        )
    return out


def on_paper(measured: dict[str, float], ceiling_rate: float, args: argparse.Namespace) -> None:
    monitor_rows = args.fleet * args.pairs * args.checks_per_day
    calibrate_rows = args.new_vehicles * args.pairs
    core_s = monitor_rows * measured["monitor"] + calibrate_rows * measured["calibrate"]
    cores = args.nodes * args.cores
    data_gb = (monitor_rows + calibrate_rows) * args.mb_per_row / 1000
    print()
    print(
        f"On paper: {args.fleet} vehicles x {args.pairs} LiDAR pairs x {args.checks_per_day} "
        f"monitoring rows a day = {monitor_rows:,} rows, plus {calibrate_rows} calibrations "
        f"({args.new_vehicles} new vehicles a day), on {args.nodes} nodes x {args.cores} cores"
    )
    print(
        f"  compute: {core_s:,.0f} core-s ({measured['monitor']:.3f} s a monitoring row, "
        f"{measured['calibrate']:.3f} s a calibration, as measured here with one worker) = "
        f"{core_s / cores:.0f} s on {cores} cores"
    )
    print(
        f"  reading: {data_gb:,.0f} GB ({args.mb_per_row} MB a row, the simulated street pair as "
        f"binary PCD) = {data_gb / args.storage_gbps / 60:.1f} min at {args.storage_gbps} GB/s "
        "from shared storage"
    )
    print(
        f"  driving: {monitor_rows + calibrate_rows:,} rows through one client and scheduler at "
        f"{ceiling_rate:.0f} rows/s (the ceiling measured here) = "
        f"{(monitor_rows + calibrate_rows) / ceiling_rate / 60:.1f} min"
    )
    print(
        "  -> the day's rows fit well within the day; reading the files and the one client "
        "and scheduler, not the cores, set the pace at that scale"
    )


def memory(folder: Path, rows: int) -> None:
    names = []
    for v in range(10):
        scene = sim.corner_scene("vlp16", seed=v)
        name = f"c{v}"
        write_points(folder / f"{name}_reference.pcd", scene.reference)
        write_points(folder / f"{name}_target.pcd", scene.target)
        np.savetxt(folder / f"{name}_stored.txt", scene.reference_from_target)
        names.append(name)
    manifest = folder / "memory.csv"
    with manifest.open("w") as f:
        f.write("id,reference,target,transform\n")
        for k in range(rows):
            n = names[k % len(names)]
            f.write(f"row{k:06d},{n}_reference.pcd,{n}_target.pcd,{n}_stored.txt\n")
    client, cluster, _ = _cluster(2)
    samples: list[tuple[int, float]] = []
    count = 0

    def sample(_: dict[str, Any]) -> None:
        nonlocal count
        count += 1
        if count in (1, 100) or count % (rows // 10) == 0:
            samples.append((count, _status("VmRSS")))

    load = _load()
    _reset_peak()
    before = _status("VmRSS")
    try:
        output = folder / "memory.parquet"
        summary = batch.run(manifest, output, client=client, progress=False, on_row=sample)
    finally:
        client.close()
        cluster.close()
    peak = _status("VmHWM")
    print()
    print(
        f"Memory: {rows:,} monitoring rows in {summary.seconds:.0f} s "
        f"({rows / summary.seconds:.1f} rows/s, 2 workers, max_in_flight 4); {load}"
    )
    print(f"  client RSS before the run {before:.0f} MB; as rows finished (rows: MB):")
    print("  " + ", ".join(f"{n:,}: {mb:.0f}" for n, mb in samples))
    print(
        f"  peak (VmHWM over the run, including folding the journal into Parquet): {peak:.0f} MB;"
        f" growth from row {rows // 10:,} to row {rows:,}: "
        f"{samples[-1][1] - next(mb for n, mb in samples if n >= rows // 10):+.1f} MB"
    )


def ceiling(folder: Path, rows: int) -> float:
    """Rows per second the client and the scheduler drive when the rows cost nothing (each names
    a missing file, so it is an error row at once), and the client's memory over them."""
    manifest = folder / "ceiling.csv"
    with manifest.open("w") as f:
        f.write("id,reference,target\n")
        for k in range(rows):
            f.write(f"e{k:06d},missing_{k}.pcd,missing.pcd\n")
    client, cluster, _ = _cluster(2)
    samples: list[tuple[int, float]] = []

    def sample(_: dict[str, Any]) -> None:
        samples.append((len(samples) + 1, _status("VmRSS")))

    load = _load()
    try:
        output = folder / "ceiling.parquet"
        # Many rows in flight, as on a large cluster (2 x its threads): the client and the
        # scheduler are then the limit, not the round trip of one row.
        summary = batch.run(
            manifest, output, client=client, max_in_flight=64, progress=False, on_row=sample
        )
    finally:
        client.close()
        cluster.close()
    rate = rows / summary.seconds
    marks = [samples[i - 1] for i in range(rows // 5, rows + 1, rows // 5)]
    print()
    print(
        f"Ceiling: {rows:,} rows that cost nothing (a missing file), 2 workers, 64 in flight: "
        f"{rate:.0f} rows/s ({1000 / rate:.1f} ms a row for the client and the scheduler); {load}"
    )
    print("  client RSS (rows: MB): " + ", ".join(f"{n:,}: {mb:.0f}" for n, mb in marks))
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--memory-rows", type=int, default=10_000)
    parser.add_argument("--skip-memory", action="store_true")
    parser.add_argument("--skip-throughput", action="store_true")
    parser.add_argument("--ceiling-rows", type=int, default=20_000)
    paper = parser.add_argument_group("the on-paper fleet")
    paper.add_argument("--fleet", type=int, default=1000)
    paper.add_argument("--pairs", type=int, default=4, help="LiDAR pairs per vehicle")
    paper.add_argument("--checks-per-day", type=int, default=48, help="monitoring rows per pair")
    paper.add_argument("--new-vehicles", type=int, default=10)
    paper.add_argument("--nodes", type=int, default=100)
    paper.add_argument("--cores", type=int, default=16)
    paper.add_argument("--mb-per-row", type=float, default=3.0)
    paper.add_argument("--storage-gbps", type=float, default=1.0)
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores; {_load()}")
    with tempfile.TemporaryDirectory(prefix="lidarcal_fleet_") as tmp:
        if not args.skip_throughput:
            measured = throughput(Path(tmp) / "fleet", args.vehicles)
            (Path(tmp) / "ceiling").mkdir()
            rate = ceiling(Path(tmp) / "ceiling", args.ceiling_rows)
            on_paper(measured[1], rate, args)  # one worker's per-row cost: the least contended
        if not args.skip_memory:
            (Path(tmp) / "memory").mkdir()
            memory(Path(tmp) / "memory", args.memory_rows)


if __name__ == "__main__":
    main()
