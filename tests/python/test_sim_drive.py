"""lidarcal.sim.drive_scene: shapes and dtypes, ground truth, determinism, options and errors."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from lidarcal import sim

FRAMES = 6


@functools.cache
def _drive(**kwargs: object) -> sim.DriveScene:
    options: dict[str, object] = {"seed": 2, "frames": FRAMES, "rate_hz": 1.0, **kwargs}
    return sim.drive_scene(**options)  # type: ignore[arg-type]


def _world(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    world: np.ndarray = points[:, :3] @ pose[:3, :3].T + pose[:3, 3]
    return world


def test_shapes_dtypes_and_repr() -> None:
    drive = _drive()
    assert len(drive) == FRAMES
    for frames, labels in [
        (drive.reference_frames, drive.reference_labels),
        (drive.target_frames, drive.target_labels),
    ]:
        assert len(frames) == len(labels) == FRAMES
        for points, label in zip(frames, labels, strict=True):
            assert points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 4
            assert label.dtype == np.int64 and label.shape == (len(points),)
            assert len(points) > 10_000
            assert not points.flags.writeable
    assert drive.reference_from_target.shape == (4, 4)
    assert drive.world_from_reference.shape == (FRAMES, 4, 4)
    assert drive.world_from_target.shape == (FRAMES, 4, 4)
    np.testing.assert_allclose(drive.times, np.arange(FRAMES) / 1.0)
    text = repr(drive)
    assert text.startswith("DriveScene(frames=6") and "field_of_view_deg=120" in text


def test_truth_is_consistent() -> None:
    drive = _drive()
    t = drive.reference_from_target
    assert np.allclose(t[:3, :3] @ t[:3, :3].T, np.eye(3))
    # The rear unit is about 4.3 m behind the front one and looks backward.
    assert -5.0 < t[0, 3] < -3.5 and t[0, 0] < -0.99
    np.testing.assert_allclose(drive.world_from_target, drive.world_from_reference @ t, atol=1e-12)
    for k in range(FRAMES):
        for points, labels, pose in [
            (drive.reference_frames[k], drive.reference_labels[k], drive.world_from_reference[k]),
            (drive.target_frames[k], drive.target_labels[k], drive.world_from_target[k]),
        ]:
            world = _world(points, pose)
            ground = labels == 0
            assert ground.sum() > 1000
            # 1 cm range noise along beams that are at most 25 degrees from level.
            assert np.abs(world[ground, 2]).max() < 0.05
            assert np.all(world[~ground, 2] > -0.05)


def test_fields_of_view_and_no_common_points() -> None:
    drive = _drive()
    for frames in (drive.reference_frames, drive.target_frames):
        for points in frames:
            azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
            assert np.abs(azimuth).max() <= 60.0 + 1e-9
    for k in range(FRAMES):
        front = _world(drive.reference_frames[k], drive.world_from_reference[k])
        rear = _world(drive.target_frames[k], drive.world_from_target[k])
        # In the front unit's frame everything it sees is ahead of everything the rear one sees.
        inv = np.linalg.inv(drive.world_from_reference[k])
        ahead = _world(front, inv)[:, 0].min()
        behind = _world(rear, inv)[:, 0].max()
        assert ahead - behind > 0.5, (k, ahead, behind)


def test_determinism() -> None:
    a = _drive()
    b = sim.drive_scene(seed=2, frames=FRAMES, rate_hz=1.0)
    for x, y in zip(
        a.reference_frames + a.target_frames, b.reference_frames + b.target_frames, strict=True
    ):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.world_from_reference, b.world_from_reference)
    c = sim.drive_scene(seed=3, frames=2)
    assert not np.array_equal(c.reference_from_target, a.reference_from_target)


def test_planar_motion_and_no_ground() -> None:
    drive = _drive(body_motion=False, ground=False)
    poses = drive.world_from_reference
    np.testing.assert_allclose(poses[:, 2, 3], poses[0, 2, 3], atol=1e-12)
    # Only the yaw changes: the world z of each of the unit's axes stays the same.
    np.testing.assert_allclose(poses[:, 2, :3], np.tile(poses[0, 2, :3], (FRAMES, 1)), atol=1e-12)
    for labels in drive.reference_labels + drive.target_labels:
        assert np.all(labels != 0)
    moving = _drive()
    assert np.ptp(moving.world_from_reference[:, 2, 3]) > 1e-3
    # Same town, mounting and route: only the body's motion differs.
    np.testing.assert_array_equal(moving.reference_from_target, drive.reference_from_target)
    np.testing.assert_allclose(poses[:, :2, 3], moving.world_from_reference[:, :2, 3], atol=0.1)


def test_options() -> None:
    narrow = sim.drive_scene(seed=2, frames=2, field_of_view_deg=60.0, range_noise=0.0)
    assert len(narrow.reference_frames[0]) < len(_drive().reference_frames[0])
    rear = narrow.target_frames[1]
    azimuth = np.degrees(np.arctan2(rear[:, 1], rear[:, 0]))
    assert np.abs(azimuth).max() <= 30.0 + 1e-9


@pytest.mark.parametrize(
    "kwargs",
    [
        {"frames": 1},
        {"frames": 3001},
        {"rate_hz": 0.0},
        {"rate_hz": 1000.0},
        {"rate_hz": float("nan")},
        {"field_of_view_deg": 0.0},
        {"field_of_view_deg": 361.0},
        {"range_noise": -0.1},
    ],
)
def test_bad_options_raise(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        sim.drive_scene(**kwargs)  # type: ignore[arg-type]
