"""The bad-input battery: every malformed or degenerate input gets a ValueError,
lidarcal.CalibrationError or OSError whose message says what is wrong, never a crash, a hang or a
silent answer. The cases are data (``CASES``) so that ``benches/bad_input_table.py`` prints the
same battery as a table. Malformed files beyond those in test_io.py are here too.
"""

from __future__ import annotations

import functools
import struct
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

import lidarcal
from lidarcal import sim

F64 = npt.NDArray[np.float64]
CE = lidarcal.CalibrationError
FFE = lidarcal.FileFormatError


@functools.cache
def corner() -> tuple[F64, F64]:
    """A corner with unequal angles (no `up` needed): (reference, target) (N, 3)."""
    s = sim.corner_scene("vlp16", seed=1, wall_angle_deg=75)
    return s.reference[:, :3].copy(), s.target[:, :3].copy()


@functools.cache
def poles() -> tuple[F64, F64]:
    s = sim.poles_scene("vlp16", seed=1)
    return s.reference.copy(), s.target.copy()


def _plane(n: int, normal: list[float], offset: float, seed: int = 0) -> F64:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-5, 5, (n, 3))
    u = np.asarray(normal, float) / np.linalg.norm(normal)
    return p - ((p @ u) + offset)[:, None] * u


@functools.cache
def parallel_poles() -> F64:
    ground = sim.rectangle([-20, -20, -1.5], [40, 0, 0], [0, 40, 0])
    a = sim.cylinder([5, 1, -1.5], [0, 0, 1], 3.0, 0.1, band=(0.5, 2.5))
    b = sim.cylinder([5, -1.5, -1.5], [0, 0, 1], 3.0, 0.1, band=(0.5, 2.5))
    return sim.scan([ground, a, b], "vlp16", seed=3)


# One scratch folder for the whole module, removed when the interpreter exits:
# the cases below write hundreds of small files and must not leave them behind.
_SCRATCH = tempfile.TemporaryDirectory(prefix="lidarcal-bad-")


def _scratch(suffix: str = "") -> Path:
    """A fresh empty folder inside the module's scratch folder."""
    return Path(tempfile.mkdtemp(suffix=suffix, dir=_SCRATCH.name))


def _tmp(name: str, content: bytes) -> Path:
    path = _scratch() / name
    path.write_bytes(content)
    return path


def _pcd(fields: str, data: bytes, points: int, kind: str = "binary", count: str = "") -> bytes:
    names = fields.split()
    counts = count or " ".join("1" for _ in names)
    head = (
        f"VERSION .7\nFIELDS {fields}\nSIZE {' '.join('4' for _ in names)}\n"
        f"TYPE {' '.join('F' for _ in names)}\nCOUNT {counts}\n"
        f"WIDTH {points}\nHEIGHT 1\nPOINTS {points}\nDATA {kind}\n"
    )
    return head.encode() + data


PLY_HUGE = (
    b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000000\n"
    b"property float x\nproperty float y\nproperty float z\nend_header\n"
)
NPY_HEAD = "\x93NUMPY\x01\x00\x76\x00{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"


@dataclass(frozen=True)
class Case:
    """One bad input: what is called, the exception expected and a fragment of its message."""

    name: str
    call: Callable[[], Any]
    exception: type[BaseException]
    fragment: str


def planes(ref: Any, tgt: Any = None, **kw: Any) -> Callable[[], Any]:
    return lambda: lidarcal.calibrate_planes(
        ref() if callable(ref) else ref, corner()[1] if tgt is None else tgt, **kw
    )


def poles_call(ref: Any, **kw: Any) -> Callable[[], Any]:
    return lambda: lidarcal.calibrate_poles(ref() if callable(ref) else ref, poles()[1], **kw)


def _some(value: float) -> Callable[[], F64]:
    def make() -> F64:
        r = corner()[0].copy()
        r[[3, 10], 1] = value
        return r

    return make


def _blob(seed: int = 0) -> F64:
    return np.random.default_rng(seed).normal(size=(5000, 3))


