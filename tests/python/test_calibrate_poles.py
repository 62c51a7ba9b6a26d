"""calibrate_poles from Python: the 20-scene accuracy protocol, hypotheses, options and errors."""

from __future__ import annotations

import numpy as np
import pytest

import lidarcal
import reference as ref
from lidarcal import sim


def errors(t_true: np.ndarray, t_est: np.ndarray) -> tuple[float, float]:
    delta = np.linalg.inv(t_est) @ t_true
    return ref.rotation_angle(delta[:3, :3]), float(np.linalg.norm(delta[:3, 3]))


def scene_radius(seed: int) -> float:
    """Radii spread over 0.05..0.15 m across the 20 scenes."""
    return 0.05 + 0.10 * seed / 19


@pytest.fixture(scope="module")
def twenty() -> list[tuple[float, float]]:
    """Must-show 1: 20 VLP-16 two-pole scenes, noise 0.006 m, random mounting (heading, tilt)."""
    out = []
    for seed in range(20):
        scene = sim.poles_scene(seed=seed, radius=scene_radius(seed))
        try:
            result = lidarcal.calibrate_poles(scene.reference, scene.target, vendor="velodyne")
        except lidarcal.CalibrationError:
            out.append((np.inf, np.inf))
            continue
        out.append(errors(scene.reference_from_target, result.transform))
    return out


def test_twenty_scenes_accuracy(twenty: list[tuple[float, float]]) -> None:
    rot = np.array([r for r, _ in twenty])
    trans = np.array([t for _, t in twenty])
    ok = (rot < 0.05) & (trans < 0.1)
    assert ok.sum() >= 19, (rot, trans)
    assert np.median(rot) <= 5e-3, np.median(rot)
    assert np.median(trans) <= 0.02, np.median(trans)


def test_result_attributes_and_hypotheses() -> None:
    scene = sim.poles_scene(seed=3, radius=0.1)
    result = lidarcal.calibrate_poles(scene.reference, scene.target, vendor="velodyne")
    assert result.method == "poles" and result.refinement.converged
    assert result.refinement.solver in ("levenberg_marquardt", "scene_alignment")
    assert result.transform.shape == (4, 4) and result.initial_transform.shape == (4, 4)
    details = result.details
    assert isinstance(details, lidarcal.PoleDetails)
    assert details.poles_reference.shape == (2, 6) and details.poles_target.shape == (2, 6)
    assert np.all(np.abs(details.radii - 0.1) < 0.02), details.radii
    hyps = details.hypotheses
    assert len(hyps) == 8
    assert set(hyps[0]) == {
        "matches",
        "reference_from_target",
        "axis_rms",
        "ground_angle",
        "ground_offset",
        "overlap",
        "score",
    }
    scores = [h["score"] for h in hyps]
    assert scores[details.chosen] == min(scores)
    assert details.margin > 1.0 and details.ambiguous is False
    assert details.report is not None and details.report["iterations"] > 0
    assert [len(e["poles"]) for e in details.extractions] == [2, 2]
    assert result.rmse.shape == (2,) and np.all(result.rmse < 0.02)
    assert len(result.inliers_reference) == len(result.inliers_target) == 2
    assert "method='poles'" in repr(result)
    # Matched axes agree under the result.
    t = result.transform
    for a, b in zip(details.poles_reference, details.poles_target, strict=True):
        assert float((t[:3, :3] @ b[3:]) @ a[3:]) > np.cos(np.radians(1.0))


def test_cylinder_beats_line_and_rqe() -> None:
    scene = sim.poles_scene(seed=14, radius=0.15)
    cyl = lidarcal.calibrate_poles(scene.reference, scene.target, vendor="velodyne")
    t_cyl = errors(scene.reference_from_target, cyl.transform)[1]
    try:
        line = lidarcal.calibrate_poles(
            scene.reference, scene.target, vendor="velodyne", axis_fit="line"
        )
        t_line = errors(scene.reference_from_target, line.transform)[1]
    except lidarcal.CalibrationError as e:
        # The centroid line's pose can fail the final check: then it is worse by refusal.
        assert e.kind == "no_agreement", e
        t_line = float("inf")
    assert t_cyl < t_line, (t_cyl, t_line)
    # RQE: the merged cloud is crisper with the calibration than with a wrong one.
    tgt = scene.target[:, :3]

    def merged(t: np.ndarray) -> np.ndarray:
        return np.vstack([scene.reference[:, :3], tgt @ t[:3, :3].T + t[:3, 3]])

    wrong = cyl.transform @ lidarcal.se3_exp([0.1, 0.0, 0.0, 0.0, 0.0, 0.05])
    good = lidarcal.metrics.rqe(merged(cyl.transform), 0.05)
    bad = lidarcal.metrics.rqe(merged(wrong), 0.05)
    assert 0.0 < bad < good <= 1.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"radius": 0.3, "seed": 2},
        {"radius": 0.05, "seed": 4, "distractor": True},
        {"radius": 0.1, "seed": 5, "target_upside_down": True},
        {"radius": 0.1, "seed": 7, "max_tilt_deg": 30.0},
    ],
)
def test_scene_variants(kwargs: dict[str, object]) -> None:
    scene = sim.poles_scene(**kwargs)  # type: ignore[arg-type]
    result = lidarcal.calibrate_poles(scene.reference, scene.target)  # data threshold
    r_err, t_err = errors(scene.reference_from_target, result.transform)
    assert r_err < 0.02 and t_err < 0.05, (kwargs, r_err, t_err)


