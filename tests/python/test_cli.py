"""The `lidarcal simulate` command, through click's CliRunner."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from lidarcal.cli import main


@pytest.mark.parametrize("scene", ["corner", "poles", "paper"])
def test_simulate_writes_pcd_and_ground_truth(tmp_path: Path, scene: str) -> None:
    out = tmp_path / scene
    result = CliRunner().invoke(
        main, ["simulate", "--scene", scene, "--seed", "2", "--output", str(out)]
    )
    assert result.exit_code == 0, result.output
    truth = json.loads((out / "ground_truth.json").read_text())
    t = np.array(truth["reference_from_target"])
    assert t.shape == (4, 4) and np.allclose(t[3], [0, 0, 0, 1])
    assert truth["seed"] == 2 and truth["scene"] == scene
    for name in ("reference", "target"):
        raw = (out / f"{name}.pcd").read_bytes()
        header, _, data = raw.partition(b"DATA binary\n")
        assert b"FIELDS x y z intensity ring" in header
        count = int(header.split(b"POINTS ")[1].split(b"\n")[0])
        assert len(data) == count * 18 and count > 1000
    # Ground truth agrees with the target file: its planar points land on the true planes.
    if scene == "corner":
        rec = np.frombuffer(
            (out / "target.pcd").read_bytes().partition(b"DATA binary\n")[2],
            dtype=np.dtype([("xyzi", "<f4", 4), ("ring", "<u2")]),
        )
        p = rec["xyzi"][:, :3].astype(np.float64) @ t[:3, :3].T + t[:3, 3]
        planes = np.array(truth["planes_in_reference"])
        dist = np.abs(p @ planes[:, :3].T + planes[:, 3]).min(axis=1)
        assert np.mean(dist < 0.1) > 0.7  # the rest are clutter boxes


def test_simulate_npy_and_same_seed_same_output(tmp_path: Path) -> None:
    runs = []
    for k in range(2):
        out = tmp_path / str(k)
        args = ["simulate", "--scene", "poles", "--model", "hdl32", "--format", "npy"]
        result = CliRunner().invoke(main, [*args, "--output", str(out)])
        assert result.exit_code == 0, result.output
        runs.append(np.load(out / "target.npy"))
    assert runs[0].shape[1] == 5
    assert np.array_equal(runs[0], runs[1])


def test_simulate_errors_exit_non_zero(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["simulate", "--model", "lux", "--output", str(tmp_path)])
    assert result.exit_code != 0 and "lux" in result.output
    blocker = tmp_path / "file"
    blocker.write_text("x")
    result = CliRunner().invoke(main, ["simulate", "--output", str(blocker / "sub")])
    assert result.exit_code != 0
    assert result.output.strip().startswith("Error:") or "Error" in result.output


def test_demo_calibrates_a_simulated_corner() -> None:
    from lidarcal.cli import main

    runner = CliRunner()
    result = runner.invoke(main, ["demo", "--seed", "2"])
    assert result.exit_code == 0, result.output
    assert "error     rotation" in result.output
    out = runner.invoke(main, ["demo", "--seed", "2", "--json"])
    assert out.exit_code == 0, out.output
    report = json.loads(out.output)
    assert report["rotation_error_deg"] < 0.1 and report["translation_error_m"] < 0.01
    assert np.array(report["transform"]).shape == (4, 4) and report["converged"]
    bad = runner.invoke(main, ["demo", "--wall-angle", "10"])
    assert bad.exit_code != 0 and "wall_angle_deg must be in" in bad.output
    assert "Traceback" not in bad.output
