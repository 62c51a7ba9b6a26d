"""lidarcal.batch and `lidarcal batch` on a real dask.distributed LocalCluster (issue 18).

Worker processes, not threads: one test kills a worker's process mid-run, another kills the whole
command (client and workers) and resumes it. The fleet is simulated (street scenes, two vehicles
with a sensor knocked by 2 degrees); the last test runs the real road pairs of eval_data.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from distributed import Client, LocalCluster

from eval_data import require
from lidarcal import batch
from lidarcal.export import to_yaml

VEHICLES = 6
BUMPED = (1, 4)


@pytest.fixture(scope="module")
def client() -> Iterator[Client]:
    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            env={"RAYON_NUM_THREADS": "1"},
        ) as cluster,
        Client(cluster) as c,
    ):
        yield c


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A manifest of VEHICLES monitoring rows and as many calibration rows, plus four bad rows:
    a corrupt cloud, a missing one, an unreadable transform and an unknown method."""
    folder = tmp_path_factory.mktemp("fleet")
    simulated = batch.simulate_fleet(folder, VEHICLES, bumped=BUMPED, calibrate=True)
    (folder / "corrupt.pcd").write_bytes(b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4\n\x00\x01garbage")
    (folder / "bad_transform.txt").write_text("1 0 0\n0 1 0 oops\n")
    rows = simulated.read_text().splitlines()[1:]
    rows += [
        "bad-corrupt,v000_reference.pcd,corrupt.pcd,",
        "bad-missing,v000_reference.pcd,nowhere.pcd,v000_stored.txt",
        "bad-transform,v000_reference.pcd,v000_target.pcd,bad_transform.txt",
    ]
    manifest = folder / "fleet.csv"
    manifest.write_text(
        "id,reference,target,transform,method\n"
        + "".join(f"{row},\n" for row in rows)
        + "bad-method,v000_reference.pcd,v000_target.pcd,,magic\n"
    )
    return manifest


def _monitors(fleet: Path, path: Path, rows: int) -> Path:
    """A manifest of ``rows`` monitoring rows over the fleet's vehicles (absolute paths)."""
    with path.open("w") as f:
        f.write("id,reference,target,transform\n")
        for k in range(rows):
            v = f"{fleet.parent}/v{k % VEHICLES:03d}"
            f.write(f"r{k:02d},{v}_reference.pcd,{v}_target.pcd,{v}_stored.txt\n")
    return path


def _ids(manifest: Path) -> list[str]:
    return [job["id"] or "" for job in batch.read_manifest(manifest)]


def _rows(output: Path) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = batch.read_results(output).to_pylist()
    return rows


def _assert_once(output: Path, manifest: Path) -> list[dict[str, Any]]:
    rows = _rows(output)
    counts = Counter(r["id"] for r in rows)
    assert [i for i, n in counts.items() if n > 1] == []
    assert sorted(counts) == sorted(_ids(manifest))
    return rows


@pytest.fixture(scope="module")
def fleet_run(
    client: Client, fleet: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, batch.Summary]:
    output = tmp_path_factory.mktemp("out") / "results.parquet"
    summary = batch.run(fleet, output, client=client, max_in_flight=3, progress=False)
    return output, summary


def test_every_row_exactly_once(fleet_run: tuple[Path, batch.Summary], fleet: Path) -> None:
    output, summary = fleet_run
    rows = _assert_once(output, fleet)
    assert not batch._ParquetSink.journal_path(output).exists()  # folded into the Parquet file
    assert pq.ParquetFile(output).schema_arrow.names == list(batch.COLUMNS)
    assert summary.rows == summary.written == len(rows) and summary.skipped == 0
    status = Counter(r["status"] for r in rows)
    assert (summary.ok, summary.refused, summary.error) == (
        status["ok"],
        status["refused"],
        status["error"],
    )
    # Both workers took rows.
    assert len({r["worker"] for r in rows}) == 2


def test_monitoring_rows_flag_the_bumped_vehicles(
    fleet_run: tuple[Path, batch.Summary], fleet: Path
) -> None:
    output, summary = fleet_run
    monitors = {r["id"]: r for r in _rows(output) if r["job"] == "monitor"}
    for v in range(VEHICLES):
        row = monitors[f"v{v:03d}"]
        assert row["status"] == "ok", row
        expected = "inconsistent" if v in BUMPED else "consistent"
        assert row["verdict"] == expected, row
        stored = np.loadtxt(fleet.parent / f"v{v:03d}_stored.txt")
        assert np.allclose(np.reshape(row["transform"], (4, 4)), stored)
        if v in BUMPED:  # the re-alignment finds the knock back
            assert abs(row["correction_rotation_deg"] - 2.0) < 0.3, row
    assert summary.inconsistent == len(BUMPED)


def test_calibration_rows_are_certified_or_refused_with_a_kind(
    fleet_run: tuple[Path, batch.Summary],
) -> None:
    output, _ = fleet_run
    calibrations = [r for r in _rows(output) if r["job"] == "calibrate" and r["id"][0] == "v"]
    assert len(calibrations) == VEHICLES
    for row in calibrations:
        if row["status"] == "ok":
            assert row["verdict"] == "consistent" and row["method"] in ("planes", "targetless")
            assert len(row["transform"]) == 16 and row["runtime_s"] > 0
            t = np.reshape(row["transform"], (4, 4))
            assert np.allclose([row["tx"], row["ty"], row["tz"]], t[:3, 3])
        else:
            assert row["status"] == "refused" and row["kind"] and row["message"], row
    assert sum(r["status"] == "ok" for r in calibrations) >= VEHICLES // 2


def test_bad_rows_are_error_rows(fleet_run: tuple[Path, batch.Summary]) -> None:
    output, summary = fleet_run
    rows = {r["id"]: r for r in _rows(output)}
    expected = {
        "bad-corrupt": ("bad_file", "corrupt.pcd"),
        "bad-missing": ("missing_file", "nowhere.pcd"),
        "bad-transform": ("bad_transform", "bad_transform.txt"),
        "bad-method": ("bad_row", "magic"),
    }
    for job_id, (kind, needle) in expected.items():
        row = rows[job_id]
        assert (row["status"], row["kind"]) == ("error", kind), row
        assert needle in row["message"], row
    assert summary.error == len(expected)
    assert all(r["status"] != "error" for i, r in rows.items() if i not in expected)


def test_a_killed_worker_loses_no_row(client: Client, fleet: Path, tmp_path: Path) -> None:
    client.wait_for_workers(2)
    output = tmp_path / "results.csv"
    killed: list[int] = []
    lost: list[str] = []  # the rows the killed worker was running

    def kill_a_busy_worker(row: dict[str, Any]) -> None:
        if killed:
            return
        pids = client.run(os.getpid)
        busy = [(addr, keys) for addr, keys in client.processing().items() if keys]
        assert busy, "no row was running when the worker was to be killed"
        addr, keys = busy[0]
        lost.extend(str(key).split("-", 3)[3] for key in keys)
        killed.append(pids[addr])
        os.kill(pids[addr], signal.SIGKILL)  # the process itself, mid-row

    summary = batch.run(
        fleet, output, client=client, max_in_flight=4, progress=False, on_row=kill_a_busy_worker
    )
    rows = _assert_once(output, fleet)
    assert killed and summary.written == len(rows)
    # The rows the killed worker was running were run again by another worker process.
    assert lost
    by_id = {r["id"]: r for r in rows}
    for job_id in lost:
        assert by_id[job_id]["worker"].split(":")[-1] != str(killed[0]), by_id[job_id]
    assert all(r["kind"] != "worker_lost" for r in rows)
    assert sum(r["status"] == "error" for r in rows) == 4  # the four bad rows only
    client.wait_for_workers(2, timeout=60)  # the nanny restarted the worker
    assert killed[0] not in client.run(os.getpid).values()


class Interrupt(Exception):
    pass


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_an_interrupted_run_resumes(
    client: Client, fleet: Path, tmp_path: Path, suffix: str
) -> None:
    manifest = _monitors(fleet, tmp_path / "monitors.csv", 12)
    output = tmp_path / f"results{suffix}"
    seen: list[str] = []

    def stop_after_three(row: dict[str, Any]) -> None:
        seen.append(row["id"])
        if len(seen) == 3:
            raise Interrupt

    with pytest.raises(Interrupt):
        batch.run(manifest, output, client=client, progress=False, on_row=stop_after_three)
    first = _rows(output)  # readable after the interruption, with the finished rows
    assert sorted(r["id"] for r in first) == sorted(seen)
    summary = batch.run(manifest, output, client=client, progress=False)
    rows = _assert_once(output, manifest)
    assert summary.skipped == 3 and summary.written == 12 - 3
    assert summary.ok == 12 and summary.inconsistent == 4  # r01 r04 r07 r10: the bumped ones
    assert [r for r in rows if r["id"] in seen] == first  # the finished rows were not redone
    again = batch.run(manifest, output, client=client, progress=False)
    assert again.written == 0 and again.skipped == 12


def test_the_command_resumes_after_being_killed(fleet: Path, tmp_path: Path) -> None:
    # Many cheap monitoring rows, so the run is surely killed part-way.
    manifest = _monitors(fleet, tmp_path / "many.csv", 40)
    output = tmp_path / "results.parquet"
    journal = batch._ParquetSink.journal_path(output)
    command = [sys.executable, "-m", "lidarcal.cli", "batch", str(manifest), "--output"]
    command += [str(output), "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (journal.exists() and journal.read_text().count("\n") >= 3):
            assert proc.poll() is None, "the command ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the client and its workers, all at once
        proc.wait()
    done = journal.read_text().count("\n")
    assert 3 <= done < 40 and not output.exists()
    with journal.open("a") as f:
        f.write('{"id": "r39", "status": "ok", "ver')  # a line the kill cut short
    rerun = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 2, rerun.stderr  # some monitoring rows are inconsistent
    assert f"{40 - done} row(s)" in rerun.stdout and f"{done} already done" in rerun.stdout
    rows = _assert_once(output, manifest)
    assert not journal.exists()
    assert sum(r["verdict"] == "inconsistent" for r in rows) == sum(
        k % VEHICLES in BUMPED for k in range(40)
    )


def test_bad_manifests_and_outputs_are_refused_before_any_work(tmp_path: Path) -> None:
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,reference,target\na,x.pcd,y.pcd\na,x.pcd,z.pcd\n")
    with pytest.raises(ValueError, match="'a' appears twice"):
        batch.run(manifest, tmp_path / "r.csv")
    manifest.write_text("id,reference\na,x.pcd\n")
    with pytest.raises(ValueError, match="needs the column"):
        batch.run(manifest, tmp_path / "r.csv")
    manifest.write_text("id,reference,target\n,x.pcd,y.pcd\n")
    with pytest.raises(ValueError, match="row 1 has no id"):
        batch.run(manifest, tmp_path / "r.csv")
    manifest.write_text("id,reference,target\na,x.pcd,y.pcd\n")
    with pytest.raises(ValueError, match=r"\.parquet or \.csv"):
        batch.run(manifest, tmp_path / "r.json")
    (tmp_path / "other.csv").write_text("x,y\n1,2\n")
    with pytest.raises(ValueError, match="not a lidarcal results file"):
        batch.run(manifest, tmp_path / "other.csv")
    assert not (tmp_path / "r.csv").exists()


def test_a_parquet_manifest_and_a_result_file_with_several_transforms(
    client: Client, fleet: Path, tmp_path: Path
) -> None:
    import pyarrow as pa

    folder = fleet.parent
    rig = tmp_path / "rig.yaml"
    entries = [
        {
            "target": str(folder / f"v{v:03d}_target.pcd"),
            "transform": np.loadtxt(folder / f"v{v:03d}_stored.txt").tolist(),
        }
        for v in (0, 1)
    ]
    rig.write_text(to_yaml(entries))
    table = pa.table(
        {
            "id": [10, 11],
            "reference": [str(folder / f"v{v:03d}_reference.pcd") for v in (0, 1)],
            "target": [str(folder / f"v{v:03d}_target.pcd") for v in (0, 1)],
            "transform": [str(rig)] * 2,
        }
    )
    pq.write_table(table, tmp_path / "m.parquet")
    summary = batch.run(tmp_path / "m.parquet", tmp_path / "r.csv", client=client, progress=False)
    rows = {r["id"]: r for r in _rows(tmp_path / "r.csv")}
    assert (rows["10"]["verdict"], rows["11"]["verdict"]) == ("consistent", "inconsistent")
    assert summary.written == 2


def test_real_road_pairs(client: Client, tmp_path: Path) -> None:
    """Issue 18, must show 2: calibrations within 0.5 deg / 5 cm of the reference; the reference
    transform consistent, a copy turned by 2 degrees inconsistent."""
    base = require("SensorsCalibration")
    refs = json.loads((base / "reference_extrinsics.json").read_text())
    lines = ["id,reference,target,transform"]
    truths: dict[str, np.ndarray] = {}
    a = np.radians(2.0)
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    for scene in sorted(refs["real_world"]):
        d = base / "real_world" / scene
        top = next(d.glob("top-*.pcd"))
        for side in ("left", "right"):
            name = f"{scene[-12:]}-{side}"
            truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
            truths[name] = truth
            tgt = next(d.glob(f"{side}-*.pcd"))
            np.savetxt(tmp_path / f"{name}.txt", truth)
            (tmp_path / f"{name}-turned.json").write_text(
                json.dumps({"transform": (truth @ turn).tolist()})
            )
            lines.append(f"{name},{top},{tgt},")
            lines.append(f"{name}-good,{top},{tgt},{name}.txt")
            lines.append(f"{name}-turned,{top},{tgt},{name}-turned.json")
    manifest = tmp_path / "road.csv"
    manifest.write_text("\n".join(lines) + "\n")
    batch.run(manifest, tmp_path / "road.parquet", client=client, progress=False)
    rows = {r["id"]: r for r in _assert_once(tmp_path / "road.parquet", manifest)}
    for name, truth in truths.items():
        row = rows[name]
        assert row["status"] == "ok", row
        est = np.reshape(row["transform"], (4, 4))
        r = truth[:3, :3] @ est[:3, :3].T
        angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
        assert angle < 0.5 and np.linalg.norm(truth[:3, 3] - est[:3, 3]) < 0.05, (name, row)
        assert rows[f"{name}-good"]["verdict"] == "consistent", rows[f"{name}-good"]
        assert rows[f"{name}-turned"]["verdict"] == "inconsistent", rows[f"{name}-turned"]


def test_a_csv_line_cut_by_a_crash_is_dropped_on_resume(tmp_path: Path) -> None:
    output = tmp_path / "r.csv"
    sink = batch._CsvSink(output)
    for job_id in ("a", "b"):
        row = batch._empty_row(job_id, "monitor")
        row.update(status="error", kind="bad_row", message="two\nlines")
        sink.write(row)
    sink.close()
    with output.open("a") as f:
        f.write("c,monitor,ok,,,,1.0 0.0")  # the crash came mid-line
    again = batch._CsvSink(output)
    again.close()
    assert sorted(again.done) == ["a", "b"]
    assert output.read_text().endswith("\n") and output.read_text().count("\n") == 3
    assert [r["message"] for r in _rows(output)] == ["two lines", "two lines"]


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
def test_rows_reading_ros_bag_topics(tmp_path: Path, ros1: bool) -> None:
    """A row's clouds may be ``BAG:/topic`` (ROS 2 bags are folders), picked by its ``time``."""
    from lidarcal import sim
    from test_cli_calibrate import _write_bag

    scene = sim.corner_scene(seed=0)
    few = np.random.default_rng(0).normal(size=(5, 4)) * [1, 1, 1, 0]  # too few to check
    bag = tmp_path / ("drive.bag" if ros1 else "drive")
    _write_bag(bag, [few, scene.reference], ros1)  # both topics carry frame k at 100 + k s
    identity = tmp_path / "identity.txt"
    np.savetxt(identity, np.eye(4))
    row = {"reference": f"{bag}:/points", "target": f"{bag}:/other", "transform": str(identity)}
    first = batch.process_row({"id": "first", **row})  # no time: the first frame, 5 points
    assert first["status"] == "error" and first["kind"] == "bad_input", first
    second = batch.process_row({"id": "second", "time": "1", **row})  # the corner, 1 s later
    assert second["status"] == "ok" and second["verdict"] == "consistent", second["message"]
    # A pose 0.5 m off is flagged on the frame the time picks.
    turned = tmp_path / "turned.txt"
    pose = np.eye(4)
    pose[:3, 3] = [0.5, 0.0, 0.0]
    np.savetxt(turned, pose)
    moved = batch.process_row({"id": "moved", "time": "1", **row, "transform": str(turned)})
    assert moved["status"] == "ok" and moved["verdict"] == "inconsistent", moved["message"]
    missing = batch.process_row({"id": "missing", **row, "target": f"{bag}:/nope"})
    assert missing["status"] == "error" and missing["kind"] == "bad_file"
    assert "/nope" in missing["message"]
