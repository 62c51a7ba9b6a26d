"""Calibration from a drive: lidarcal.odometry and lidarcal.calibrate_sequence on simulated
drives whose units never see the same thing at the same time, and their bad-input errors."""

from __future__ import annotations

import numpy as np
import pytest

import lidarcal
from lidarcal import sim

FRAMES = 100  # 10 s at 10 Hz: two turns


def errors(truth: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    r = truth[:3, :3] @ est[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))
    return angle, float(np.linalg.norm(truth[:3, 3] - est[:3, 3]))


@pytest.fixture(scope="module")
def drive() -> sim.DriveScene:
    return sim.drive_scene(4, frames=FRAMES)


@pytest.fixture(scope="module")
def result(drive: sim.DriveScene) -> lidarcal.SequenceResult:
    return lidarcal.calibrate_sequence(drive.reference_frames, drive.target_frames)


def test_drive_is_calibrated_to_the_issue_tolerance(drive, result) -> None:
    rot, trans = errors(drive.reference_from_target, result.transform)
    assert rot < 0.2 and trans < 0.03, (rot, trans)
    assert result.method == "sequence"
    assert result.converged and result.fitness > 0.2 and result.rmse < 0.05
    # Hand-eye alone leaves the height unobserved on flat ground; the map alignment fixed it.
    assert result.unobserved_by_motion is not None
    assert abs(result.unobserved_by_motion[2]) > 0.9
    assert set(result.timings) == {"odometry", "hand_eye", "align"}
    assert result.reference_poses.shape == (FRAMES, 4, 4)
    assert result.target_poses.shape == (FRAMES, 4, 4)
    assert "SequenceResult(" in repr(result)


def test_the_trajectories_are_the_true_ones(drive, result) -> None:
    first = np.linalg.inv(drive.world_from_reference[0])
    for k in (10, FRAMES // 2, FRAMES - 1):
        rot, trans = errors(first @ drive.world_from_reference[k], result.reference_poses[k])
        assert rot < 0.5 and trans < 0.01 * result.distance + 0.05, (k, rot, trans)
    # Rigidity: the target's trajectory is the reference's seen through the extrinsic.
    t = result.transform
    k = FRAMES - 1
    mapped = np.linalg.inv(t) @ result.reference_poses[k] @ t
    rot, trans = errors(mapped, result.target_poses[k])
    assert rot < 0.5 and trans < 0.5, (rot, trans)


def test_odometry_matches_the_calibration_poses(drive, result) -> None:
    poses = lidarcal.odometry(drive.reference_frames[:30])
    assert poses.shape == (30, 4, 4) and poses.dtype == np.float64
    np.testing.assert_allclose(poses[0], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(poses, result.reference_poses[:30], atol=1e-9)


def test_single_frame_methods_refuse_a_drive_frame(drive) -> None:
    with pytest.raises(lidarcal.CalibrationError):
        lidarcal.calibrate(drive.reference_frames[50], drive.target_frames[50])


def test_a_standing_vehicle_is_unobservable(drive) -> None:
    ref = [drive.reference_frames[0]] * 20
    tgt = [drive.target_frames[0]] * 20
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_sequence(ref, tgt)
    assert info.value.kind == "unobservable"
    assert "standing" in str(info.value)


def test_a_straight_drive_is_unobservable(drive) -> None:
    # The first 3 s of every drive are straight.
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_sequence(drive.reference_frames[:30], drive.target_frames[:30])
    assert info.value.kind == "unobservable"


def test_bad_input(drive) -> None:
    ref, tgt = drive.reference_frames[:12], drive.target_frames[:12]
    with pytest.raises(ValueError, match="same number of frames"):
        lidarcal.calibrate_sequence(ref, tgt[:11])
    with pytest.raises(ValueError, match="at least 10 frames"):
        lidarcal.calibrate_sequence(ref[:5], tgt[:5])
    nan = [f.copy() for f in tgt]
    nan[3][7, 1] = np.nan
    with pytest.raises(ValueError, match=r"target_frames\[3\]"):
        lidarcal.calibrate_sequence(ref, nan)
    with pytest.raises(ValueError, match="shape"):
        lidarcal.calibrate_sequence(ref, [f[:, :2] for f in tgt])
    with pytest.raises(TypeError, match="list of"):
        lidarcal.calibrate_sequence(ref[0], tgt[0])
    with pytest.raises(ValueError, match="strides"):
        lidarcal.calibrate_sequence(ref, tgt, strides=[0])
    with pytest.raises(ValueError, match="voxel"):
        lidarcal.odometry(ref, voxel=-1.0)
    with pytest.raises(ValueError, match="at least 2 frames"):
        lidarcal.odometry(ref[:1])
    with pytest.raises(ValueError, match="frame 1 has"):
        lidarcal.odometry([ref[0], ref[1][:10]])
    with pytest.raises(ValueError, match="seed"):
        lidarcal.calibrate_sequence(ref, tgt, seed=-1)


def test_unsynchronized_frames_are_refused(drive) -> None:
    # The target's frames one frame (0.7 m of driving) late: the map alignment would absorb it
    # into the extrinsic; the gate against hand-eye refuses instead.
    with pytest.raises(lidarcal.CalibrationError) as info:
        lidarcal.calibrate_sequence(drive.reference_frames[:-1], drive.target_frames[1:])
    assert info.value.kind in ("no_agreement", "unobservable")