CASES: list[Case] = [
    # --- calibrate_planes: array shape, dtype, values ---
    Case(
        "planes: empty",
        planes(np.zeros((0, 3))),
        ValueError,
        "has 0 points; three planes need at least 9",
    ),
    Case(
        "planes: 1-D",
        planes(np.zeros(30)),
        ValueError,
        "must have shape (N, 3) or (N, 4), got (30)",
    ),
    Case("planes: 2 columns", planes(np.zeros((30, 2))), ValueError, "got (30, 2)"),
    Case("planes: 5 columns", planes(np.zeros((30, 5))), ValueError, "got (30, 5)"),
    Case("planes: 3-D array", planes(np.zeros((3, 10, 3))), ValueError, "got (3, 10, 3)"),
    Case(
        "planes: object dtype",
        planes(np.array([[1, 2, None]] * 20, dtype=object)),
        ValueError,
        "got dtype object",
    ),
    Case(
        "planes: str dtype",
        planes(np.array([["a", "b", "c"]] * 20)),
        ValueError,
        "must hold real numbers",
    ),
    Case("planes: None", planes(None), ValueError, "must hold real numbers"),
    Case("planes: complex", planes(np.ones((30, 3), complex)), ValueError, "got dtype complex128"),
    Case(
        "planes: all NaN",
        planes(np.full((100, 3), np.nan)),
        ValueError,
        "300 non-finite value(s) (NaN or inf); the first is in row 0",
    ),
    Case(
        "planes: some NaN",
        planes(_some(np.nan)),
        ValueError,
        "2 non-finite value(s) (NaN or inf); the first is in row 3",
    ),
    Case("planes: some inf", planes(_some(-np.inf)), ValueError, "2 non-finite value(s)"),
    Case(
        "planes: 5 points",
        planes(lambda: corner()[0][:5]),
        ValueError,
        "has 5 points; three planes need at least 9",
    ),
    Case(
        "planes: 20 points",
        planes(lambda: corner()[0][:20]),
        CE,
        "only 0 plane(s) with at least 50 inliers",
    ),
    Case("planes: identical points", planes(np.ones((1000, 3))), CE, "collinear or coincident"),
    Case(
        "planes: collinear points",
        planes(np.outer(np.linspace(0, 10, 1000), [1, 2, 3])),
        CE,
        "collinear or coincident",
    ),
    Case(
        "planes: one plane only",
        planes(lambda: _plane(3000, [0, 0, 1], 1.5)),
        CE,
        "only 1 plane(s) with at least 50 inliers",
    ),
    Case(
        "planes: two parallel planes",
        planes(
            lambda: np.vstack([_plane(3000, [1, 0, 0], -3), _plane(3000, [1, 0, 0], 3, seed=1)])
        ),
        CE,
        "discarded as parallel",
    ),
    Case("planes: Gaussian blob", planes(_blob), CE, "no clearly planar surface"),
    Case(
        "planes: blob, threshold given",
        planes(_blob, _blob(1), distance_threshold=0.05),
        CE,
        # Planes forced out of a random blob: the robust refinement cannot settle between them.
        "the robust refinement did not settle",
    ),
    Case(
        "planes: coordinates 1e300",
        planes(lambda: corner()[0] * 1e300),
        ValueError,
        "beyond +/-1e8 m",
    ),
    Case(
        "planes: coordinates 1e30",
        planes(lambda: corner()[0] * 1e30),
        ValueError,
        "no LiDAR return is that far",
    ),
    Case(
        "planes: one point at 1.7e308",
        planes(lambda: np.vstack([corner()[0], [[1.7e308, 0, 0]]])),
        ValueError,
        "1 point(s) with a coordinate beyond",
    ),
    Case(
        "planes: coordinates 1e-300",
        planes(lambda: corner()[0] * 1e-300),
        CE,
        "collinear or coincident",
    ),
    Case(
        "planes: threshold 0",
        planes(corner()[0] if False else (lambda: corner()[0]), distance_threshold=0.0),
        ValueError,
        "distance_threshold must be finite and positive, got 0",
    ),
    Case(
        "planes: threshold -1",
        planes(lambda: corner()[0], distance_threshold=-1.0),
        ValueError,
        "got -1",
    ),
    Case(
        "planes: threshold NaN",
        planes(lambda: corner()[0], distance_threshold=float("nan")),
        ValueError,
        "got NaN",
    ),
    Case(
        "planes: reference not in its sensor's frame (shifted 100 m)",
        planes(lambda: corner()[0] + [100.0, 0.0, 0.0]),
        ValueError,
        "must be in its own sensor's frame",
    ),
    Case(
        "planes: seed -1",
        planes(lambda: corner()[0], seed=-1),
        ValueError,
        "seed must be an integer in [0, 2**64), got -1",
    ),
    Case(
        "planes: seed 2.5",
        planes(lambda: corner()[0], seed=2.5),
        ValueError,
        "seed must be an integer in [0, 2**64), got 2.5",
    ),
    Case(
        "planes: threshold 100 m",
        planes(lambda: corner()[0], distance_threshold=100.0),
        CE,
        "only 1 plane(s) with at least 50 inliers within 100.000 m",
    ),
    Case(
        "planes: loss scale 0",
        planes(lambda: corner()[0], loss="huber", loss_scale=0.0),
        ValueError,
        "loss scale must be finite and positive",
    ),
    Case(
        "planes: huber without scale",
        planes(lambda: corner()[0], loss="huber"),
        ValueError,
        "needs loss_scale",
    ),
    Case(
        "planes: unknown loss",
        planes(lambda: corner()[0], loss="l1"),
        ValueError,
        "loss must be 'auto'",
    ),
    Case(
        "planes: up zero",
        planes(lambda: corner()[0], up=[0, 0, 0]),
        ValueError,
        "up vectors must be finite and non-zero",
    ),
    Case(
        "planes: up (4,)",
        planes(lambda: corner()[0], up=[0, 0, 1, 0]),
        ValueError,
        "up must be a (3,) vector",
    ),
    Case(
        "planes: max_iterations 0",
        planes(lambda: corner()[0], max_iterations=0),
        ValueError,
        "max_iterations must be at least 1",
    ),
    Case(
        "planes: time budget 0",
        planes(lambda: corner()[0], time_budget_s=0.0),
        ValueError,
        "time_budget_s must be finite and positive",
    ),
    Case(
        "planes: time budget 1 us",
        planes(lambda: corner()[0], time_budget_s=1e-6),
        CE,
        "time budget of 0.000 s exhausted",
    ),
    Case(
        "planes: cube corner without up",
        lambda: lidarcal.calibrate_planes(
            *[
                c[:, :3]
                for c in (
                    sim.corner_scene("vlp16", seed=1).reference,
                    sim.corner_scene("vlp16", seed=1).target,
                )
            ]
        ),
        CE,
        "ambiguous plane correspondence",
    ),
    # --- calibrate_poles ---
    Case(
        "poles: no intensity column",
        poles_call(lambda: poles()[0][:, :3]),
        ValueError,
        "needs an (N, 4) array with intensity",
    ),
    Case("poles: empty", poles_call(np.zeros((0, 4))), ValueError, "has 0 points; the pole"),
    Case(
        "poles: NaN intensity",
        poles_call(
            lambda: np.where(
                np.arange(len(poles()[0]))[:, None] == 3, [0, 0, 0, np.nan], poles()[0]
            )
        ),
        ValueError,
        "1 NaN or infinite intensity value(s); the first is in row 3",
    ),
    Case(
        "poles: NaN coordinate",
        poles_call(
            lambda: np.where(
                np.arange(len(poles()[0]))[:, None] == 4, [np.nan, 0, 0, 1], poles()[0]
            )
        ),
        ValueError,
        "NaN or infinite coordinates; the first is row 4",
    ),
    Case(
        "poles: no bright points",
        poles_call(lambda: np.hstack([poles()[0][:, :3], np.zeros((len(poles()[0]), 1))])),
        CE,
        "no clear class of bright",
    ),
    Case(
        "poles: all points bright",
        poles_call(lambda: np.hstack([poles()[0][:, :3], np.full((len(poles()[0]), 1), 255.0)])),
        CE,
        "no clear class of bright",
    ),
    Case(
        "poles: a handful of points",
        poles_call(lambda: poles()[0][:5]),
        CE,
        "bright point(s) at or above intensity",
    ),
    Case(
        "poles: everything bright",
        poles_call(lambda: np.hstack([_blob(), np.full((5000, 1), 250.0)]), vendor="velodyne"),
        CE,
        "100.0 % of the returns as tape",
    ),
    Case(
        "poles: bright Gaussian blob",
        poles_call(
            lambda: np.hstack([_blob(), np.full((5000, 1), 250.0)]),
            vendor="velodyne",
            max_bright_fraction=1.0,
        ),
        CE,
        "compact bright blob",
    ),
    Case(
        "poles: max_bright_fraction 0",
        poles_call(lambda: poles()[0], max_bright_fraction=0.0),
        ValueError,
        "max_bright_fraction must be in (0, 1]",
    ),
    Case("poles: parallel poles", poles_call(parallel_poles), CE, "parallel"),
    Case(
        "poles: coordinates 1e300",
        poles_call(lambda: poles()[0] * [1e300, 1e300, 1e300, 1]),
        ValueError,
        "beyond +/-1e8 m",
    ),
    Case(
        "poles: cluster tolerance 0",
        poles_call(lambda: poles()[0], cluster_tolerance=0.0),
        ValueError,
        "cluster_tolerance must be finite and positive, got 0",
    ),
    Case(
        "poles: cluster tolerance -1",
        poles_call(lambda: poles()[0], cluster_tolerance=-1.0),
        ValueError,
        "got -1",
    ),
    Case(
        "poles: radius 0",
        poles_call(lambda: poles()[0], pole_radius=0.0),
        ValueError,
        "pole_radius must be finite and positive",
    ),
    Case(
        "poles: intensity threshold NaN",
        poles_call(lambda: poles()[0], intensity_threshold=float("nan")),
        ValueError,
        "intensity_threshold must be finite",
    ),
    Case(
        "poles: threshold above all",
        poles_call(lambda: poles()[0], intensity_threshold=1e9),
        CE,
        "only 0 bright point(s)",
    ),
    Case(
        "poles: unknown vendor",
        poles_call(lambda: poles()[0], vendor="sick"),
        ValueError,
        "vendor must be one of",
    ),
    Case(
        "poles: min_points 1",
        poles_call(lambda: poles()[0], min_points=1),
        ValueError,
        "min_points must be at least 6",
    ),
    Case(
        "poles: unknown axis_fit",
        poles_call(lambda: poles()[0], axis_fit="plane"),
        ValueError,
        "axis_fit must be 'cylinder' or 'line'",
    ),
    # --- kernels ---
    Case(
        "ransac_plane: empty",
        lambda: lidarcal.ransac_plane(np.zeros((0, 3)), 0.05),
        ValueError,
        "a plane needs at least 3 points, got 0",
    ),
    Case(
        "ransac_plane: threshold 0",
        lambda: lidarcal.ransac_plane(corner()[0], 0.0),
        ValueError,
        "distance_threshold must be finite and positive",
    ),
    Case(
        "ransac_plane: threshold -1",
        lambda: lidarcal.ransac_plane(corner()[0], -1.0),
        ValueError,
        "got -1",
    ),
    Case(
        "ransac_plane: identical points",
        lambda: lidarcal.ransac_plane(np.ones((100, 3)), 0.05),
        ValueError,
        "collinear or coincident",
    ),
    Case(
        "ransac_plane: collinear",
        lambda: lidarcal.ransac_plane(np.outer(np.linspace(0, 1, 100), [1, 1, 1]), 0.05),
        ValueError,
        "collinear or coincident",
    ),
    Case(
        "ransac_plane: coordinates 1e38",
        lambda: lidarcal.ransac_plane(corner()[0] * 1e38, 1e36),
        ValueError,
        "beyond +/-1e8 m",
    ),
    Case(
        "ransac_plane: confidence 1",
        lambda: lidarcal.ransac_plane(corner()[0], 0.05, confidence=1.0),
        ValueError,
        "confidence must be in (0, 1)",
    ),
    Case(
        "ransac_line: identical points",
        lambda: lidarcal.ransac_line(np.ones((100, 3)), 0.05),
        ValueError,
        "coincident",
    ),
    Case(
        "ransac_line: 1 point",
        lambda: lidarcal.ransac_line(np.eye(3)[:1], 0.05),
        ValueError,
        "a line needs at least 2 points",
    ),
    Case(
        "extract_planes: count 0",
        lambda: lidarcal.extract_planes(corner()[0], 0),
        ValueError,
        "count must be at least 1",
    ),
    Case(
        "extract_planes: threshold 0",
        lambda: lidarcal.extract_planes(corner()[0], 3, 0.0),
        ValueError,
        "distance_threshold must be finite and positive",
    ),
    Case(
        "extract_planes: angle -1",
        lambda: lidarcal.extract_planes(corner()[0], 3, min_angle_deg=-1.0),
        ValueError,
        "min_angle_deg must be in (0, 90)",
    ),
    Case(
        "extract_planes: identical",
        lambda: lidarcal.extract_planes(np.ones((1000, 3)), 3),
        CE,
        "only 0 plane(s)",
    ),
    Case(
        "kabsch: empty",
        lambda: lidarcal.kabsch(np.zeros((0, 3)), np.zeros((0, 3))),
        ValueError,
        "at least 2 vector pairs",
    ),
    Case(
        "kabsch: zero vectors",
        lambda: lidarcal.kabsch(np.zeros((5, 3)), np.zeros((5, 3))),
        ValueError,
        "do not determine a rotation",
    ),
    Case(
        "kabsch: (N, 2)",
        lambda: lidarcal.kabsch(np.zeros((3, 2)), np.zeros((3, 2))),
        ValueError,
        "a must have shape (N, 3)",
    ),
    Case(
        "kabsch: inf weight",
        lambda: lidarcal.kabsch(np.eye(3), np.eye(3), [1, np.inf, 1]),
        ValueError,
        "weights contains 1 non-finite",
    ),
    Case(
        "so3_exp: norm 1e300",
        lambda: lidarcal.so3_exp([1e300, 0, 0]),
        ValueError,
        "too large: the result is not finite",
    ),
    Case(
        "se3_exp: norm 1e300",
        lambda: lidarcal.se3_exp([0, 0, 0, 1e300, 0, 0]),
        ValueError,
        "too large",
    ),
    Case(
        "refine: points 1e200",
        lambda: lidarcal.refine_point_to_plane(np.array([[0, 0, 1.0, 0]]), [np.eye(3) * 1e200]),
        ValueError,
        "points of plane group 0 has 3 point(s) with a coordinate beyond",
    ),
    Case(
        "rqe: sigma 0",
        lambda: lidarcal.metrics.rqe(corner()[0], 0.0),
        ValueError,
        "sigma must be finite and positive",
    ),
    # --- files (test_io.py has the basic malformed-file battery) ---
    Case(
        "read: missing file",
        lambda: lidarcal.read_points("/nonexistent/cloud.pcd"),
        FileNotFoundError,
        "No such file",
    ),
    Case(
        "read: directory",
        lambda: lidarcal.read_points(_scratch(suffix=".ply")),
        IsADirectoryError,
        ".ply",
    ),
    Case(
        "read: garbage .ply",
        lambda: lidarcal.read_points(_tmp("a.ply", b"\x00\xff" * 64)),
        FFE,
        "not a PLY",
    ),
    Case(
        "read: truncated LZF stream",
        lambda: lidarcal.read_points(
            _tmp(
                "a.pcd",
                _pcd("x y z", struct.pack("<II", 30, 24) + b"\x1f\x00", 2, "binary_compressed"),
            )
        ),
        FFE,
        "truncated",
    ),
    Case(
        "read: LZF back-reference before start",
        lambda: lidarcal.read_points(
            _tmp(
                "a.pcd",
                _pcd("x y z", struct.pack("<II", 3, 24) + b"\xe0\x10\x00", 2, "binary_compressed"),
            )
        ),
        FFE,
        "corrupt LZF",
    ),
    Case(
        "read: COUNT 2e18",
        lambda: lidarcal.read_points(
            _tmp("a.pcd", _pcd("x y z", b"", 1, count="1 1 2222222222222222221"))
        ),
        FFE,
        "values per point",
    ),
    Case(
        "read: POINTS 1e18, no data",
        lambda: lidarcal.read_points(_tmp("a.pcd", _pcd("x y z", b"", 10**18))),
        FFE,
        "truncated",
    ),
    Case(
        "read: PLY vertex count 1e18",
        lambda: lidarcal.read_points(
            _tmp(
                "a.ply",
                PLY_HUGE,
            )
        ),
        FFE,
        "truncated",
    ),
    Case(
        "read: truncated npy",
        lambda: lidarcal.read_points(
            _tmp(
                "a.npy",
                NPY_HEAD.format(shape="(100, 3)").encode("latin-1") + b" " * 50 + b"\n" + bytes(16),
            )
        ),
        FFE,
        "truncated",
    ),
    Case(
        "read: npy (N, 2)",
        lambda: lidarcal.read_points(
            _tmp(
                "a.npy",
                NPY_HEAD.format(shape="(1, 2)").encode("latin-1") + b" " * 52 + b"\n" + bytes(16),
            )
        ),
        FFE,
        "(N, K)",
    ),
    Case(
        "read: unknown field",
        lambda: lidarcal.read_points(_tmp("a.csv", b"1,2,3\n"), ["ring"]),
        ValueError,
        'no field "ring"',
    ),
    Case(
        "read: fields is a string",
        lambda: lidarcal.read_points(_tmp("a.csv", b"1,2,3\n"), "x"),
        ValueError,
        "fields must be None",
    ),
    Case(
        "write: values beyond float32",
        lambda: lidarcal.write_points(_scratch() / "a.ply", np.full((2, 3), 1e300)),
        ValueError,
        "does not fit the float32",
    ),
    Case(
        "write: duplicate names",
        lambda: lidarcal.write_points(_scratch() / "a.pcd", np.zeros((2, 3)), ["x", "x", "z"]),
        ValueError,
        "appears twice",
    ),
    Case(
        "write: NaN",
        lambda: lidarcal.write_points(_scratch() / "a.pcd", np.full((2, 3), np.nan)),
        ValueError,
        "non-finite",
    ),
    Case(
        "write: 1-D",
        lambda: lidarcal.write_points(_scratch() / "a.pcd", np.zeros(3)),
        ValueError,
        "2-D array (N, K) with K >= 3",
    ),
    Case(
        "write: missing directory",
        lambda: lidarcal.write_points("/nonexistent/dir/a.pcd", np.zeros((2, 3))),
        FileNotFoundError,
        "No such file",
    ),
    Case(
        "write: unknown extension",
        lambda: lidarcal.write_points(_scratch() / "a.las", np.zeros((2, 3))),
        ValueError,
        "unknown point-cloud extension",
    ),
]


