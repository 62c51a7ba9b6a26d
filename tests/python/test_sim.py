"""lidarcal.sim: shapes and dtypes, ground truth, determinism and errors."""

from __future__ import annotations

import numpy as np
import pytest

import lidarcal
from lidarcal import sim


def _pose(z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[2, 3] = z
    return pose


def test_scan_over_ground_matches_ring_elevations() -> None:
    ground = sim.rectangle([-100, -100, 0], [200, 0, 0], [0, 200, 0], intensity=(5.0, 40.0))
    model = sim.BeamModel("vlp16")
    pts = sim.scan([ground], model, _pose(2.0), seed=3, with_ring=True)
    assert pts.shape[1] == 5 and pts.dtype == np.float64
    rings = pts[:, 4].astype(int)
    for ring, elevation in enumerate(model.elevations_deg):
        ranges = np.linalg.norm(pts[rings == ring, :3], axis=1)
        expected = 2.0 / np.sin(np.radians(abs(elevation)))
        if elevation > 0 or expected > model.max_range:
            assert ranges.size == 0
        else:
            assert ranges.size == model.columns
            assert np.all(np.abs(ranges - expected) < 6 * model.range_noise)
    assert np.all((pts[:, 3] >= 5) & (pts[:, 3] <= 40))  # ground intensities


def test_cylinder_band_is_bright_and_on_surface() -> None:
    pole = sim.cylinder([4, 0, -1], [0, 0, 1], 3.0, 0.2, band=(1.0, 2.0))
    pts = sim.scan([pole], "os128", noise=0.0)
    radial = np.hypot(pts[:, 0] - 4.0, pts[:, 1])
    lateral = np.abs(radial - 0.2) < 1e-9
    assert lateral.mean() > 0.95
    band = (pts[:, 2] > 0.0 + 1e-6) & (pts[:, 2] < 1.0 - 1e-6)
    assert np.all(pts[band & lateral, 3] >= 235)
    assert np.all(pts[~band & lateral & (pts[:, 2] < -0.01), 3] <= 80)


@pytest.mark.parametrize("kind", ["corner", "poles", "paper"])
def test_scenes_ground_truth_and_determinism(kind: str) -> None:
    def make(seed: int) -> sim.Scene:
        if kind == "corner":
            return sim.corner_scene("vlp16", seed=seed)
        if kind == "poles":
            return sim.poles_scene("vlp16", seed=seed, distractor=True)
        return sim.paper_scene(75.0, None, seed)

    scene = make(4)
    again = make(4)
    assert np.array_equal(scene.reference, again.reference)
    assert np.array_equal(scene.target, again.target)
    assert np.array_equal(scene.reference_from_target, again.reference_from_target)
    assert not np.array_equal(scene.target, make(5).target)
    t = scene.reference_from_target
    assert t.shape == (4, 4) and np.allclose(t[:3, :3] @ t[:3, :3].T, np.eye(3))
    tgt = scene.target[:, :3] @ t[:3, :3].T + t[:3, 3]
    labels = scene.target_labels
    tol = 0.5 if kind == "paper" else 0.1  # 0.1 m isotropic / <= 0.015 m range noise
    for i, plane in enumerate(scene.planes):
        on = tgt[labels == i]
        assert len(on) > 100
        dist = on @ plane[:3] + plane[3]
        assert np.sqrt(np.mean(dist**2)) < tol / 4
        assert np.max(np.abs(dist)) < tol
    if kind == "poles":
        for k, (axis, radius) in enumerate(zip(scene.pole_axes, scene.pole_radii, strict=True)):
            on = tgt[labels == k + 1]
            rel = on - axis[:3]
            perp = rel - np.outer(rel @ axis[3:], axis[3:])
            radial = np.linalg.norm(perp, axis=1)
            assert np.median(np.abs(radial - radius)) < 0.01


def test_custom_model_and_repr() -> None:
    model = sim.BeamModel.custom([-10.0, 0.0, 10.0], columns=360, range_noise=0.0)
    assert model.beams == 3 and model.columns == 360
    assert "BeamModel(name='custom'" in repr(model)
    wall = sim.rectangle([5, -10, -5], [0, 20, 0], [0, 0, 10])
    pts = sim.scan([wall], model)
    assert np.allclose(pts[:, 0], 5.0)
    assert "Scene(kind='corner'" in repr(sim.corner_scene(seed=0, clutter_boxes=0))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: sim.scan([], "lux"), "unknown LiDAR model"),
        (lambda: sim.scan([], dropout=1.5), "dropout must be a probability"),
        (lambda: sim.scan([], noise=-1.0), "range noise"),
        (lambda: sim.scan([], sensor_pose=np.diag([2.0, 1, 1, 1])), "not orthonormal"),
        (lambda: sim.scan([object()]), r"shapes\[0\] is not"),  # type: ignore[list-item]
        (lambda: sim.cylinder([0, 0, 0], [0, 0, 1], 1.0, -0.1), "radius must be positive"),
        (lambda: sim.cylinder([0, 0, 0], [0, 0, 0], 1.0, 0.1), "zero length"),
        (lambda: sim.rectangle([0, 0, 0], [1, 0, 0], [1, 1, 0]), "orthogonal"),
        (lambda: sim.rectangle([0, 0, np.nan], [1, 0, 0], [0, 1, 0]), "non-finite"),
        (lambda: sim.BeamModel.custom([]), "at least one elevation"),
        (lambda: sim.poles_scene(radius=0.0), "pole radius"),
        (lambda: sim.paper_scene(configuration=3), "configuration must be 1, 2 or None"),
        (lambda: sim.paper_scene(alpha_deg=200.0), "alpha must be"),
        (lambda: sim.corner_scene(extra_walls=5), "extra_walls"),
    ],
)
def test_bad_input_raises_value_error(call: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()  # type: ignore[operator]


def test_write_pcd_binary_and_errors(tmp_path: pytest.TempPathFactory) -> None:
    pts = sim.scan([sim.rectangle([-5, -5, 0], [10, 0, 0], [0, 10, 0])], sensor_pose=_pose(1.0))
    path = tmp_path / "g.pcd"  # type: ignore[operator]
    sim.write_pcd(path, pts)
    raw = path.read_bytes()
    header, _, data = raw.partition(b"DATA binary\n")
    assert f"POINTS {len(pts)}".encode() in header
    back = np.frombuffer(data, dtype="<f4").reshape(-1, 4)
    assert np.allclose(back, pts, atol=1e-5)
    with pytest.raises(OSError, match="nonexistent"):
        sim.write_pcd("/nonexistent-lidarcal/x.pcd", pts)
    with pytest.raises(ValueError, match="ring"):
        sim.write_pcd(path, np.hstack([pts, np.full((len(pts), 1), 0.5)]))
    assert lidarcal.sim is sim
