"""Property tests (hypothesis): calibrations transform as the frames do, swapping the clouds
inverts the result, and results do not depend on the number of threads, in processes or in
Python threads."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import numpy.typing as npt
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import lidarcal
from lidarcal import sim

F64 = npt.NDArray[np.float64]
SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@functools.cache
def scene() -> tuple[F64, F64, F64]:
    s = sim.corner_scene("vlp16", seed=1, wall_angle_deg=75)
    return s.reference[:, :3].copy(), s.target[:, :3].copy(), s.reference_from_target


@functools.cache
def base() -> F64:
    ref, tgt, _ = scene()
    return lidarcal.calibrate_planes(ref, tgt).transform


def transform(points: F64, t: F64) -> F64:
    return points @ t[:3, :3].T + t[:3, 3]


def pose_gap(a: F64, b: F64) -> tuple[float, float]:
    """Rotation (rad) and translation (m) of inv(a) @ b."""
    d = np.linalg.inv(a) @ b
    angle = float(np.linalg.norm(lidarcal.so3_log(d[:3, :3])))
    return angle, float(np.linalg.norm(d[:3, 3]))


# A frame change of the target sensor: any rotation, and a translation small enough (0.5 m) that
# the new origin stays on the sensor's side of every wall (normals are oriented toward the origin,
# which the method assumes is the sensor).
twists = st.tuples(
    st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5),
    st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0),
).filter(lambda x: np.linalg.norm(x[3:]) < np.pi and np.linalg.norm(x[:3]) < 0.5)  # fmt: skip


@SETTINGS
@given(twists)
def test_moving_the_target_frame_moves_the_result_by_exactly_that(xi: tuple[float, ...]) -> None:
    ref, tgt, _ = scene()
    new_from_target = lidarcal.se3_exp(np.array(xi))
    got = lidarcal.calibrate_planes(ref, transform(tgt, new_from_target)).transform
    expected = base() @ np.linalg.inv(new_from_target)
    rot, trans = pose_gap(expected, got)
    assert rot < 1e-6 and trans < 1e-6, (rot, trans)


@SETTINGS
@given(twists)
def test_moving_the_reference_frame_moves_the_result_by_exactly_that(xi: tuple[float, ...]) -> None:
    ref, tgt, _ = scene()
    new_from_reference = lidarcal.se3_exp(np.array(xi))
    got = lidarcal.calibrate_planes(transform(ref, new_from_reference), tgt).transform
    expected = new_from_reference @ base()
    rot, trans = pose_gap(expected, got)
    assert rot < 1e-6 and trans < 1e-6, (rot, trans)


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_swapping_reference_and_target_inverts_the_result(seed: int) -> None:
    ref, tgt, truth = scene()
    forward = lidarcal.calibrate_planes(ref, tgt, seed=seed).transform
    backward = lidarcal.calibrate_planes(tgt, ref, seed=seed).transform
    rot, trans = pose_gap(forward, np.linalg.inv(backward))
    assert rot < 1e-6 and trans < 1e-6, (rot, trans)
    rot, trans = pose_gap(truth, forward)
    assert rot < 2e-3 and trans < 0.02, (rot, trans)


CHILD = """
import json, sys
import numpy as np, lidarcal
from lidarcal import sim
out = {}
s = sim.corner_scene("hdl64", seed=2, wall_angle_deg=75)
out["planes"] = lidarcal.calibrate_planes(s.reference, s.target).transform.tobytes().hex()
p = sim.poles_scene("vlp16", seed=3)
out["poles"] = lidarcal.calibrate_poles(p.reference, p.target).transform.tobytes().hex()
big = s.reference[:, :3]
out["ransac"] = lidarcal.ransac_plane(big, 0.05, seed=7).coefficients.tobytes().hex()
json.dump(out, sys.stdout)
"""


def test_results_are_bit_identical_on_one_and_two_threads() -> None:
    results = []
    for threads in ("1", "2"):
        env = dict(os.environ, RAYON_NUM_THREADS=threads)
        done = subprocess.run(
            [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True
        )
        results.append(json.loads(done.stdout))
    assert results[0] == results[1]


def _calibrate(seed: int) -> F64:
    s = sim.corner_scene("vlp16", seed=seed, wall_angle_deg=70 + seed)
    return lidarcal.calibrate_planes(s.reference, s.target, seed=seed).transform


def test_eight_python_threads_give_the_serial_results() -> None:
    seeds = list(range(8))
    serial = [_calibrate(s) for s in seeds]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(_calibrate, seeds))
    for a, b in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(a, b)
