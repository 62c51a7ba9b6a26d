"""`lidarcal calibrate --sequence` (calibration from a drive) on folders of frames and on ROS bags,
`lidarcal simulate --scene drive`, the folder reader and the pairing of two recordings' frames."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import lidarcal
from lidarcal import cli
from lidarcal.cli import main
from lidarcal.frames import in_range, pair_by_time, read_folder

# The shortest drive of seed 0 that calibrates: 80 frames (8 s) reach the first turn; 60 do not.
FRAMES = 80


def rotation_error_deg(truth: np.ndarray, estimate: np.ndarray) -> float:
    d = truth[:3, :3] @ estimate[:3, :3].T
    return float(np.degrees(np.arccos(np.clip((np.trace(d) - 1) / 2, -1.0, 1.0))))


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`lidarcal simulate --scene drive`: reference/ and target/ folders and ground_truth.json."""
    out = tmp_path_factory.mktemp("drive")
    res = CliRunner().invoke(
        main, ["simulate", "--scene", "drive", "--frames", str(FRAMES), "--output", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "--sequence" in res.output
    return out


def test_simulate_drive_writes_numbered_frames_and_times(drive: Path) -> None:
    truth = json.loads((drive / "ground_truth.json").read_text())
    assert truth["scene"] == "drive" and truth["frames"] == FRAMES
    assert np.array(truth["world_from_reference"]).shape == (FRAMES, 4, 4)
    for name in ("reference", "target"):
        frames = sorted((drive / name).glob("*.pcd"))
        assert [p.name for p in frames[:2]] == ["000000.pcd", "000001.pcd"]
        assert len(frames) == FRAMES
        times = np.loadtxt(drive / name / "times.txt")
        np.testing.assert_allclose(times, truth["times"], atol=1e-6)
    assert lidarcal.read_points(drive / "target" / "000003.pcd").shape[1] == 4


def test_sequence_from_folders(drive: Path, tmp_path: Path) -> None:
    truth = np.array(json.loads((drive / "ground_truth.json").read_text())["reference_from_target"])
    ref, tgt = str(drive / "reference"), str(drive / "target")
    out, png = tmp_path / "rear.yaml", tmp_path / "drive.png"
    res = CliRunner().invoke(
        main,
        ["calibrate", ref, tgt, "--sequence", "--json", "--output", str(out), "--plot", str(png)],
    )
    assert res.exit_code == 0, res.output
    entry = json.loads(res.stdout)
    t = np.array(entry["transform"])
    assert rotation_error_deg(truth, t) < 0.5
    assert np.linalg.norm(truth[:3, 3] - t[:3, 3]) < 0.05
    # The fields of the other methods, and the drive's evidence where they put their details.
    assert entry["method"] == "sequence" and entry["converged"] is True
    assert (entry["reference"], entry["target"]) == (ref, tgt)
    assert (entry["reference_frame"], entry["target_frame"]) == ("reference", "target")
    for key in ("translation", "quaternion_xyzw", "rpy_deg", "rpy_rad", "std_translation_m"):
        assert key in entry
    assert "check" not in entry
    d = entry["diagnostics"]
    assert 0 < d["fitness"] <= 1 and 0 < d["rmse"] < 0.05 and entry["rmse"] == [d["rmse"]]
    assert d["distance_m"] > 40 and d["frames"] == FRAMES
    hand_eye = np.array(d["hand_eye_transform"])
    assert hand_eye.shape == (4, 4) and rotation_error_deg(truth, hand_eye) < 1.0
    assert set(d["timings_ms"]) >= {"odometry", "hand_eye", "align"}
    assert entry["sequence"] == {
        "frames": FRAMES,
        "read": [FRAMES, FRAMES],
        "time_span_s": [0.0, 7.9],
    }
    assert entry["plot"] == str(png) and png.stat().st_size > 10_000
    assert yaml.safe_load(out.read_text()) == entry
    # The text summary of the same entry, as `calibrate` prints it without --json.
    text = cli._summary(entry, "reference", "target")
    assert "(sequence, converged True)" in text
    assert f"drive             {FRAMES} frames" in text and "map fitness" in text
    assert "hand-eye" in text and "--frame-id reference --child-frame-id target" in text
    # The other export formats take it too.
    from lidarcal.export import read_transform, write_result

    for suffix in (".txt", ".urdf", ".json"):
        write_result(tmp_path / f"rear{suffix}", entry)
        np.testing.assert_allclose(read_transform(tmp_path / f"rear{suffix}"), t, atol=1e-6)


def test_standing_vehicle_is_refused_with_its_kind(drive: Path, tmp_path: Path) -> None:
    ref_frame = lidarcal.read_points(drive / "reference" / "000000.pcd")
    tgt_frame = lidarcal.read_points(drive / "target" / "000000.pcd")
    for name, frame in (("ref", ref_frame), ("tgt", tgt_frame)):
        (tmp_path / name).mkdir()
        for k in range(12):
            np.save(tmp_path / name / f"{k}.npy", frame)
    args = ["calibrate", str(tmp_path / "ref"), str(tmp_path / "tgt"), "--sequence"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1
    assert res.stderr.startswith(f"Error [unobservable]: {tmp_path / 'tgt'}: ")
    assert "standing vehicle" in res.stderr and "Traceback" not in res.stderr
    res = CliRunner().invoke(main, [*args, "--json", "--output", str(tmp_path / "x.yaml")])
    assert res.exit_code == 1
    out = json.loads(res.stdout)
    assert out["kind"] == "unobservable" and "standing vehicle" in out["error"]
    assert not (tmp_path / "x.yaml").exists()  # nothing to write


def _folder(path: Path, names: list[str], times: list[float] | None = None) -> Path:
    path.mkdir()
    rng = np.random.default_rng(len(names))
    for name in names:
        np.save(path / name, rng.normal(size=(20, 3)))
    if times is not None:
        (path / "times.txt").write_text("".join(f"{t}\n" for t in times))
    return path


def _run(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["calibrate", *map(str, args)])
    assert "Traceback" not in res.output
    return res.exit_code, res.output


def test_folder_errors(tmp_path: Path) -> None:
    three = _folder(tmp_path / "three", ["0.npy", "1.npy", "2.npy"])
    two = _folder(tmp_path / "two", ["frame_0.npy", "frame_1.npy"])
    code, out = _run(three, two, "--sequence")
    assert code == 1
    assert f"{three} has 3 frames and {two} 2 (after --start/--end)" in out
    assert "pair up frame by frame" in out
    # --start/--end count frames without times.txt: 0..1 of both pair up (and are too few).
    code, out = _run(three, two, "--sequence", "--end", "1")
    assert code == 1 and "Error [" not in out and "10" in out  # bad input: no kind
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no frames here\n")
    code, out = _run(three, empty, "--sequence")
    assert code == 1 and f"{empty}: no frames" in out
    unnumbered = _folder(tmp_path / "unnumbered", ["a.npy", "b.npy", "3.npy"])
    code, out = _run(three, unnumbered, "--sequence")
    assert code == 1 and "must hold their number" in out and "a.npy, b.npy" in out
    twice = _folder(tmp_path / "twice", ["1.npy", "01.npy"])
    code, out = _run(three, twice, "--sequence")
    assert code == 1 and "have the same number 1" in out
    short = _folder(tmp_path / "short", ["0.npy", "1.npy", "2.npy"], times=[0.0, 0.1])
    code, out = _run(three, short, "--sequence")
    assert code == 1 and "2 time(s) for 3 frame(s)" in out
    code, out = _run(three, three, "--sequence", "--start", "5")
    assert code == 1 and "no frame between --start 5.0" in out
    single = three / "0.npy"
    code, out = _run(three, single, "--sequence")
    assert code == 1 and "not a single file" in out
    code, out = _run(three, two)
    assert code == 1 and "a folder of frames is read with --sequence" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--start", "1"], "needs --sequence"),
        (["--sequence", "--method", "planes"], "does not apply to --sequence"),
        (["--sequence", "--time", "3"], "does not apply to --sequence"),
        (["--sequence", "--rig"], "does not apply to --sequence"),
        (["--sequence", "EXTRA"], "one TARGET to the REFERENCE, got 2 targets"),
    ],
)
def test_options_that_do_not_fit(tmp_path: Path, args: list[str], message: str) -> None:
    a = _folder(tmp_path / "a", ["0.npy"])
    args = [str(a) if x == "EXTRA" else x for x in args]
    code, out = _run(a, a, *args)
    assert code == 2 and message in out


def test_read_folder_times_and_range(tmp_path: Path) -> None:
    numbered = _folder(tmp_path / "n", ["scan_10.npy", "scan_5.npy", "scan_7.npy"])
    (numbered / "ground_truth.json").write_text("{}")  # not a frame: ignored
    frames, times, paths = read_folder(numbered)
    assert [p.name for p in paths] == ["scan_5.npy", "scan_7.npy", "scan_10.npy"]
    assert times.tolist() == [5.0, 7.0, 10.0] and len(frames) == 3
    _, times, _ = read_folder(numbered, start=2)  # frames from the first
    assert times.tolist() == [7.0, 10.0]
    timed = _folder(
        tmp_path / "t", ["0.npy", "1.npy", "2.npy"], times=[1.6e9, 1.6e9 + 0.1, 1.6e9 + 0.2]
    )
    _, times, _ = read_folder(timed, start=0.05, end=1.6e9 + 0.15)  # relative, absolute
    assert times.tolist() == [1.6e9 + 0.1]
    assert in_range(np.array([0.0, 1.0]), None, None).all()


def test_pair_by_time() -> None:
    ref = np.arange(10) * 0.1
    # The target is 20 ms late, misses a frame and has one an instant after another.
    tgt = np.delete(ref + 0.02, 4)
    tgt = np.append(tgt, 2.0)
    pairs = pair_by_time(ref, tgt)
    assert [i for i, _ in pairs] == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert all(abs(ref[i] - tgt[j]) < 0.05 for i, j in pairs)
    # A target at twice the rate: each reference frame takes its nearest target frame once.
    fast = np.arange(20) * 0.05 + 0.01
    pairs = pair_by_time(ref, fast)
    assert [j for _, j in pairs] == list(range(0, 20, 2))
    # Nothing within half a frame period: no pairs.
    assert pair_by_time(ref, np.array([5.0, 5.1])) == []
    assert pair_by_time(ref, np.array([])) == []


def _write_bag(path: Path, topics: dict[str, list[tuple[int, np.ndarray]]]) -> None:
    """A ROS 2 bag of PointCloud2 topics: ``{topic: [(header stamp ns, (N, 4) cloud), ...]}``,
    each message recorded 5 ms after its stamp."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    point_field, cloud2 = types["sensor_msgs/msg/PointField"], types["sensor_msgs/msg/PointCloud2"]
    header, time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    fields = [
        point_field(name=n, offset=4 * i, datatype=7, count=1)
        for i, n in enumerate(["x", "y", "z", "intensity"])
    ]
    with Writer(path, version=8) as writer:  # type: ignore[call-arg]
        for topic, messages in topics.items():
            conn = writer.add_connection(topic, cloud2.__msgtype__, typestore=store)
            for stamp, cloud in messages:
                data = np.ascontiguousarray(cloud, dtype="<f4")
                msg = cloud2(
                    header=header(
                        stamp=time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=topic
                    ),
                    height=1,
                    width=len(data),
                    fields=fields,
                    is_bigendian=False,
                    point_step=16,
                    row_step=16 * len(data),
                    data=data.view(np.uint8).reshape(-1),
                    is_dense=True,
                )
                writer.write(conn, stamp + 5_000_000, store.serialize_cdr(msg, cloud2.__msgtype__))


def test_sequence_from_a_bag(drive: Path, tmp_path: Path) -> None:
    pytest.importorskip("rosbags")
    from lidarcal.rosbag import read_bag_frames

    # A standing vehicle in a bag: the front unit at 10 Hz, the rear one 20 ms later with one
    # frame lost and one stray frame long after; pairing by time keeps 11 pairs.
    ref_frame = lidarcal.read_points(drive / "reference" / "000000.pcd")[::4]
    tgt_frame = lidarcal.read_points(drive / "target" / "000000.pcd")[::4]
    t0 = 1_700_000_000 * 10**9
    front = [(t0 + k * 10**8, ref_frame) for k in range(12)]
    rear = [(t0 + k * 10**8 + 2 * 10**7, tgt_frame) for k in range(12) if k != 4]
    rear.append((t0 + 3 * 10**9, tgt_frame))
    bag = tmp_path / "drive"
    _write_bag(bag, {"/front": front, "/rear": rear})

    frames, times = read_bag_frames(bag, "/rear")
    assert len(frames) == 12 and frames[0].shape == tgt_frame.shape
    assert times[0] == pytest.approx(
        1.7e9 + 0.02, abs=1e-6
    )  # the header stamp, not the record time
    frames, times = read_bag_frames(bag, "/front", start=0.25, end=0.55)
    # From the bag's start (the first record, 5 ms after the first stamp): stamps 0.3 to 0.5.
    assert len(frames) == 3 and times[0] == pytest.approx(1.7e9 + 0.3, abs=1e-6)
    with pytest.raises(ValueError, match="has no messages from 10 s"):
        read_bag_frames(bag, "/front", start=10.0)

    res = CliRunner().invoke(
        main, ["calibrate", f"{bag}:/front", f"{bag}:/rear", "--sequence", "--json"]
    )
    assert res.exit_code == 1, res.output
    out = json.loads(res.stdout)
    assert out["kind"] == "unobservable" and out["target"] == f"{bag}:/rear"
    assert "over the 11 frames" in out["error"]
    assert f"Error [unobservable]: {bag}:/rear: " in res.stderr
    # A bag and a folder do not pair.
    code, msg = _run(f"{bag}:/front", drive / "target", "--sequence")
    assert code == 1 and "pairs two bags by time or two folders" in msg


def test_folder_copy_with_fewer_frames(drive: Path, tmp_path: Path) -> None:
    """The drive's folders cut differently: a clear count mismatch, not a calibration."""
    cut = tmp_path / "target"
    cut.mkdir()
    for p in sorted((drive / "target").glob("*.pcd"))[:50]:
        shutil.copy(p, cut / p.name)
    np.savetxt(cut / "times.txt", np.loadtxt(drive / "target" / "times.txt")[:50], fmt="%.6f")
    code, out = _run(drive / "reference", cut, "--sequence", "--start", "1", "--end", "7")
    assert code == 1 and "has 61 frames and" in out and "40 (after --start/--end)" in out


def test_sequence_calibrates_from_a_bag(drive: Path, tmp_path: Path) -> None:
    """The drive as a ROS 2 bag (every other point, to keep it small), the rear unit's stamps
    jittered by up to 10 ms: paired by time, it calibrates as the folders do."""
    pytest.importorskip("rosbags")
    truth = np.array(json.loads((drive / "ground_truth.json").read_text())["reference_from_target"])
    rng = np.random.default_rng(0)
    t0 = 1_700_000_000 * 10**9
    topics: dict[str, list[tuple[int, np.ndarray]]] = {"/front": [], "/rear": []}
    for k in range(FRAMES):
        front = lidarcal.read_points(drive / "reference" / f"{k:06d}.pcd")[::2]
        rear = lidarcal.read_points(drive / "target" / f"{k:06d}.pcd")[::2]
        topics["/front"].append((t0 + k * 10**8, front))
        topics["/rear"].append((t0 + k * 10**8 + int(rng.integers(-(10**7), 10**7)), rear))
    bag = tmp_path / "drive"
    _write_bag(bag, topics)
    res = CliRunner().invoke(
        main, ["calibrate", f"{bag}:/front", f"{bag}:/rear", "--sequence", "--json"]
    )
    assert res.exit_code == 0, res.output
    entry = json.loads(res.stdout)
    t = np.array(entry["transform"])
    assert rotation_error_deg(truth, t) < 0.5
    assert np.linalg.norm(truth[:3, 3] - t[:3, 3]) < 0.05
    assert entry["sequence"]["frames"] == FRAMES
    assert entry["sequence"]["time_span_s"] == pytest.approx([1.7e9, 1.7e9 + 7.9], abs=1e-6)
    assert entry["target_frame"] == "rear"