def run_case(case: Case) -> tuple[str, str]:
    """Runs a case; returns (exception type name, message), or ("(no exception)", repr)."""
    try:
        result = case.call()
    except Exception as e:
        return type(e).__name__, str(e)
    return "(no exception)", repr(result)[:200]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input(case: Case) -> None:
    with pytest.raises(case.exception) as info:
        case.call()
    message = str(info.value)
    assert case.fragment in message, message
    # No internal error (a panic turned into RuntimeError) may hide behind a CalibrationError.
    assert "internal error" not in message


def test_case_names_are_unique() -> None:
    assert len({c.name for c in CASES}) == len(CASES)


def test_good_scenes_calibrate() -> None:
    """The scenes the battery corrupts are good ones: unmodified, they calibrate."""
    ref, tgt = corner()
    assert lidarcal.calibrate_planes(ref, tgt).refinement.converged
    pr, pt = poles()
    assert lidarcal.calibrate_poles(pr, pt).refinement.converged


def test_time_budget_stops_a_pathological_clustering() -> None:
    """A tolerance that joins a whole dense cloud makes the clustering quadratic (seconds here,
    tens of minutes at a million points); the budget stops it with a clear error, early."""
    import time

    scene = sim.poles_scene("hdl64", seed=1)
    start = time.perf_counter()
    with pytest.raises(CE, match=r"time budget of 0\.200 s exhausted during clustering"):
        lidarcal.calibrate_poles(
            scene.reference,
            scene.target,
            intensity_threshold=0.0,
            max_bright_fraction=1.0,  # else refused at once: every return would be "tape"
            cluster_tolerance=5.0,
            time_budget_s=0.2,
        )
    assert time.perf_counter() - start < 5.0
    # A generous budget changes nothing.
    pr, pt = poles()
    a = lidarcal.calibrate_poles(pr, pt)
    b = lidarcal.calibrate_poles(pr, pt, time_budget_s=600.0)
    np.testing.assert_array_equal(a.transform, b.transform)
