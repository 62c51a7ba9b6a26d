"""calibrate_targetless, calibrate(method=...) and calibrate_rig: simulated streets, the corridor
that must be refused, and the real road scenes (skipped outside CI when ../shared is absent)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import lidarcal
from eval_data import EVAL, require
from lidarcal import _lidarcal, sim

DATA = EVAL / "SensorsCalibration"


def details(result: lidarcal.CalibrationResult) -> lidarcal.TargetlessDetails:
    d = result.details
    assert isinstance(d, lidarcal.TargetlessDetails)
    return d


def errors(t_true: np.ndarray, t_est: np.ndarray) -> tuple[float, float]:
    r = t_true[:3, :3] @ t_est[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))
    return angle, float(np.linalg.norm(t_true[:3, 3] - t_est[:3, 3]))


@pytest.mark.parametrize(("seed", "side"), [(0, "left"), (3, "right")])
def test_street_with_tilted_side_unit(seed: int, side: str) -> None:
    scene = sim.street_scene(seed=seed, side=side)
    # Street 3 fits a pose beyond max_translation as well as the truth: trust the bound here.
    result = lidarcal.calibrate_targetless(
        scene.reference, scene.target.astype(np.float32), challenger_range=1.0
    )
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)
    assert result.method == "targetless" and result.refinement.converged
    assert result.refinement.solver in ("icp", "levenberg_marquardt", "verification")
    d = details(result)
    assert d.planes_reference.shape[0] >= 2 and d.planes_reference.shape[1] == 4
    assert len(result.inliers_reference) == len(d.planes_reference) == len(result.rmse)
    assert d.best_score > d.second_score
    assert d.ambiguous is False
    assert d.agreement > d.best_score
    assert len(d.violations) == 2 and max(d.violations) < 0.05
    direction, share = d.weakest_translation
    assert direction.shape == (3,) and share > 0.01
    assert d.icp is not None and 0.0 < d.icp["fitness"] <= 1.0
    assert min(len(f) for f in d.features) >= 2 and d.hypothesis_counts[1] >= 1
    assert result.covariance is not None and result.covariance.shape == (6, 6)
    assert set(result.timings) >= {"planes", "hypotheses", "verify", "refine", "icp", "total"}
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


def test_rig_with_an_unconnectable_target() -> None:
    left = sim.street_scene(seed=0, side="left")
    # A unit that sees only flat ground: nothing fixes its yaw or position, so it is never
    # connected to the reference.
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-10, 10, (5000, 2)), rng.normal(-1.8, 0.01, 5000)])
    targets = {"left": left.target, "ground": ground}
    with pytest.raises(lidarcal.CalibrationError, match="could not connect ground"):
        lidarcal.calibrate_rig(left.reference, targets, method="targetless")
    rig = lidarcal.calibrate_rig(left.reference, targets, method="targetless", require_all=False)
    assert rig.unconnected == ["ground"] and set(rig.transforms) == {"left"}
    assert ("reference", "ground") in rig.failures
    angle, dist = errors(left.reference_from_target, rig.transforms["left"])
    assert angle < 0.2 and dist < 0.05


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
    bad = scene.target.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"left has 1 row.* NaN .* row 5"):
        lidarcal.calibrate_rig(scene.reference, {"left": bad})
    with pytest.raises(ValueError, match=r"left must have shape \(N, 3\) or \(N, 4\)"):
        lidarcal.calibrate_rig(scene.reference, {"left": scene.target[:, :2]})
    with pytest.raises(ValueError, match="method must be 'auto'"):
        lidarcal.calibrate_rig(scene.reference, [scene.target], method="icp")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'reference' is reserved"):
        lidarcal.calibrate_rig(scene.reference, {"reference": scene.target})
    with pytest.raises(ValueError, match="seed must be an integer"):
        lidarcal.calibrate_rig(scene.reference, [scene.target], seed=-1)


# Every real_world pair within the issue 8 goal: 0.5 deg / 5 cm against the reference (itself
# consistent to about 0.2 deg / 3 cm across the scenes). The closest to the limit is 17-45-07
# right->top (0.13 deg, 4.8 cm; that scene's reference z is 3.5 cm off the other two scenes').
REAL_WORLD = [
    ("2022-02-15-17-31-37-050", "left"),
    ("2022-02-15-17-31-37-050", "right"),  # the free-space check rejects the 180-deg turn
    ("2022-02-15-17-36-04-449", "left"),
    ("2022-02-15-17-36-04-449", "right"),
    ("2022-02-15-17-45-07-750", "left"),  # no common plane pair: the ground sweep
    ("2022-02-15-17-45-07-750", "right"),
]


@pytest.mark.parametrize(("scene", "side"), REAL_WORLD)
def test_real_road_pairs(scene: str, side: str) -> None:
    require("SensorsCalibration", "reference_extrinsics.json")
    refs = json.loads((DATA / "reference_extrinsics.json").read_text())
    truth = np.array(refs["real_world"][scene][f"{side}_to_top"]["matrix_4x4"])
    top = np.load(DATA / "real_world" / scene / "top.npy")[:, :3]
    tgt = np.load(DATA / "real_world" / scene / f"{side}.npy")[:, :3]
    result = lidarcal.calibrate_targetless(top, tgt)
    angle, dist = errors(truth, result.transform)
    assert angle < 0.5 and dist < 0.05, (angle, dist)
    assert details(result).ambiguous is False
    violations = details(result).violations
    assert max(violations) < 0.06, violations


# hesai_scene1 (weaker reference, ~0.4 deg / 4 cm; small overlap): all four QT units. qt_201 sits
# 3.06 m from the P64 along the street; only a pair hypothesis slid along its free direction
# starts within ICP's reach. Measured: 0.10 deg / 3.9 cm, 0.28 / 1.9, 0.21 / 2.9, 0.22 / 4.0.
HESAI = ["qt_201", "qt_202", "qt_203", "qt_204"]


@pytest.mark.parametrize("qt", HESAI)
def test_hesai_qt_units(qt: str) -> None:
    require("SensorsCalibration", "reference_extrinsics.json")
    refs = json.loads((DATA / "reference_extrinsics.json").read_text())
    truth = np.array(refs["hesai_scene1"][f"{qt}_to_p64"]["matrix_4x4"])
    h = DATA / "hesai_scene1"
    result = lidarcal.calibrate_targetless(
        np.load(h / "p64.npy")[:, :3], np.load(h / f"{qt}.npy")[:, :3]
    )
    angle, dist = errors(truth, result.transform)
    assert angle < 0.5 and dist < 0.05, (angle, dist)
    assert details(result).ambiguous is False


# Held out: real recordings never used to tune the targetless method. small_gicp is two sweeps
# of one HDL-32E 0.5 m / 0.7 deg apart at a building (reference: a registration result that ICP
# moves by 0.02 deg / 1.5 cm); measured 0.14 deg / 0.8 cm. The RS-16 corner (two walls and the
# ground, cropped, ~7k points a cloud) gives the targetless method only two matched planes: its
# best pose is 4.5 deg / 43 cm off and a pose 3.8 deg away verifies almost as well, so it must be
# refused as ambiguous, and `auto` falls back to the corner method.
def test_held_out_small_gicp() -> None:
    g = require("small_gicp")
    source = np.load(g / "source.npy")[:, :3].astype(np.float64)
    target = np.load(g / "target.npy")[:, :3].astype(np.float64)
    # A few invalid returns sit at the origin.
    source = source[np.linalg.norm(source, axis=1) > 0.5]
    target = target[np.linalg.norm(target, axis=1) > 0.5]
    truth = np.loadtxt(g / "T_target_source.txt")
    result = lidarcal.calibrate_targetless(target, source)
    angle, dist = errors(truth, result.transform)
    assert angle < 0.5 and dist < 0.05, (angle, dist)
    assert details(result).ambiguous is False


def test_held_out_rs16_corner_is_refused_not_wrong() -> None:
    a = require("lidar_appearance_calibration")
    reference = np.load(a / "ref_filter.npy").astype(np.float64)
    data = np.load(a / "data_filter.npy").astype(np.float64)
    with pytest.raises(lidarcal.CalibrationError, match="ambiguous"):
        lidarcal.calibrate_targetless(reference, data)
    assert lidarcal.calibrate(reference, data).method == "planes"


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("side", ["left", "right"])
def test_every_simulated_street(seed: int, side: str) -> None:
    # Seeds 1 and 2 used to verify the 180-degree turn of the street or be refused; the free-space
    # check and the ground sweep solve all eight when the bound on the rig is trusted
    # (challenger_range=1). With the default challengers, street 3 is refused instead: a pose
    # 6.8-7.8 m along (or across) that street, beyond max_translation, fits as well as the truth.
    scene = sim.street_scene(seed=seed, side=side)
    result = lidarcal.calibrate_targetless(scene.reference, scene.target, challenger_range=1.0)
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)
    try:
        result = lidarcal.calibrate_targetless(scene.reference, scene.target)
    except lidarcal.CalibrationError as e:
        assert seed == 3, e
        assert e.kind in ("ambiguous", "out_of_range") and "max_translation" in str(e), e
        return
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)


def test_challenger_range_is_checked() -> None:
    scene = sim.street_scene(seed=0)
    for bad in (0.5, float("nan")):
        with pytest.raises(ValueError, match="challenger_range"):
            lidarcal.calibrate_targetless(scene.reference, scene.target, challenger_range=bad)


def test_min_agreement_refuses_a_pose_that_explains_too_little() -> None:
    scene = sim.street_scene(seed=0)
    result = lidarcal.calibrate_targetless(scene.reference, scene.target)
    agreement = result.details.agreement
    assert agreement >= _lidarcal._defaults()["calibrate_targetless"]["min_agreement"]
    # Asked for more common structure than the street's best pose brings, it refuses, naming the
    # share it found.
    floor = min(0.99, agreement + 0.05)
    with pytest.raises(lidarcal.CalibrationError) as refused:
        lidarcal.calibrate_targetless(scene.reference, scene.target, min_agreement=floor)
    assert refused.value.kind == "no_agreement"
    assert "too little common structure" in str(refused.value)
    assert f"{100 * agreement:.1f} %" in str(refused.value)
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="min_agreement"):
            lidarcal.calibrate_targetless(scene.reference, scene.target, min_agreement=bad)


# Side units 3 m along the vehicle from the roof unit, with two planes per cloud (road and one
# facade): every hypothesis is a pair, and only its copy slid along the street starts within ICP's
# reach. Before the slide, (0, left) was refused and (1, left) verified the 180-degree turn.
@pytest.mark.parametrize(
    ("seed", "side", "offset"), [(0, "left", -3.0), (1, "left", -3.0), (2, "right", 3.0)]
)
def test_unit_along_the_vehicle_found_by_the_slide(seed: int, side: str, offset: float) -> None:
    scene = sim.street_scene(seed=seed, side=side, target_offset=offset)
    assert abs(scene.reference_from_target[0, 3] - offset) < 0.25
    result = lidarcal.calibrate_targetless(scene.reference, scene.target, max_planes=2)
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)


def test_pose_beyond_max_translation_is_never_returned() -> None:
    # Street 6, right unit 1 m forward: that street barely pins the translation along it (at
    # offset 0 it is refused as unobservable), and here a pose 118 deg and 6.3 m off agrees
    # better than the truth. Verified as a challenger beyond max_translation (or carried there by
    # ICP), it is refused, never returned.
    scene = sim.street_scene(seed=6, side="right", target_offset=1.0)
    try:
        result = lidarcal.calibrate_targetless(scene.reference, scene.target)
    except lidarcal.CalibrationError as e:
        assert "max_translation" in str(e) or "does not constrain" in str(e), e
        return
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)


def test_infinite_max_translation_bounds_the_slide() -> None:
    # max_translation=inf keeps every hypothesis; the slide still stops at SLIDE_RANGE (10 m).
    scene = sim.street_scene(seed=0, side="left", target_offset=-3.0)
    result = lidarcal.calibrate_targetless(
        scene.reference, scene.target, max_translation=float("inf"), max_planes=2
    )
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert angle < 0.1 and dist < 0.02, (angle, dist)


def test_street_target_offset_is_checked() -> None:
    with pytest.raises(ValueError, match="target_offset"):
        sim.street_scene(target_offset=6.0)


@pytest.mark.parametrize("side", ["left", "right"])
def test_bare_street_is_never_silently_wrong(side: str) -> None:
    # Facades and road only (no clutter): the translation along the street is free. Refused
    # with that direction, or (with a cross wall) solved, never a wrong pose.
    for cross_wall in (False, True):
        scene = sim.street_scene(seed=0, side=side, clutter=False, cross_wall=cross_wall)
        try:
            result = lidarcal.calibrate_targetless(scene.reference, scene.target)
        except lidarcal.CalibrationError as e:
            assert e.kind in ("unobservable", "ambiguous", "out_of_range"), e
            continue
        angle, dist = errors(scene.reference_from_target, result.transform)
        assert angle < 0.1 and dist < 0.02, (cross_wall, angle, dist)


def _symmetric_room() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed 16 x 10 m room centred under the reference: a half turn about the vertical maps it
    onto itself, so the true pose and its 180-degree twin explain the scans equally well."""
    shapes = [
        sim.rectangle([-8, -5, 0], [16, 0, 0], [0, 10, 0]),
        sim.rectangle([8, -5, 0], [0, 10, 0], [0, 0, 4]),
        sim.rectangle([-8, -5, 0], [0, 10, 0], [0, 0, 4]),
        sim.rectangle([-8, 5, 0], [16, 0, 0], [0, 0, 4]),
        sim.rectangle([-8, -5, 0], [16, 0, 0], [0, 0, 4]),
    ]
    world_from_reference = np.eye(4)
    world_from_reference[:3, 3] = [0.0, 0.0, 2.0]
    c, s = np.cos(0.3), np.sin(0.3)
    world_from_target = np.eye(4)
    world_from_target[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    world_from_target[:3, 3] = [0.4, 0.3, 1.6]
    reference = sim.scan(shapes, "hdl64", world_from_reference, seed=1)
    target = sim.scan(shapes, "vlp16", world_from_target, seed=2)
    return reference, target, np.linalg.inv(world_from_reference) @ world_from_target


def test_symmetric_room_is_refused_or_flagged() -> None:
    reference, target, truth = _symmetric_room()
    with pytest.raises(lidarcal.CalibrationError, match=r"ambiguous: two poses 180\.0 deg"):
        lidarcal.calibrate_targetless(reference, target)
    result = lidarcal.calibrate_targetless(reference, target, refuse_ambiguous=False)
    d = details(result)
    assert d.ambiguous is True
    assert d.second_score >= 0.8 * d.best_score
    angle, _ = errors(truth, result.transform)
    assert angle < 0.1 or angle > 179.9, angle


@pytest.mark.parametrize("model", ["vlp16", "os128"])
@pytest.mark.parametrize("kind", ["corner", "poles"])
def test_other_scenes_are_solved_or_refused_never_wrong(kind: str, model: str) -> None:
    """Scenes the targetless method was not built for: a wall corner (solved or refused) and two
    poles on bare ground (only the ground is a plane: refused). `auto` solves every one with the
    method made for it. Measured over seeds 0-5 and three beam models: targetless solved 15 of
    18 corners, refused 3 and all 18 pole scenes, and was never wrong."""
    for seed in range(3):
        scene = (sim.corner_scene if kind == "corner" else sim.poles_scene)(model, seed=seed)
        try:
            result = lidarcal.calibrate_targetless(scene.reference[:, :3], scene.target[:, :3])
        except lidarcal.CalibrationError:
            pass
        else:
            angle, dist = errors(scene.reference_from_target, result.transform)
            assert angle < 0.5 and dist < 0.05, (seed, angle, dist)
            assert kind == "corner", "only the ground is a plane in the pole scenes"
        up = [0.0, 0.0, 1.0] if kind == "corner" else None
        auto = lidarcal.calibrate(scene.reference, scene.target, up=up)
        angle, dist = errors(scene.reference_from_target, auto.transform)
        assert angle < 0.5 and dist < 0.05, (seed, auto.method, angle, dist)
        assert auto.method == ("planes" if kind == "corner" else "poles")
