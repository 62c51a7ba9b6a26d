"""`lidarcal calibrate`, the result exports (YAML/JSON/TXT/URDF), plots and ROS bags."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

import lidarcal
from eval_data import require
from lidarcal import sim
from lidarcal.cli import main
from lidarcal.export import quaternion_xyzw, rpy, static_transform_publisher


def rotation_error_deg(truth: np.ndarray, estimate: np.ndarray) -> float:
    d = truth[:3, :3] @ estimate[:3, :3].T
    return float(np.degrees(np.arccos(np.clip((np.trace(d) - 1) / 2, -1, 1))))


@pytest.fixture(scope="module")
def corner_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray]:
    out = tmp_path_factory.mktemp("corner")
    scene = sim.corner_scene("vlp16", seed=3)
    lidarcal.write_points(out / "ref.pcd", scene.reference)
    lidarcal.write_points(out / "tgt.ply", scene.target)
    return out / "ref.pcd", out / "tgt.ply", scene.reference_from_target


def test_quaternion_and_rpy_match_scipy() -> None:
    for r in Rotation.random(200, random_state=3):
        m = r.as_matrix()
        q = quaternion_xyzw(m)
        expected = r.as_quat()
        assert np.allclose(q, expected * np.sign(expected[3]), atol=1e-12)
        angles = rpy(m)
        back = Rotation.from_euler("ZYX", angles[::-1]).as_matrix()
        assert np.allclose(back, m, atol=1e-12)
    # Gimbal lock: pitch +-90 deg still reproduces the matrix.
    m = Rotation.from_euler("ZYX", [0.3, np.pi / 2, 0.0]).as_matrix()
    assert np.allclose(Rotation.from_euler("ZYX", rpy(m)[::-1]).as_matrix(), m, atol=1e-9)


def test_calibrate_json_yaml_txt_urdf(tmp_path: Path, corner_files: tuple) -> None:
    ref, tgt, truth = corner_files
    runner = CliRunner()
    outputs, prints = {}, {}
    for ext in ("yaml", "json", "txt", "urdf"):
        out = tmp_path / f"x.{ext}"
        res = runner.invoke(
            main, ["calibrate", str(ref), str(tgt), "--up", "0,0,1", "--output", str(out), "--json"]
        )
        assert res.exit_code == 0, res.output
        outputs[ext] = out
        prints[ext] = json.loads(res.output)
    printed = prints["urdf"]
    t = np.array(printed["transform"])
    assert printed["method"] == "planes" and printed["converged"] is True
    assert len(printed["rmse"]) == 3 and "diagnostics" in printed
    assert rotation_error_deg(truth, t) < 0.05
    assert np.linalg.norm(truth[:3, 3] - t[:3, 3]) < 0.01
    # YAML and JSON files hold the same dictionary as the object printed by the same run.
    assert yaml.safe_load(outputs["yaml"].read_text()) == prints["yaml"]
    assert json.loads(outputs["json"].read_text()) == prints["json"]
    # TXT: the 4x4 after a comment line.
    np.testing.assert_allclose(np.loadtxt(outputs["txt"]), t, atol=1e-9)
    # URDF: a fixed joint whose origin reproduces the transform.
    joint = ET.parse(outputs["urdf"]).getroot().find("joint")
    assert joint is not None and joint.get("type") == "fixed"
    origin = joint.find("origin")
    assert origin is not None
    xyz = np.array(origin.get("xyz", "").split(), dtype=float)
    angles = np.array(origin.get("rpy", "").split(), dtype=float)
    np.testing.assert_allclose(xyz, t[:3, 3], atol=1e-8)
    np.testing.assert_allclose(
        Rotation.from_euler("ZYX", angles[::-1]).as_matrix(), t[:3, :3], atol=1e-8
    )
    parent = joint.find("parent")
    assert parent is not None and parent.get("link") == "ref"


def test_urdf_names_are_unique(tmp_path: Path, corner_files: tuple) -> None:
    ref, tgt, _ = corner_files
    again = tmp_path / "tgt.npy"  # the same stem as tgt.ply
    np.save(again, lidarcal.read_points(tgt))
    out = tmp_path / "rig.urdf"
    res = CliRunner().invoke(
        main, ["calibrate", str(ref), str(tgt), str(again), "--up", "0,0,1", "--output", str(out)]
    )
    assert res.exit_code == 0, res.output
    root = ET.parse(out).getroot()
    links = [link.get("name") for link in root.findall("link")]
    joints = [joint.get("name") for joint in root.findall("joint")]
    assert links == ["ref", "tgt", "tgt_2"]
    assert len(set(joints)) == 2


def test_text_output_prints_the_tf_command(corner_files: tuple) -> None:
    ref, tgt, _ = corner_files
    res = CliRunner().invoke(main, ["calibrate", str(ref), str(tgt), "--up", "0,0,1"])
    assert res.exit_code == 0, res.output
    assert "reference_from_target" in res.output
    assert "ros2 run tf2_ros static_transform_publisher" in res.output
    assert "--frame-id ref --child-frame-id tgt" in res.output


def test_several_targets_and_a_failure(tmp_path: Path, corner_files: tuple) -> None:
    ref, tgt, _ = corner_files
    blob = tmp_path / "blob.npy"
    np.save(blob, np.random.default_rng(0).normal(size=(2000, 3)))
    res = CliRunner().invoke(
        main,
        ["calibrate", str(ref), str(tgt), str(blob), "--up", "0,0,1", "--json"],
    )
    assert res.exit_code == 1
    out = json.loads(res.stdout)
    assert [("error" in r) for r in out["results"]] == [False, True]
    assert "no clearly planar surface" in out["results"][1]["error"]
    assert out["results"][1]["kind"] in ("too_few_features", "unobservable", "no_agreement")
    assert f"Error [{out['results'][1]['kind']}]: {blob}" in res.stderr
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--crop", "1,2,3"], "needs 6 comma-separated numbers"),
        (["--crop", "5,1,-9,9,-9,9"], "minimum must not exceed"),
        (["--crop", "100,101,100,101,100,101"], "no point is left inside"),
        (["--up", "0,0"], "needs 3 comma-separated numbers"),
        (["--output", "x.xml"], "use .yaml, .json, .txt or .urdf"),
        (["--method", "poles"], "pass intensity_threshold or vendor"),
    ],
)
def test_bad_options_give_one_line_errors(
    corner_files: tuple, args: list[str], message: str
) -> None:
    ref, tgt, _ = corner_files
    res = CliRunner().invoke(main, ["calibrate", str(ref), str(tgt), *args])
    assert res.exit_code != 0
    assert message in res.output, res.output
    assert "Traceback" not in res.output


def test_poles_need_intensity(tmp_path: Path, corner_files: tuple) -> None:
    ref, _, _ = corner_files
    xyz = tmp_path / "xyz.npy"
    np.save(xyz, lidarcal.read_points(ref)[:, :3])
    res = CliRunner().invoke(main, ["calibrate", str(ref), str(xyz), "--method", "poles"])
    assert res.exit_code == 1
    assert "the target file has none" in res.stderr


def test_corrupt_file_is_one_line(tmp_path: Path, corner_files: tuple) -> None:
    ref, _, _ = corner_files
    bad = tmp_path / "bad.pcd"
    bad.write_bytes(b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 9\nDATA binary\n")
    res = CliRunner().invoke(main, ["calibrate", str(ref), str(bad)])
    assert res.exit_code == 1
    assert "bad.pcd" in res.stderr and "truncated" in res.stderr


def test_poles_from_the_command_line(tmp_path: Path) -> None:
    scene = sim.poles_scene("vlp16", seed=1)
    lidarcal.write_points(tmp_path / "a.pcd", scene.reference)
    lidarcal.write_points(tmp_path / "b.bin", scene.target)
    res = CliRunner().invoke(
        main,
        [
            "calibrate",
            str(tmp_path / "a.pcd"),
            str(tmp_path / "b.bin"),
            "--method",
            "poles",
            "--vendor",
            "velodyne",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["method"] == "poles" and out["diagnostics"]["hypothesis_margin"] > 0
    t = np.array(out["transform"])
    assert rotation_error_deg(scene.reference_from_target, t) < 1.0


def test_plot_is_written(tmp_path: Path, corner_files: tuple) -> None:
    ref, tgt, _ = corner_files
    png = tmp_path / "x.png"
    res = CliRunner().invoke(
        main, ["calibrate", str(ref), str(tgt), "--up", "0,0,1", "--plot", str(png)]
    )
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000


def test_overlay_and_residuals(corner_files: tuple) -> None:
    from lidarcal.plot import overlay, residuals

    ref_path, tgt_path, truth = corner_files
    ref, tgt = lidarcal.read_points(ref_path), lidarcal.read_points(tgt_path)
    result = lidarcal.calibrate_planes(ref, tgt, up=[0, 0, 1])
    res = residuals(ref, tgt, result)
    assert len(res) == sum(len(i) for i in result.inliers_target)
    assert np.sqrt(np.mean(res**2)) < 0.03
    fig = overlay(ref, tgt, result)
    assert len(fig.axes) == 6
    fig = overlay(ref, tgt, truth)  # a bare transform: no highlights, no histogram
    assert len(fig.axes) == 6
    with pytest.raises(ValueError, match="must be 4x4"):
        overlay(ref, tgt, np.eye(3))


def test_static_transform_publisher_ros1() -> None:
    line = static_transform_publisher(np.eye(4), "base", "lidar", ros1=True)
    assert line.endswith(
        "0.000000 0.000000 0.000000 0.000000000 0.000000000 0.000000000 1.000000000 base lidar"
    )


def test_to_dict_real_pair_against_authors() -> None:
    appearance = require("lidar_appearance_calibration")
    res = CliRunner().invoke(
        main,
        [
            "calibrate",
            str(appearance / "ref_filter.pcd"),
            str(appearance / "data_filter.pcd"),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    truth = np.array(
        json.loads((appearance / "reference_extrinsics.json").read_text())["data_to_ref_eps_opt"][
            "matrix_4x4"
        ]
    )
    t = np.array(out["transform"])
    # Same bound as the array API's real-data test (the authors' estimate is itself ~0.5 deg off).
    assert rotation_error_deg(truth, t) < 2.0 and np.linalg.norm(truth[:3, 3] - t[:3, 3]) < 0.08


def _write_bag(path: Path, clouds: list[np.ndarray], ros1: bool) -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types = store.types
    PointField = types["sensor_msgs/msg/PointField"]
    PointCloud2 = types["sensor_msgs/msg/PointCloud2"]
    Header = types["std_msgs/msg/Header"]
    Time = types["builtin_interfaces/msg/Time"]
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import Writer  # type: ignore[assignment]

        writer = Writer(path, version=8)  # type: ignore[call-arg]
    with writer:
        conn = writer.add_connection("/points", PointCloud2.__msgtype__, typestore=store)
        other = writer.add_connection("/other", PointCloud2.__msgtype__, typestore=store)
        for k, cloud in enumerate(clouds):
            # x y z as f32, 4 bytes padding, intensity as u16 at offset 16: point_step 18.
            rec = np.zeros(
                len(cloud),
                dtype=np.dtype(
                    {
                        "names": ["x", "y", "z", "intensity"],
                        "formats": ["<f4", "<f4", "<f4", "<u2"],
                        "offsets": [0, 4, 8, 16],
                        "itemsize": 18,
                    }
                ),
            )
            for i, n in enumerate("xyz"):
                rec[n] = cloud[:, i]
            rec["intensity"] = cloud[:, 3]
            fields = [
                PointField(name=n, offset=o, datatype=7, count=1)
                for n, o in zip("xyz", (0, 4, 8), strict=True)
            ]
            fields.append(PointField(name="intensity", offset=16, datatype=4, count=1))
            stamp = Time(sec=100 + k, nanosec=0)
            header = (
                Header(seq=k, stamp=stamp, frame_id="lidar")
                if ros1
                else Header(stamp=stamp, frame_id="lidar")
            )
            msg = PointCloud2(
                header=header,
                height=1,
                width=len(cloud),
                fields=fields,
                is_bigendian=False,
                point_step=18,
                row_step=18 * len(cloud),
                data=rec.view(np.uint8),
                is_dense=True,
            )
            raw = (
                store.serialize_ros1(msg, PointCloud2.__msgtype__)
                if ros1
                else store.serialize_cdr(msg, PointCloud2.__msgtype__)
            )
            writer.write(conn, (100 + k) * 10**9, raw)
            writer.write(other, (100 + k) * 10**9, raw)


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
def test_read_bag_by_topic_and_time(tmp_path: Path, ros1: bool) -> None:
    from lidarcal.rosbag import read_bag

    rng = np.random.default_rng(0)
    clouds = [
        np.column_stack([rng.normal(size=(50, 3)).astype(np.float32), rng.integers(0, 255, 50)])
        for _ in range(3)
    ]
    clouds[1][5, 0] = np.nan
    path = tmp_path / ("x.bag" if ros1 else "x2")
    _write_bag(path, clouds, ros1)
    first = read_bag(path, "/points")
    np.testing.assert_array_equal(first, clouds[0].astype(np.float32).astype(np.float64))
    second = read_bag(path, "/points", time=1.2)  # nearest to start + 1.2 s: the second frame
    assert len(second) == 49  # the NaN point is dropped
    third = read_bag(path, "/points", time=102.0e9 / 1e9)  # an absolute time
    np.testing.assert_array_equal(third, clouds[2].astype(np.float32).astype(np.float64))
    with pytest.raises(ValueError, match="name the topic"):
        read_bag(path)
    # The command line takes BAG:/topic (ROS 2 bags are folders).
    res = CliRunner().invoke(
        main, ["calibrate", f"{path}:/points", f"{path}:/other", "--time", "1", "--json"]
    )
    assert "no such file" not in res.output
    assert json.loads(res.stdout)["target"] == f"{path}:/other"  # (a blob: it fails to calibrate)
    res = CliRunner().invoke(main, ["calibrate", f"{path}:/points", str(tmp_path / "nope.pcd")])
    assert res.exit_code == 2 and "nope.pcd: no such file" in res.output
    with pytest.raises(ValueError, match="no PointCloud2 topic '/nope'"):
        read_bag(path, "/nope")
    with pytest.raises(FileNotFoundError):
        read_bag(tmp_path / "missing.bag", "/points")
    bad = tmp_path / "bad.bag"
    bad.write_bytes(b"not a bag")
    with pytest.raises(lidarcal.FileFormatError, match="not a readable ROS bag"):
        read_bag(bad, "/points")


def test_auto_on_a_street_reports_targetless(tmp_path: Path) -> None:
    scene = sim.street_scene(seed=0, side="left")
    lidarcal.write_points(tmp_path / "top.pcd", scene.reference)
    lidarcal.write_points(tmp_path / "left.pcd", scene.target)
    out = tmp_path / "street.yaml"
    res = CliRunner().invoke(
        main,
        [
            "calibrate",
            str(tmp_path / "top.pcd"),
            str(tmp_path / "left.pcd"),
            "--output",
            str(out),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    printed = json.loads(res.stdout)
    assert printed["method"] == "targetless"
    diagnostics = printed["diagnostics"]
    assert diagnostics["matched_planes"] >= 3
    assert diagnostics["best_score"] >= diagnostics["second_score"]
    assert len(diagnostics["weakest_translation_direction"]) == 3
    t = np.array(printed["transform"])
    assert rotation_error_deg(scene.reference_from_target, t) < 0.1
    assert np.linalg.norm(scene.reference_from_target[:3, 3] - t[:3, 3]) < 0.03
    assert yaml.safe_load(out.read_text()) == printed


def test_poles_threshold_that_marks_everything_is_refused(tmp_path: Path) -> None:
    scene = sim.poles_scene("vlp16", seed=0)
    ref, tgt = tmp_path / "ref.npy", tmp_path / "tgt.npy"
    np.save(ref, scene.reference)
    np.save(tgt, scene.target)
    args = ["calibrate", str(ref), str(tgt), "--method", "poles"]
    res = CliRunner().invoke(main, [*args, "--intensity-threshold", "0"])
    assert res.exit_code == 1
    assert "100.0 % of the returns as tape" in res.stderr and "max_bright_fraction" in res.stderr
    res = CliRunner().invoke(main, [*args, "--max-bright-fraction", "0"])
    assert res.exit_code == 2 and "--max-bright-fraction" in res.output
    res = CliRunner().invoke(main, [*args, "--max-bright-fraction", "0.5", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["method"] == "poles"


def test_rig_flag(tmp_path: Path) -> None:
    left = sim.street_scene(seed=0, side="left")
    right = sim.street_scene(seed=0, side="right")
    files = {}
    for name, cloud in (("top", left.reference), ("left", left.target), ("right", right.target)):
        files[name] = tmp_path / f"{name}.npy"
        np.save(files[name], cloud)
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-10, 10, (5000, 2)), rng.normal(-1.8, 0.01, 5000)])
    files["ground"] = tmp_path / "ground.npy"
    np.save(files["ground"], ground)
    args = ["calibrate", *(str(files[n]) for n in ("top", "left", "right", "ground"))]
    out = tmp_path / "rig.yaml"
    res = CliRunner().invoke(
        main, [*args, "--rig", "--method", "targetless", "--json", "--output", str(out)]
    )
    assert res.exit_code == 1, res.output  # the ground-only unit cannot be placed
    assert "ground.npy: not connected to the reference" in res.stderr
    results = json.loads(res.stdout)["results"]
    assert [Path(r["target"]).stem for r in results] == ["left", "right", "ground"]
    for r, scene in zip(results[:2], (left, right), strict=True):
        t = np.array(r["transform"])
        assert rotation_error_deg(scene.reference_from_target, t) < 0.2
        assert np.linalg.norm(t[:3, 3] - scene.reference_from_target[:3, 3]) < 0.05
        assert r["rig"]["direct"] is True
        assert {(e["a"], e["b"]) for e in r["rig"]["edges"]} >= {("reference", r["target_frame"])}
        # The pose is the graph's; the method's own is kept, and its 1-sigma is not claimed.
        assert "method_transform" in r["diagnostics"] and "std_translation_m" not in r
    assert "error" in results[2]
    assert out.exists() and "left" in out.read_text()
    text = CliRunner().invoke(main, [*args[:4], "--rig", "--method", "targetless"])
    assert text.exit_code == 0, text.output
    assert "rig               direct; " in text.output
