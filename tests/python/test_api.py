"""The Python surface: types, argument checking, error messages, GIL release."""

from __future__ import annotations

import re
import threading
import time

import numpy as np
import pytest

import lidarcal


def test_version_and_exception_hierarchy() -> None:
    assert re.fullmatch(r"\d+\.\d+\.\d+.*", lidarcal.__version__)
    assert issubclass(lidarcal.CalibrationError, RuntimeError)
    assert lidarcal.CalibrationError.__module__ == "lidarcal"


def test_accepts_lists_ints_and_strided_arrays() -> None:
    b = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    assert np.allclose(lidarcal.kabsch(b, b), np.eye(3))
    big = np.eye(3)[:, ::-1].T  # a non-contiguous view
    assert not big.flags["C_CONTIGUOUS"] or not big.flags["F_CONTIGUOUS"]
    assert np.allclose(lidarcal.kabsch(big, big), np.eye(3))
    pts4 = np.hstack([np.eye(3), np.ones((3, 1))])  # (N, 4): intensity column ignored
    res = lidarcal.refine_point_to_plane(np.array([[1.0, 0, 0, -1.0]]), [pts4], max_iterations=1)
    assert res.transform.shape == (4, 4)


@pytest.mark.parametrize(
    ("a", "b", "message"),
    [
        (np.zeros((3, 2)), np.zeros((3, 2)), r"a must have shape \(N, 3\), got \(3, 2\)"),
        (np.zeros(3), np.zeros(3), r"a must have shape \(N, 3\), got \(3\)"),
        (np.zeros((2, 3, 3)), np.zeros((2, 3, 3)), r"got \(2, 3, 3\)"),
        (np.eye(3), np.eye(4)[:, :3], "same number of vectors, got 3 and 4"),
        (np.eye(3)[:1], np.eye(3)[:1], "at least 2 vector pairs"),
        (np.array([["a", "b", "c"]] * 3), np.eye(3), "must hold real numbers"),
        (None, np.eye(3), "must hold real numbers"),
        (
            np.array([[1, 0, 0], [2, 0, 0]]),
            np.array([[1, 0, 0], [3, 0, 0]]),
            "do not determine a rotation",
        ),
        (
            np.array([[np.nan, 0, 0], [0, 1, 0], [0, 0, np.inf]]),
            np.eye(3),
            r"2 non-finite value\(s\).*row 0",
        ),
    ],
)
def test_kabsch_bad_input(a: object, b: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        lidarcal.kabsch(a, b)  # type: ignore[arg-type]


def test_kabsch_bad_weights() -> None:
    e = np.eye(3)
    with pytest.raises(ValueError, match="non-negative"):
        lidarcal.kabsch(e, e, [1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="one entry per vector pair"):
        lidarcal.kabsch(e, e, [1.0, 1.0])
    with pytest.raises(ValueError, match="sum to zero"):
        lidarcal.kabsch(e, e, [0.0, 0.0, 0.0])


def test_lie_bad_input() -> None:
    with pytest.raises(ValueError, match=r"phi must have shape \(3,\)"):
        lidarcal.so3_exp(np.zeros(4))
    with pytest.raises(ValueError, match="not orthonormal"):
        lidarcal.so3_log(np.eye(3) * 2)
    with pytest.raises(ValueError, match="reflection"):
        lidarcal.so3_log(np.diag([1.0, 1.0, -1.0]))
    bad = np.eye(4)
    bad[3, 0] = 1.0
    with pytest.raises(ValueError, match=r"last row .* \[0, 0, 0, 1\]"):
        lidarcal.se3_log(bad)


def test_refine_bad_input() -> None:
    planes = np.array([[0.0, 0.0, 1.0, 0.0]])
    pts = np.zeros((5, 3))
    with pytest.raises(ValueError, match="one array per feature: 1 features, 2 arrays"):
        lidarcal.refine_point_to_plane(planes, [pts, pts])
    with pytest.raises(ValueError, match="frame must be 'target' or 'reference'"):
        lidarcal.refine_point_to_plane(planes, [pts], frames=["sideways"])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="loss must be"):
        lidarcal.refine_point_to_plane(planes, [pts], loss="l1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="robust loss scale must be finite and positive"):
        lidarcal.refine_point_to_plane(planes, [pts], loss="huber", loss_scale=0.0)
    with pytest.raises(ValueError, match="plane normal has zero length"):
        lidarcal.refine_point_to_plane(np.zeros((1, 4)), [pts])
    with pytest.raises(ValueError, match="group 0 has no points"):
        lidarcal.refine_point_to_plane(planes, [np.zeros((0, 3))])
    with pytest.raises(ValueError, match=r"planes must have shape \(K, 4\)"):
        lidarcal.refine_point_to_plane(np.zeros((1, 3)), [pts])
    with pytest.raises(ValueError, match="initial_transform"):
        lidarcal.refine_point_to_plane(planes, [pts], np.eye(4) * 2)
    with pytest.raises(ValueError, match="max_iterations must be at least 1"):
        lidarcal.refine_point_to_plane(planes, [pts], max_iterations=0)
    with pytest.raises(ValueError, match=r"points\[0\] contains 1 non-finite"):
        lidarcal.refine_point_to_plane(planes, [np.array([[0.0, np.nan, 0.0]])])


def test_iteration_cap_is_reported() -> None:
    rng = np.random.default_rng(1)
    planes = np.array([[1.0, 0, 0, -2.0], [0, 1.0, 0, -2.0], [0, 0, 1.0, 1.0]])
    pts = []
    for pl in planes:
        p = rng.uniform(-2, 2, (200, 3))
        pts.append(p - (p @ pl[:3] + pl[3])[:, None] * pl[:3])
    start = lidarcal.se3_exp([0.5, 0.5, 0.5, 0.3, 0.2, 0.1])
    res = lidarcal.refine_point_to_plane(planes, pts, start, max_iterations=1)
    assert not res.converged
    assert res.termination == "max_iterations"
    assert res.iterations == 1
    assert "converged=False" in repr(res)
    full = lidarcal.refine_point_to_plane(planes, pts, start)
    assert full.converged and full.cost < 1e-20
    assert np.allclose(full.transform, np.eye(4), atol=1e-9)


def test_gil_is_released_during_rust_work() -> None:
    """While a long refinement runs in a worker thread, the main thread keeps running Python."""
    rng = np.random.default_rng(2)
    planes = np.array([[1.0, 0, 0, -2.0], [0, 1.0, 0, -2.0], [0, 0, 1.0, 1.0]])
    pts = [rng.uniform(-2, 2, (400_000, 3)) for _ in planes]
    start = lidarcal.se3_exp([0.3, 0.2, 0.1, 0.1, 0.1, 0.1])
    span: dict[str, float] = {}

    def work() -> None:
        span["start"] = time.perf_counter()
        lidarcal.refine_point_to_plane(planes, pts, start, max_iterations=30)
        span["end"] = time.perf_counter()

    worker = threading.Thread(target=work)
    ticks: list[float] = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    during = [t for t in ticks if span["start"] < t < span["end"]]
    duration = span["end"] - span["start"]
    # With the GIL held the main loop would stall for the whole call; released, it keeps ticking.
    assert duration > 0.05, f"the call was too short ({duration:.3f} s) to show anything"
    assert len(during) >= 10, f"only {len(during)} main-thread ticks during a {duration:.3f} s call"
