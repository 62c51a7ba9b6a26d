"""calibrate_targetless, calibrate(method=...) and calibrate_rig: simulated streets, the corridor
that must be refused, and the real road scenes (skipped outside CI when ../shared is absent)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

import lidarcal
from lidarcal import sim

DATA = Path(__file__).resolve().parents[3] / "shared" / "eval_data" / "SensorsCalibration"


def errors(t_true: np.ndarray, t_est: np.ndarray) -> tuple[float, float]:
    r = t_true[:3, :3] @ t_est[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))
    return angle, float(np.linalg.norm(t_true[:3, 3] - t_est[:3, 3]))


@pytest.mark.parametrize(("seed", "side"), [(0, "left"), (3, "right")])
def test_street_with_tilted_side_unit(seed: int, side: str) -> None:
    scene = sim.street_scene(seed=seed, side=side)
    result = lidarcal.calibrate_targetless(scene.reference, scene.target.astype(np.float32))
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)
    assert result.method == "targetless" and result.converged
    assert result.matched_planes is not None and result.matched_planes >= 2
    assert result.planes_reference is not None
    assert result.planes_reference.shape == (result.matched_planes, 4)
    assert result.best_score is not None and result.second_score is not None
    assert result.best_score > result.second_score
    weakest = result.weakest_translation
    assert weakest is not None and weakest[0].shape == (3,) and weakest[1] > 0.01
    assert result.covariance is not None and result.covariance.shape == (6, 6)
    assert set(result.timings) >= {"planes", "hypotheses", "verify", "refine", "icp", "total"}
    assert result.corners is None and result.poles_reference is None
    assert "method='targetless'" in repr(result)


def test_corridor_is_refused() -> None:
    scene = sim.corridor_scene(seed=0)
    with pytest.raises(
        lidarcal.CalibrationError, match=r"does not constrain the translation along \["
    ):
        lidarcal.calibrate_targetless(scene.reference, scene.target)


def test_auto_reports_the_method_used() -> None:
    scene = sim.street_scene(seed=0)
    result = lidarcal.calibrate(scene.reference, scene.target)
    assert result.method in ("planes", "targetless")
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (result.method, angle, dist)
    with pytest.raises(ValueError, match="method must be"):
        lidarcal.calibrate(scene.reference, scene.target, "icp")  # type: ignore[arg-type]
    corridor = sim.corridor_scene(seed=0)
    with pytest.raises(lidarcal.CalibrationError, match="no method calibrated this pair"):
        lidarcal.calibrate(corridor.reference, corridor.target)


def test_rig_is_consistent() -> None:
    left = sim.street_scene(seed=0, side="left")
    right = sim.street_scene(seed=0, side="right")
    # Same seed: the same street and roof unit, two side units.
    assert np.allclose(left.reference, right.reference)
    rig = lidarcal.calibrate_rig(
        left.reference, {"left": left.target, "right": right.target}, method="targetless"
    )
    assert isinstance(rig, lidarcal.RigCalibration)
    for name, scene in (("left", left), ("right", right)):
        angle, dist = errors(scene.reference_from_target, rig.transforms[name])
        assert angle < 0.2 and dist < 0.05, (name, angle, dist)
    assert {(e.a, e.b) for e in rig.edges} >= {("reference", "left"), ("reference", "right")}
    for e in rig.edges:
        assert np.isfinite(e.rotation_residual_deg) and np.isfinite(e.translation_residual_m)


def test_bad_input() -> None:
    scene = sim.corridor_scene(seed=0)
    with pytest.raises(ValueError, match="at least 100"):
        lidarcal.calibrate_targetless(np.zeros((10, 3)), scene.target)
    with pytest.raises(ValueError, match="voxel_size must be finite and positive"):
        lidarcal.calibrate_targetless(scene.reference, scene.target, voxel_size=0.0)
    with pytest.raises(ValueError, match=r"shape \(N, 3\) or \(N, 4\)"):
        lidarcal.calibrate(np.zeros((100, 2)), scene.target)
    with pytest.raises(ValueError, match="targets is empty"):
        lidarcal.calibrate_rig(scene.reference, {})


def _require(path: Path) -> None:
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{path} is missing: CI must run with ../shared beside the checkout")
        pytest.skip(f"{path} not present (it ships in the project's shared/ folder)")


# Pairs the method solves within the goal (0.5 deg / 5 cm). The other three real pairs
# are known failures, listed in the README: 17-31 right->top verifies the 180-degree turn, and in
# 17-45 the side units share no non-parallel plane pair with the roof unit (refused).
SOLVED = [
    ("2022-02-15-17-31-37-050", "left"),
    ("2022-02-15-17-36-04-449", "left"),
    ("2022-02-15-17-36-04-449", "right"),
]


@pytest.mark.parametrize(("scene", "side"), SOLVED)
def test_real_road_pairs(scene: str, side: str) -> None:
    _require(DATA / "reference_extrinsics.json")
    refs = json.loads((DATA / "reference_extrinsics.json").read_text())
    truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
    top = np.load(DATA / "real_world" / scene / "top.npy")[:, :3]
    tgt = np.load(DATA / "real_world" / scene / f"{side}.npy")[:, :3]
    result = lidarcal.calibrate_targetless(top, tgt)
    angle, dist = errors(truth, result.transform)
    assert angle < 0.5 and dist < 0.05, (angle, dist)


def test_real_scene_without_common_planes_is_refused() -> None:
    _require(DATA / "reference_extrinsics.json")
    d = DATA / "real_world" / "2022-02-15-17-45-07-750"
    with pytest.raises(lidarcal.CalibrationError, match="no pair of non-parallel planes"):
        lidarcal.calibrate_targetless(np.load(d / "top.npy")[:, :3], np.load(d / "left.npy")[:, :3])
