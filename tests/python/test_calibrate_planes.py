"""calibrate_planes from Python: parity with the NumPy pipeline, ground truth, real data, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

import lidarcal
import reference as ref
from eval_data import require
from lidarcal import sim


def planar(result: lidarcal.CalibrationResult) -> lidarcal.PlanarDetails:
    d = result.details
    assert isinstance(d, lidarcal.PlanarDetails)
    return d


def two_sensor_corner(
    t_true: np.ndarray, seed: int, sigma: float = 0.02, clutter: int = 800
) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    reference, _ = ref.corner_cloud(rng, 2500, clutter, sigma)
    seen, _ = ref.corner_cloud(rng, 2500, clutter, sigma)
    target = ref.transform_points(np.linalg.inv(t_true), seen)
    return reference, target


def errors(t_true: np.ndarray, t_est: np.ndarray) -> tuple[float, float]:
    return (
        ref.rotation_angle(t_true[:3, :3] @ t_est[:3, :3].T),
        float(np.linalg.norm(t_true[:3, 3] - t_est[:3, 3])),
    )


POSES = [
    lidarcal.se3_exp([0.5, -0.3, 0.2, 0.05, -0.02, 0.5]),
    lidarcal.se3_exp([1.0, 0.5, 0.0, 0.0, 0.0, np.pi]),  # turned around
    lidarcal.se3_exp([0.2, 0.8, -0.3, 0.55, 0.1, 0.2]),  # tilted ~30 deg
]


@pytest.mark.parametrize("k", range(len(POSES)))
def test_recovers_ground_truth(k: int) -> None:
    t_true = POSES[k]
    reference, target = two_sensor_corner(t_true, seed=k)
    result = lidarcal.calibrate_planes(reference, target.astype(np.float32))
    r_err, t_err = errors(t_true, result.transform)
    assert r_err < 2e-3 and t_err < 1e-2, (r_err, t_err)
    assert result.refinement.converged and result.method == "planes"
    assert result.refinement.solver == "levenberg_marquardt" and result.refinement.iterations > 0
    assert result.transform.shape == (4, 4) and result.initial_transform.shape == (4, 4)
    d = planar(result)
    assert d.planes_reference.shape == (3, 4) and len(result.inliers_target) == 3
    assert d.corners.shape == (2, 3) and d.ordering["scores"].shape == (3,)
    assert d.report is not None and d.report["final_cost"] == result.refinement.cost
    assert result.covariance is not None and result.covariance.shape == (6, 6)
    assert set(result.timings) >= {"planes", "match", "refine", "total"}
    assert "CalibrationResult(method='planes'" in repr(result)
    assert "Refinement(solver='levenberg_marquardt', converged=True" in repr(result)
    # Matched planes agree under the result: target planes map onto the reference planes.
    for p_ref, p_tgt in zip(d.planes_reference, d.planes_target, strict=True):
        n = result.transform[:3, :3] @ p_tgt[:3]
        assert float(n @ p_ref[:3]) > np.cos(np.radians(1.0))


def test_matches_numpy_pipeline_from_the_same_planes() -> None:
    t_true = POSES[0]
    reference, target = two_sensor_corner(t_true, seed=5)
    # The NumPy pipeline solves plain least squares.
    result = lidarcal.calibrate_planes(reference, target, loss="squared")
    pts_ref = [reference[i] for i in result.inliers_reference]
    pts_tgt = [target[i] for i in result.inliers_target]
    # Hand the reference the target planes shuffled: it must find the same correspondence.
    shuffle = [2, 0, 1]
    initial, refined, perm = ref.planar_pipeline(
        planar(result).planes_reference,
        planar(result).planes_target[shuffle],
        pts_ref,
        [pts_tgt[i] for i in shuffle],
    )
    assert np.array_equal(np.array(shuffle)[perm], [0, 1, 2])
    assert np.allclose(initial, result.initial_transform, atol=1e-9)
    r_err, t_err = errors(refined, result.transform)
    assert r_err < 1e-6 and t_err < 1e-6, (r_err, t_err)


def test_cube_corner_tie_broken_by_the_check_or_by_up() -> None:
    rng = np.random.default_rng(3)
    corner = np.array([5.0, 5.0, -1.5])

    def cube(n: int) -> np.ndarray:
        faces = []
        for axis in range(3):
            p = np.tile(corner, (n, 1))
            for other in (a for a in range(3) if a != axis):
                p[:, other] -= rng.uniform(0, 4, n)
            p[:, axis] += rng.normal(0, 0.01, n)
            faces.append(p)
        return np.vstack(faces)

    t_true = lidarcal.se3_exp([0.3, -0.2, 0.1, 0.0, 0.0, 0.25])
    reference = cube(2000)
    target = ref.transform_points(np.linalg.inv(t_true), cube(2000))
    # The three correspondences tie on the normals; seen from the sensors (not along the
    # corner's diagonal) only the truth keeps each cloud out of the other's free space.
    result = lidarcal.calibrate_planes(reference, target)
    ordering = planar(result).ordering
    assert not ordering["used_up"] and ordering["margin"] < np.radians(0.5)
    r_err, t_err = errors(t_true, result.transform)
    assert r_err < 2e-3 and t_err < 1e-2
    up_target = t_true[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    result = lidarcal.calibrate_planes(reference, target, up=[[0, 0, 1.0], up_target])
    assert planar(result).ordering["used_up"]
    r_err, t_err = errors(t_true, result.transform)
    assert r_err < 2e-3 and t_err < 1e-2


def test_bare_simulated_cube_corner_needs_up() -> None:
    # Two walls at 90 degrees and the ground, nothing else: every tied correspondence passes
    # the check, so without `up` the corner method refuses and says so.
    scene = sim.corner_scene(seed=0)
    with pytest.raises(lidarcal.CalibrationError) as refused:
        lidarcal.calibrate_planes(scene.reference, scene.target)
    assert refused.value.kind == "ambiguous"
    assert "pass `up`" in str(refused.value)
    assert "of the tied orderings 3 pass the check" in str(refused.value)
    result = lidarcal.calibrate_planes(scene.reference, scene.target, up=[0.0, 0.0, 1.0])
    r_err, t_err = errors(scene.reference_from_target, result.transform)
    assert r_err < 2e-3 and t_err < 1e-2


def test_bad_input() -> None:
    good, _ = two_sensor_corner(POSES[0], seed=1)
    with pytest.raises(ValueError, match="at least 9"):
        lidarcal.calibrate_planes(np.zeros((5, 3)), good)
    with pytest.raises(ValueError, match=r"target must have shape \(N, 3\) or \(N, 4\)"):
        lidarcal.calibrate_planes(good, np.zeros((100, 2)))
    nan = good.copy()
    nan[10, 0] = np.nan
    with pytest.raises(ValueError, match=r"reference contains 1 non-finite.*row 10"):
        lidarcal.calibrate_planes(nan, good)
    with pytest.raises(ValueError, match="distance_threshold must be finite and positive"):
        lidarcal.calibrate_planes(good, good, distance_threshold=-1.0)
    with pytest.raises(ValueError, match="up must be a"):
        lidarcal.calibrate_planes(good, good, up=[0.0, 1.0])
    with pytest.raises(ValueError, match="loss must be"):
        lidarcal.calibrate_planes(good, good, loss="l2")  # type: ignore[arg-type]
    blob = np.random.default_rng(0).normal(size=(3000, 3))
    with pytest.raises(lidarcal.CalibrationError, match="no clearly planar surface"):
        lidarcal.calibrate_planes(blob, blob)


def test_real_pair_against_the_authors_result() -> None:
    """The seed's own RS-LiDAR-16 pair. The authors' estimate is trusted to ~0.5 deg / 5 cm;
    lidarcal lands 1.38 deg / 5.9 cm from it (see CHANGELOG, Known issues: the upper storey of one
    facade is a slightly different surface). The bound below guards that result."""
    appearance = require("lidar_appearance_calibration")
    reference = np.load(appearance / "ref_filter.npy")
    target = np.load(appearance / "data_filter.npy")
    truth = np.array(
        json.loads((appearance / "reference_extrinsics.json").read_text())["data_to_ref_eps_opt"][
            "matrix_4x4"
        ]
    )
    result = lidarcal.calibrate_planes(reference, target)
    r_err, t_err = errors(truth, result.transform)
    assert np.degrees(r_err) < 2.0 and t_err < 0.08, (np.degrees(r_err), t_err)
    assert result.refinement.converged
    assert np.all(result.rmse < 0.05)