def test_thresholds_and_radius_options() -> None:
    scene = sim.poles_scene(seed=1, radius=0.08)
    for kwargs in [
        {"vendor": "hesai"},
        {"intensity_threshold": 220.0},
        {"pole_radius": 0.08},
        {},
    ]:
        result = lidarcal.calibrate_poles(scene.reference, scene.target, **kwargs)  # type: ignore[arg-type]
        assert errors(scene.reference_from_target, result.transform)[0] < 0.01, kwargs
    result = lidarcal.calibrate_poles(scene.reference, scene.target, pole_radius=0.08)
    assert isinstance(result.details, lidarcal.PoleDetails)
    assert np.allclose(result.details.radii, 0.08)
    details = lidarcal.calibrate_poles(scene.reference, scene.target).details
    assert isinstance(details, lidarcal.PoleDetails)
    thresholds = np.array([e["intensity_threshold"] for e in details.extractions])
    assert np.all((thresholds > 80) & (thresholds < 235))


def test_errors() -> None:
    scene = sim.poles_scene(seed=1)
    reference, target = scene.reference, scene.target
    # Must-show 4: no intensity column, no bright points, one pole, parallel poles, NaN.
    with pytest.raises(ValueError, match=r"needs an \(N, 4\) array with intensity"):
        lidarcal.calibrate_poles(reference[:, :3], target)
    with pytest.raises(lidarcal.CalibrationError, match="bright point"):
        lidarcal.calibrate_poles(reference, target, intensity_threshold=300.0)
    dark = reference.copy()
    dark[:, 3] = np.minimum(dark[:, 3], 80.0)
    with pytest.raises(lidarcal.CalibrationError, match="bright point"):
        lidarcal.calibrate_poles(dark, target, vendor="velodyne")
    labels = scene.reference_labels
    one = reference.copy()
    one[labels == 2, 3] = 50.0  # the second pole's tape is gone
    with pytest.raises(lidarcal.CalibrationError, match=r"found 1 pole\(s\)"):
        lidarcal.calibrate_poles(one, target, vendor="velodyne")
    parallel = reference.copy()
    pole = reference[labels == 1]
    shifted = pole.copy()
    shifted[:, 1] += 2.5  # a copy of pole 1, 2.5 m aside: parallel
    parallel = np.vstack([one, shifted])
    with pytest.raises(lidarcal.CalibrationError, match=r"parallel within 2\.0 deg"):
        lidarcal.calibrate_poles(parallel, target, vendor="velodyne")
    nan = reference.copy()
    nan[[5, 9], 3] = np.nan
    with pytest.raises(ValueError, match=r"2 NaN or infinite intensity value.*row 5"):
        lidarcal.calibrate_poles(nan, target)
    with pytest.raises(ValueError, match="vendor"):
        lidarcal.calibrate_poles(reference, target, vendor="acme")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="axis_fit"):
        lidarcal.calibrate_poles(reference, target, axis_fit="plane")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="sigma"):
        lidarcal.metrics.rqe(reference, 0.0)


def test_planes_result_has_planar_details() -> None:
    rng = np.random.default_rng(0)
    cloud, _ = ref.corner_cloud(rng, 2500, 200, 0.01)
    result = lidarcal.calibrate_planes(cloud, cloud)
    assert isinstance(result.details, lidarcal.PlanarDetails)
    assert not hasattr(result, "poles_reference") and not hasattr(result.details, "radii")


@pytest.mark.parametrize(("model", "seed"), [("os128", 2), ("vlp16", 0)])
def test_a_threshold_that_makes_everything_tape_is_refused(model: str, seed: int) -> None:
    # Threshold 0: every return is "tape". These two scenes came back 45 and 111 degrees off,
    # with ambiguous=False, before the bright-share check.
    scene = sim.poles_scene(model, seed=seed)
    with pytest.raises(lidarcal.CalibrationError, match=r"100\.0 % of the returns as tape"):
        lidarcal.calibrate_poles(scene.reference, scene.target, intensity_threshold=0.0)
    with pytest.raises(ValueError, match=r"max_bright_fraction must be in \(0, 1\]"):
        lidarcal.calibrate_poles(scene.reference, scene.target, max_bright_fraction=1.5)
    result = lidarcal.calibrate_poles(scene.reference, scene.target)
    angle, dist = errors(scene.reference_from_target, result.transform)
    assert np.degrees(angle) < 0.5 and dist < 0.05, (angle, dist)
