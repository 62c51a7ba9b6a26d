"""lidarcal.refine_pose_graph (Rust, central differences, halving line search) against the NumPy
reference (forward differences, plain Gauss-Newton), its argument checks, and the pose-graph
report of calibrate_rig."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import lidarcal
import reference as ref
from lidarcal import sim


def _random_pose(rng: np.random.Generator, t_scale: float, r_scale: float) -> np.ndarray:
    xi = np.concatenate([rng.normal(0, t_scale, 3), rng.normal(0, r_scale, 3)])
    return ref.se3_exp(xi)


def _graph(
    seed: int, nodes: int, noise_t: float, noise_r: float
) -> tuple[list[np.ndarray], list[tuple[int, int, np.ndarray, np.ndarray]], list[np.ndarray]]:
    """True poses, noisy measurements of every pair (a complete graph) with random SPD weights,
    and the start: the true poses disturbed."""
    rng = np.random.default_rng(seed)
    truth = [np.eye(4)] + [_random_pose(rng, 2.0, 0.5) for _ in range(nodes - 1)]
    edges = []
    for a in range(nodes):
        for b in range(a + 1, nodes):
            z = np.linalg.inv(truth[a]) @ truth[b]
            z = _random_pose(rng, noise_t, noise_r) @ z
            # A coupled SPD information of a realistic size: ~1 cm and ~0.1 degree.
            m = rng.normal(size=(6, 6))
            d = np.diag([100.0] * 3 + [500.0] * 3)
            w = d @ (m @ m.T + 6 * np.eye(6)) @ d
            edges.append((a, b, z, (w + w.T) / 2))
    start = [truth[0]] + [_random_pose(rng, 0.02, 0.01) @ t for t in truth[1:]]
    return truth, edges, start


@pytest.mark.parametrize("seed", range(5))
def test_parity_with_numpy_reference(seed: int) -> None:
    _, edges, start = _graph(seed, nodes=4, noise_t=0.03, noise_r=0.005)
    ours = lidarcal.refine_pose_graph(np.stack(start), edges)
    theirs = ref.refine_pose_graph(start, edges)
    assert ours.shape == (4, 4, 4)
    np.testing.assert_array_equal(ours[0], start[0])
    for a, b in zip(ours, theirs, strict=True):
        # Both minimise the same cost; they differ only by the Jacobians' finite differences.
        np.testing.assert_allclose(a, b, atol=1e-7)

    def cost(poses: list[np.ndarray] | np.ndarray) -> float:
        total = 0.0
        for i, j, z, w in edges:
            e = ref.pose_graph_edge_error(z, poses[i], poses[j])
            total += float(e @ w @ e)
        return total

    assert cost(ours) < cost(start)


def test_consistent_measurements_are_recovered_exactly() -> None:
    truth, edges, start = _graph(7, nodes=3, noise_t=0.0, noise_r=0.0)
    ours = lidarcal.refine_pose_graph(np.stack(start), edges)
    for a, b in zip(ours, truth, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)


def test_bad_graphs() -> None:
    eye = np.eye(4)
    w = np.eye(6)
    with pytest.raises(ValueError, match=r"shape \(K, 4, 4\)"):
        lidarcal.refine_pose_graph(np.zeros((2, 3, 3)), [])
    with pytest.raises(ValueError, match="edge 0 joins nodes 0 and 5"):
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 5, eye, w)])
    with pytest.raises(ValueError, match="node 2 is in no edge"):
        lidarcal.refine_pose_graph(np.stack([eye, eye, eye]), [(0, 1, eye, w)])
    with pytest.raises(ValueError, match="symmetric"):
        bad = np.eye(6)
        bad[0, 1] = 1.0
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 1, eye, bad)])
    with pytest.raises(ValueError, match="non-finite"):
        nan = np.eye(6)
        nan[2, 2] = np.nan
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 1, eye, nan)])
    with pytest.raises(ValueError, match=r"shape \(6, 6\)"):
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 1, eye, np.eye(5))])
    with pytest.raises(ValueError, match=r"last row of a 4x4 transform"):
        lidarcal.refine_pose_graph(np.stack([eye, 2 * eye]), [(0, 1, eye, w)])
    with pytest.raises(ValueError, match=r"edges\[0\] a_from_b contains 16 non-finite"):
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 1, eye * np.nan, w)])
    with pytest.raises(ValueError, match="iterations"):
        lidarcal.refine_pose_graph(np.stack([eye, eye]), [(0, 1, eye, w)], iterations=-1)


def test_cost_never_rises_on_a_weakly_constrained_graph() -> None:
    """Rotation information of ~0.3 rad: plain Gauss-Newton (the NumPy reference) overshoots and
    its cost rises; the halving line search keeps every iteration's cost at or below the last."""
    rng = np.random.default_rng(0)
    _, edges, start = _graph(0, nodes=4, noise_t=0.03, noise_r=0.005)
    weak = []
    for a, b, z, _w in edges:
        m = rng.normal(size=(6, 6))
        w = m @ m.T + 6 * np.eye(6)
        w[:3, :3] *= 1e4
        weak.append((a, b, z, (w + w.T) / 2))

    def cost(poses: list[np.ndarray] | np.ndarray) -> float:
        return sum(
            float(e @ w @ e)
            for i, j, z, w in weak
            for e in [ref.pose_graph_edge_error(z, poses[i], poses[j])]
        )

    costs = [cost(lidarcal.refine_pose_graph(np.stack(start), weak, k)) for k in range(8)]
    assert costs[0] == pytest.approx(cost(start))
    assert all(b <= a * (1 + 1e-12) for a, b in itertools.pairwise(costs)), costs
    assert costs[-1] < 0.1 * costs[0]
    plain = [cost(ref.refine_pose_graph(start, weak, k)) for k in range(1, 8)]
    assert any(b > a for a, b in itertools.pairwise(plain)), plain


def test_rig_reports_its_pose_graph() -> None:
    """calibrate_rig's result says how the pose-graph refinement went: a simulated roof unit and
    two side units of one street, every edge consistent to the noise, so the graph settles."""
    left = sim.street_scene(seed=0, side="left")
    right = sim.street_scene(seed=0, side="right")
    rig = lidarcal.calibrate_rig(
        left.reference, {"left": left.target, "right": right.target}, method="targetless"
    )
    report = rig.pose_graph
    assert isinstance(report, lidarcal.PoseGraphReport)
    assert report.converged is True
    assert report.termination in ("step_tolerance", "no_further_decrease")
    assert isinstance(report.iterations, int) and 0 < report.iterations <= 20
    assert np.isfinite(report.initial_cost) and np.isfinite(report.final_cost)
    assert 0.0 <= report.final_cost <= report.initial_cost
