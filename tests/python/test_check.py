"""lidarcal.check, CalibrationError.kind, the `lidarcal check` command and the hard cases."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import lidarcal
from eval_data import require
from lidarcal import sim
from lidarcal.cli import main
from lidarcal.export import read_transform, to_dict, write_result

KINDS = {
    "ambiguous",
    "unobservable",
    "too_few_features",
    "no_agreement",
    "out_of_range",
    "time_budget",
    "inconsistent_methods",
}


def _shift(transform: np.ndarray, rotation_deg: float, translation_m: float) -> np.ndarray:
    """``transform`` turned about the target's z axis and moved along the reference's y axis."""
    a = np.radians(rotation_deg)
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    out = transform @ turn
    out[1, 3] += translation_m
    return out


@pytest.fixture(scope="module")
def street() -> sim.Scene:
    return sim.street_scene(seed=0)


def test_truth_is_consistent_and_errors_are_flagged(street: sim.Scene) -> None:
    truth = street.reference_from_target
    report = lidarcal.check(street.reference, street.target, truth)
    assert report.verdict == "consistent", report
    assert bool(report) and report.overlap > 0.1 and report.agreement > 0.8
    assert report.correction_rotation_deg < 0.1 and report.correction_translation_m < 0.02
    assert report.detectable_rotation_deg > 0 and report.detectable_translation_m > 0
    assert "consistent" in repr(report) and report.to_dict()["verdict"] == "consistent"
    for rot, trans in [(1.0, 0.0), (0.0, 0.15), (180.0, 0.0), (0.0, 3.0)]:
        off = lidarcal.check(street.reference, street.target, _shift(truth, rot, trans))
        assert off.verdict != "consistent", (rot, trans, off)
        assert not off


def test_a_corridor_is_unverifiable() -> None:
    scene = sim.corridor_scene(seed=0)
    report = lidarcal.check(scene.reference, scene.target, scene.reference_from_target)
    assert report.verdict == "unverifiable", report
    assert "does not constrain the translation" in report.reason
    assert report.weakest_translation_share < 0.01


def test_disjoint_clouds_are_unverifiable(street: sim.Scene) -> None:
    far = street.reference_from_target.copy()
    far[0, 3] += 500.0
    report = lidarcal.check(street.reference, street.target, far)
    assert report.verdict == "unverifiable" and "too little overlap" in report.reason


@pytest.mark.parametrize(
    ("transform", "message"),
    [
        (np.eye(3), "4"),
        (np.full((4, 4), np.nan), "non-finite"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "orthonormal"),
    ],
)
def test_bad_transforms_raise(street: sim.Scene, transform: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        lidarcal.check(street.reference, street.target, transform)


def test_bad_clouds_raise(street: sim.Scene) -> None:
    bad = street.target.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        lidarcal.check(street.reference, bad, street.reference_from_target)
    with pytest.raises(ValueError):
        lidarcal.check(street.reference[:5], street.target, street.reference_from_target)
    with pytest.raises(ValueError):
        lidarcal.check(street.reference, street.target[:, :2], street.reference_from_target)


def test_every_result_carries_a_consistent_check(street: sim.Scene) -> None:
    corner = sim.corner_scene("vlp16", seed=1, wall_angle_deg=100)
    for result in (
        lidarcal.calibrate_planes(corner.reference, corner.target),
        lidarcal.calibrate_targetless(street.reference, street.target),
        lidarcal.calibrate(street.reference, street.target),
    ):
        assert result.check.verdict == "consistent", result.check


def test_refusals_carry_a_kind() -> None:
    corridor = sim.corridor_scene(seed=0)
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_targetless(corridor.reference, corridor.target)
    assert info.value.kind == "unobservable"
    poles = sim.poles_scene(seed=0)
    dark = poles.reference.copy()
    dark[:, 3] = np.minimum(dark[:, 3], 80.0)
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_poles(dark, poles.target, vendor="velodyne")
    assert info.value.kind == "too_few_features"
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate(corridor.reference, corridor.target)
    assert info.value.kind in KINDS


def test_read_transform_reads_every_output_format(tmp_path: Path, street: sim.Scene) -> None:
    result = lidarcal.calibrate_targetless(street.reference, street.target)
    entries = [
        to_dict(result, reference="top.pcd", target="left.pcd"),
        to_dict(result, reference="top.pcd", target="right.pcd", transform=np.eye(4)),
    ]
    for ext in (".yaml", ".json", ".txt", ".urdf"):
        path = tmp_path / f"rig{ext}"
        write_result(path, entries)
        got = read_transform(path, "left")
        np.testing.assert_allclose(got, result.transform, atol=1e-6)
        np.testing.assert_allclose(read_transform(path, "right.pcd"), np.eye(4), atol=1e-9)
        with pytest.raises(ValueError, match="pass --target"):
            read_transform(path)
        with pytest.raises(ValueError, match="no transform for target"):
            read_transform(path, "rear")
    bare = tmp_path / "bare.txt"
    np.savetxt(bare, result.transform)
    np.testing.assert_allclose(read_transform(bare), result.transform)
    broken = tmp_path / "broken.txt"
    broken.write_text("1 0 0\n0 1 0\n")
    with pytest.raises(ValueError, match="trailing row"):
        read_transform(broken)


def test_cli_check_exit_codes(tmp_path: Path, street: sim.Scene) -> None:
    ref, tgt = tmp_path / "ref.npy", tmp_path / "tgt.npy"
    np.save(ref, street.reference)
    np.save(tgt, street.target)
    good, bad = tmp_path / "good.txt", tmp_path / "bad.txt"
    np.savetxt(good, street.reference_from_target)
    np.savetxt(bad, _shift(street.reference_from_target, 2.0, 0.3))
    runner = CliRunner()
    ok = runner.invoke(main, ["check", str(ref), str(tgt), "--transform", str(good)])
    assert ok.exit_code == 0, ok.output
    assert "consistent" in ok.output
    assert "points there" in ok.output  # the agreement gain at the re-aligned pose
    off = runner.invoke(main, ["check", str(ref), str(tgt), "--transform", str(bad), "--json"])
    assert off.exit_code == 2, off.output
    assert json.loads(off.output)["verdict"] == "inconsistent"
    assert "agreement_gain" in json.loads(off.output)
    far = tmp_path / "far.txt"
    moved = street.reference_from_target.copy()
    moved[0, 3] += 500.0
    np.savetxt(far, moved)
    none = runner.invoke(main, ["check", str(ref), str(tgt), "--transform", str(far)])
    assert none.exit_code == 3, none.output
    missing = runner.invoke(main, ["check", str(ref), str(tgt), "--transform", str(ref) + "x"])
    assert missing.exit_code != 0


def test_cli_prints_the_kind_of_a_refusal(tmp_path: Path) -> None:
    scene = sim.corridor_scene(seed=0)
    ref, tgt = tmp_path / "ref.npy", tmp_path / "tgt.npy"
    np.save(ref, scene.reference)
    np.save(tgt, scene.target)
    out = CliRunner().invoke(main, ["calibrate", str(ref), str(tgt), "--json"])
    assert out.exit_code == 1
    entry = json.loads(out.output.splitlines()[0])
    assert entry["kind"] in KINDS and entry["error"]


HARD_CASES = [
    "corners_11_auto.npz",
    "partial_28_targetless.npz",
    "poles_0_poles.npz",
    "poles_17_auto.npz",
    "repeated_0_targetless.npz",
]


@pytest.mark.parametrize("name", HARD_CASES)
def test_hard_case_is_refused_with_a_kind_or_solved(name: str) -> None:
    hard = require("hard_cases")
    meta = json.loads((hard / "README.json").read_text())[name]
    z = np.load(hard / name)
    reference, target = z["reference"].astype(np.float64), z["target"].astype(np.float64)
    call = {
        "auto": lidarcal.calibrate,
        "poles": lidarcal.calibrate_poles,
        "targetless": lidarcal.calibrate_targetless,
    }[meta["method_called"]]
    try:
        result = call(reference, target)
    except lidarcal.CalibrationError as e:
        assert e.kind in KINDS
        return
    error = np.linalg.inv(z["reference_from_target"]) @ result.transform
    angle = np.arccos(np.clip((np.trace(error[:3, :3]) - 1) / 2, -1, 1))
    assert angle <= 0.05 and np.linalg.norm(error[:3, 3]) <= 0.10, (name, angle, error[:3, 3])


def test_sensors_further_apart_than_max_translation_are_refused_not_replaced() -> None:
    # partial_28: sensors 7.4 m apart, beyond the default max_translation of 5 m. The best pose
    # within 5 m (a quarter turn, 10 m off) used to come back; the true pose is verified as a
    # challenger beyond the bound. It scores lower (0.12 against 0.17: the wrong pose overlaps
    # more) but the check prefers it (77 % / 70 % of its overlap in agreement against 44 % /
    # 53 %, 2.0 % of the points in free space against 6.2 %), so the result is refused.
    hard = require("hard_cases")
    z = np.load(hard / "partial_28_targetless.npz")
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_targetless(z["reference"], z["target"])
    assert info.value.kind in ("ambiguous", "out_of_range")
    assert "max_translation" in str(info.value)
    # Not refused, the same pose comes back flagged.
    relaxed = lidarcal.calibrate_targetless(z["reference"], z["target"], refuse_ambiguous=False)
    assert relaxed.details.ambiguous
