"""Parity of lidarcal's Rust kernels with the NumPy reference in reference.py."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

import lidarcal
import reference as ref
from lidarcal import _lidarcal

RNG_SEED = 20261122


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(RNG_SEED)


def random_pose(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    phi = axis * (rng.uniform(0, np.pi) if angle is None else angle)
    return ref.se3_exp(np.concatenate([rng.uniform(-3, 3, 3), phi]))


def rotation_error(a: np.ndarray, b: np.ndarray) -> float:
    return ref.rotation_angle(a @ b.T)


# --- Kabsch -------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3, 10, 1000])
def test_kabsch_matches_reference(rng: np.random.Generator, n: int) -> None:
    for _ in range(20):
        r_true = Rotation.random(random_state=rng).as_matrix()
        b = rng.normal(size=(n, 3))
        a = b @ r_true.T + 0.05 * rng.normal(size=(n, 3))
        w = rng.uniform(0.1, 2.0, n)
        for weights in (None, w):
            got = lidarcal.kabsch(a, b, weights)
            want = ref.kabsch(a, b, weights)
            assert np.abs(got - want).max() < 1e-10
            assert np.allclose(got @ got.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(got) == pytest.approx(1.0, abs=1e-12)


def test_kabsch_reflection_and_float32(rng: np.random.Generator) -> None:
    b = rng.normal(size=(50, 3))
    a = b * np.array([1.0, 1.0, -1.0])  # a mirror image: the best rotation is not a reflection
    got = lidarcal.kabsch(a, b)
    assert np.linalg.det(got) == pytest.approx(1.0)
    assert np.abs(got - ref.kabsch(a, b)).max() < 1e-10
    r_true = Rotation.random(random_state=rng).as_matrix()
    b32 = rng.normal(size=(100, 3)).astype(np.float32)
    a32 = (b32.astype(np.float64) @ r_true.T).astype(np.float32)
    got32 = lidarcal.kabsch(a32, b32)
    assert got32.dtype == np.float64
    assert rotation_error(got32, r_true) < 1e-6  # float32 inputs carry ~1e-7 relative error
    assert np.abs(got32 - ref.kabsch(a32.astype(float), b32.astype(float))).max() < 1e-10


# --- Lie groups ---------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 1e-3, 0.5, 2.0, 3.0, np.pi - 1e-6])
def test_so3_and_se3_match_reference(rng: np.random.Generator, angle: float) -> None:
    for _ in range(10):
        t = random_pose(rng, angle)
        xi = ref.se3_log(t)
        assert np.abs(lidarcal.so3_exp(xi[3:]) - ref.so3_exp(xi[3:])).max() < 1e-12
        assert np.abs(lidarcal.so3_log(t[:3, :3]) - ref.so3_log(t[:3, :3])).max() < 1e-10
        assert np.abs(lidarcal.se3_exp(xi) - ref.se3_exp(xi)).max() < 1e-12
        assert np.abs(lidarcal.se3_log(t) - xi).max() < 1e-9
        # Independent check: the exponential of the 4x4 twist matrix.
        twist = np.zeros((4, 4))
        twist[:3, :3] = ref.hat(xi[3:])
        twist[:3, 3] = xi[:3]
        assert np.abs(lidarcal.se3_exp(xi) - expm(twist)).max() < 1e-11


def test_log_exp_round_trip_near_pi(rng: np.random.Generator) -> None:
    for _ in range(50):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        r = ref.so3_exp(axis * (np.pi - 10 ** rng.uniform(-12, -3)))
        back = lidarcal.so3_exp(lidarcal.so3_log(r))
        assert rotation_error(back, r) < 1e-12


# --- Residuals and Jacobians --------------------------------------------------------------


@pytest.mark.parametrize("frame", ["target", "reference"])
def test_plane_residuals_and_jacobians(rng: np.random.Generator, frame: str) -> None:
    t = random_pose(rng)
    plane = np.concatenate([rng.normal(size=3), [1.3]])
    pts = rng.uniform(-5, 5, (200, 3))
    r, j = _lidarcal.point_to_plane_residuals(pts, plane, t, frame)
    r_ref, j_ref = ref.plane_residuals(pts, plane, t, frame)
    assert np.abs(r - r_ref).max() < 1e-12
    assert np.abs(j - j_ref).max() < 1e-12
    # The reference's analytic Jacobian against central differences.
    num = ref.numeric_jacobian(lambda tt: ref.plane_residuals(pts, plane, tt, frame)[0], t)
    assert np.abs(num - j).max() < 1e-6


@pytest.mark.parametrize("frame", ["target", "reference"])
def test_line_residuals_and_jacobians(rng: np.random.Generator, frame: str) -> None:
    t = random_pose(rng)
    line = np.concatenate([rng.normal(size=3), rng.normal(size=3)])
    pts = rng.uniform(-5, 5, (200, 3))
    r, j = _lidarcal.point_to_line_residuals(pts, line, t, frame)
    r_ref, j_ref = ref.line_residuals(pts, line, t, frame)
    assert r.shape == (200, 2) and j.shape == (200, 2, 6)
    assert np.abs(r - r_ref).max() < 1e-12
    assert np.abs(j - j_ref).max() < 1e-12
    num = ref.numeric_jacobian(lambda tt: ref.line_residuals(pts, line, tt, frame)[0], t)
    assert np.abs(num - j).max() < 1e-6


# --- Solves -------------------------------------------------------------------------------


def corner_problem(
    rng: np.random.Generator, n: int = 1500, sigma: float = 0.02
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[str], np.ndarray]:
    """Three planes seen by both sensors; symmetric groups (target and reference points)."""
    t_true = random_pose(rng)
    planes_ref = np.array(
        [[-1.0, 0.15, 0.0, 5.0], [0.1, -1.0, 0.05, 4.0], [0.0, 0.05, 1.0, 1.8]], dtype=float
    )
    planes_ref /= np.linalg.norm(planes_ref[:, :3], axis=1, keepdims=True)
    t_inv = np.linalg.inv(t_true)
    planes, points, frames = [], [], []
    for pl in planes_ref:
        n_, d = pl[:3], pl[3]
        e1, e2 = ref.orthonormal_basis(n_)
        on = (-d * n_) + rng.uniform(-3, 3, (n, 1)) * e1 + rng.uniform(-3, 3, (n, 1)) * e2
        noisy_ref = on + sigma * rng.normal(size=(n, 1)) * n_
        noisy_tgt = ref.transform_points(t_inv, on + sigma * rng.normal(size=(n, 1)) * n_)
        # Target points against the reference plane...
        planes.append(pl)
        points.append(noisy_tgt)
        frames.append("target")
        # ...and reference points against the same plane expressed in the target frame.
        m = t_inv[:3, :3] @ n_
        planes.append(np.concatenate([m, [d - m @ t_inv[:3, 3]]]))
        points.append(noisy_ref)
        frames.append("reference")
    start = ref.se3_exp(np.array([0.2, -0.25, 0.15, 0.06, 0.05, -0.06])) @ t_true
    return t_true, np.array(planes), points, frames, start


@pytest.mark.parametrize("loss", ["squared", "huber", "cauchy"])
def test_point_to_plane_solve_matches_scipy(rng: np.random.Generator, loss: str) -> None:
    t_true, planes, points, frames, start = corner_problem(rng)
    scale = 0.03
    res = lidarcal.refine_point_to_plane(
        planes, points, start, frames=frames, loss=loss, loss_scale=scale
    )
    t_ref, cost_ref = ref.solve_planes(planes, points, frames, start, loss, scale)
    assert res.converged
    assert rotation_error(res.transform[:3, :3], t_ref[:3, :3]) < 1e-6
    assert np.linalg.norm(res.transform[:3, 3] - t_ref[:3, 3]) < 1e-6
    assert res.cost == pytest.approx(cost_ref, rel=1e-9)
    # The reported cost is the reference cost at lidarcal's own solution.
    at_ours = ref.plane_cost(res.transform, planes, points, frames, loss, scale)
    assert res.cost == pytest.approx(at_ours, rel=1e-12)
    assert res.initial_cost == pytest.approx(
        ref.plane_cost(start, planes, points, frames, loss, scale), rel=1e-12
    )
    # And both are close to the truth (the noise is 2 cm on 9000 points).
    assert rotation_error(res.transform[:3, :3], t_true[:3, :3]) < 2e-3
    assert np.linalg.norm(res.transform[:3, 3] - t_true[:3, 3]) < 1e-2


def test_point_to_line_solve_matches_scipy(rng: np.random.Generator) -> None:
    t_true = random_pose(rng, 0.8)
    lines_ref = np.array(
        [[0, 0, 0, 0, 0, 1], [2, 0, 0, 0, 1, 0.2], [0, 3, 1, 1, 0, 0.1]], dtype=float
    )
    t_inv = np.linalg.inv(t_true)
    points = []
    for ln in lines_ref:
        s = rng.uniform(-2, 2, (300, 1))
        on = ln[:3] + s * ln[3:] / np.linalg.norm(ln[3:])
        points.append(ref.transform_points(t_inv, on + 0.01 * rng.normal(size=on.shape)))
    frames = ["target"] * 3
    start = ref.se3_exp(np.array([0.1, -0.1, 0.05, 0.05, -0.04, 0.03])) @ t_true
    res = lidarcal.refine_point_to_line(lines_ref, points, start)
    t_ref, cost_ref = ref.solve_lines(lines_ref, points, frames, start)
    assert res.converged
    assert rotation_error(res.transform[:3, :3], t_ref[:3, :3]) < 1e-6
    assert np.linalg.norm(res.transform[:3, 3] - t_ref[:3, 3]) < 1e-6
    assert res.cost == pytest.approx(cost_ref, rel=1e-9)
    assert res.cost == pytest.approx(
        ref.line_cost(res.transform, lines_ref, points, frames), rel=1e-12
    )


def test_covariance_is_consistent_with_hessian(rng: np.random.Generator) -> None:
    _, planes, points, frames, start = corner_problem(rng, n=500)
    res = lidarcal.refine_point_to_plane(planes, points, start, frames=frames)
    cov = res.covariance
    assert cov is not None
    sigma2 = 2 * res.cost / (res.residual_count - 6)
    assert np.allclose(cov @ res.hessian, sigma2 * np.eye(6), atol=1e-9 * sigma2)
