"""One source of defaults: a keyword whose default lives in Rust takes None everywhere in Python.

``_lidarcal._defaults()`` reports, per function, the Rust ``Default`` (or constant) each such
keyword takes. These tests hold everything else to it: the runtime signatures, the stubs and the
Python forwarders (``lidarcal.sim``, ``lidarcal.calibrate``, ``calibrate_rig`` and
``refine_pose_graph``) show ``None`` (or, where None means something else, the same value),
the docstrings state the right value, and leaving a keyword out gives the same result as passing
the Rust value explicitly.
"""

from __future__ import annotations

import ast
import functools
import inspect
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import lidarcal
from lidarcal import _lidarcal, sim

DEFAULTS: dict[str, dict[str, Any]] = _lidarcal._defaults()
STUB = Path(__file__).resolve().parents[2] / "python" / "lidarcal" / "_lidarcal.pyi"

# The Python functions that forward to a function of the extension module.
WRAPPERS: dict[str, Callable[..., Any]] = {
    "calibrate_auto": lidarcal.calibrate,
    "calibrate_rig": lidarcal.calibrate_rig,
    "refine_pose_graph": lidarcal.refine_pose_graph,
    "Shape.rectangle": sim.rectangle,
    "Shape.cuboid": sim.cuboid,
    "Shape.cylinder": sim.cylinder,
    "sim_scan": sim.scan,
    "sim_corner_scene": sim.corner_scene,
    "sim_poles_scene": sim.poles_scene,
    "sim_street_scene": sim.street_scene,
    "sim_paper_scene": sim.paper_scene,
}

# Literal defaults that are this API's own choices, with no Rust default to agree with.
PYTHON_CHOICES = {
    "name",  # BeamModel.custom's label
    "with_ring",  # an output column
    "loss_scale",  # only read by huber/cauchy, whose Rust variants carry their own scale
    "count",  # extract_planes' three planes ...
    "distance_threshold",  # ... at 5 cm: a Rust caller always passes both
}


def _runtime(name: str) -> Any:
    obj: Any = _lidarcal
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def _stub_functions() -> dict[str, ast.FunctionDef]:
    tree = ast.parse(STUB.read_text())
    found: dict[str, ast.FunctionDef] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            found[node.name] = node
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    found[f"{node.name}.{item.name}"] = item
    return found


STUBS = _stub_functions()


def _stub_defaults(node: ast.FunctionDef) -> dict[str, Any]:
    """Keyword -> default as written in the stub (``...`` for Ellipsis)."""
    args = node.args
    positional = args.posonlyargs + args.args
    with_default = positional[len(positional) - len(args.defaults) :]
    pairs = list(zip(with_default, args.defaults, strict=True))
    pairs += [
        (a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults, strict=True) if d is not None
    ]
    return {a.arg: ast.literal_eval(d) for a, d in pairs}


def _signature_defaults(func: Callable[..., Any]) -> dict[str, Any]:
    return {
        name: p.default
        for name, p in inspect.signature(func).parameters.items()
        if p.default is not inspect.Parameter.empty
    }


def _fmt(value: Any) -> str:
    """A default as the docstrings write it: ``90`` for 90.0, ``(20, 70)``, ``'vlp16'``."""
    if isinstance(value, bool | str):
        return repr(value)
    if isinstance(value, tuple):
        return "(" + ", ".join(_fmt(v) for v in value) + ")"
    return f"{value:g}"


def _signatures(name: str) -> dict[str, dict[str, Any]]:
    found = {
        "runtime": _signature_defaults(_runtime(name)),
        "stub": _stub_defaults(STUBS[name]),
    }
    if name in WRAPPERS:
        found["wrapper"] = _signature_defaults(WRAPPERS[name])
    return found


def _docs(name: str) -> dict[str, str]:
    found = {
        "runtime": _runtime(name).__doc__ or "",
        "stub": ast.get_docstring(STUBS[name]) or "",
    }
    if name in WRAPPERS:
        found["wrapper"] = WRAPPERS[name].__doc__ or ""
    return found


def test_the_table_covers_the_functions_that_take_rust_defaults() -> None:
    assert set(WRAPPERS) <= set(DEFAULTS)
    assert {"check", "ransac_plane", "extract_planes", "refine_point_to_plane"} <= set(DEFAULTS)
    assert {
        "calibrate_planes",
        "calibrate_poles",
        "calibrate_targetless",
        "calibrate_auto",
        "calibrate_rig",
        "refine_pose_graph",
        "overlap",
    } <= set(DEFAULTS)
    for name, table in DEFAULTS.items():
        assert name in STUBS, f"{name} has no stub"
        assert table, f"{name}: empty table"


@pytest.mark.parametrize("name", sorted(DEFAULTS))
def test_signatures_take_none_or_the_rust_value(name: str) -> None:
    rust = DEFAULTS[name]
    for where, defaults in _signatures(name).items():
        for keyword, value in defaults.items():
            if keyword in rust:
                # `...`: the stub of a default PyO3 cannot render (configuration=Some(1)).
                assert value is None or value is Ellipsis or value == rust[keyword], (
                    f"{where} {name}({keyword}={value!r}) but Rust says {rust[keyword]!r}"
                )
            else:
                assert value is None or keyword in PYTHON_CHOICES, (
                    f"{where} {name}({keyword}={value!r}): a literal default with no Rust source"
                )
        missing = set(rust) - set(defaults)
        assert not missing, f"{where} {name}: no default for {sorted(missing)}"


@pytest.mark.parametrize("name", sorted(DEFAULTS))
def test_docstrings_state_the_rust_defaults(name: str) -> None:
    rust = DEFAULTS[name]
    user_doc = "wrapper" if name in WRAPPERS else "stub"
    user_signature = _signatures(name)[user_doc]
    docs = _docs(name)
    for keyword, value in rust.items():
        if user_signature[keyword] is None and value is not None:
            assert f"``{keyword}={_fmt(value)}``" in docs[user_doc], (
                f"the {user_doc} docstring of {name} does not say {keyword}={_fmt(value)}"
            )
        # Wherever a docstring says what the default is, it is the Rust value (a paragraph that
        # speaks of defaults; examples calling the function are other paragraphs).
        pattern = re.compile(rf"\b{keyword}=(\(.*?\)|'[^']*'|[-+\w.]+)")
        for where, doc in docs.items():
            about_defaults = [p for p in doc.split("\n\n") if "efault" in p]
            for said in pattern.findall("\n".join(about_defaults)):
                said = said.rstrip(".")
                assert said in (_fmt(value), "None"), (
                    f"the {where} docstring of {name} says {keyword}={said}, Rust {_fmt(value)}"
                )


# --- leaving a keyword out gives what passing the Rust value gives -------------------------------


def _scene_arrays(scene: Any) -> list[np.ndarray]:
    return [scene.reference, scene.target, scene.reference_from_target, scene.planes]


def _scan_shape(shape: Any) -> np.ndarray:
    pose = np.eye(4)
    pose[2, 3] = 1.5
    return _lidarcal.sim_scan([shape], "vlp16", pose, seed=3)


def _plane_rows(planes: list[Any]) -> list[np.ndarray]:
    return [np.append(p.coefficients, p.inliers) for p in planes]


def _refine_inputs() -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(0)
    normals = np.eye(3)
    planes = np.hstack([normals, -np.ones((3, 1))])
    points = []
    for n in normals:
        p = rng.uniform(-2, 2, (40, 3))
        p[:, np.argmax(n)] = 1.0
        points.append(p + rng.normal(0, 0.005, p.shape))
    initial = _lidarcal.se3_exp([0.05, -0.03, 0.02, 0.01, 0.02, -0.01])
    return planes, points, initial


@functools.cache
def _corner() -> Any:
    return _lidarcal.sim_corner_scene(seed=2, clutter_boxes=0)


@functools.cache
def _skewed_corner() -> Any:
    """A corner the planar method orders without ``up`` (walls not at a right angle)."""
    return _lidarcal.sim_corner_scene(seed=2, clutter_boxes=0, wall_angle_deg=75.0)


@functools.cache
def _poles() -> Any:
    return _lidarcal.sim_poles_scene(seed=1)


@functools.cache
def _street() -> Any:
    return _lidarcal.sim_street_scene(seed=1)


def _calibrated(result: Any) -> list[Any]:
    return [result.transform, result.rmse, result.method]


def _pose_graph() -> tuple[np.ndarray, list[tuple[int, int, np.ndarray, np.ndarray]]]:
    """Three nodes, measured edges a little off the poses, every edge weighted alike."""
    truth = [np.eye(4), _translation(1.0, 0.0, 0.0), _translation(0.0, 2.0, 0.5)]
    kicks = [[0.01, 0, 0, 0, 0.002, 0], [0, -0.02, 0.01, 0.003, 0, 0], [0, 0, 0.02, 0, 0, -0.002]]
    edges = [
        (a, b, np.linalg.inv(truth[a]) @ truth[b] @ _lidarcal.se3_exp(k), np.eye(6))
        for (a, b), k in zip([(0, 1), (1, 2), (0, 2)], kicks, strict=True)
    ]
    start = np.stack([truth[0], truth[1] @ _translation(0.05, 0, 0), truth[2]])
    return start, edges


# name -> a call taking the keywords under test, and what of its result to compare.
CALLS: dict[str, Callable[..., Any]] = {
    "BeamModel.custom": lambda **kw: [
        [m.columns, m.min_range, m.max_range, m.range_noise, *m.elevations_deg]
        for m in [_lidarcal.BeamModel.custom([-10.0, 0.0, 10.0], **kw)]
    ],
    "Shape.rectangle": lambda **kw: _scan_shape(
        _lidarcal.Shape.rectangle([-9, -9, 0], [18, 0, 0], [0, 18, 0], **kw)
    ),
    "Shape.cuboid": lambda **kw: _scan_shape(
        _lidarcal.Shape.cuboid([2.0, 2.0, 2.0], _translation(4.0, 0.0, 1.0), **kw)
    ),
    "Shape.cylinder": lambda **kw: _scan_shape(
        _lidarcal.Shape.cylinder([3, 0, 0], [0, 0, 1], 3.0, 0.2, band=(0.5, 2.5), **kw)
    ),
    "sim_scan": lambda **kw: _lidarcal.sim_scan(
        [_lidarcal.Shape.rectangle([-9, -9, -1.5], [18, 0, 0], [0, 18, 0])], **kw
    ),
    "sim_corner_scene": lambda **kw: _scene_arrays(_lidarcal.sim_corner_scene(**kw)),
    "sim_poles_scene": lambda **kw: _scene_arrays(_lidarcal.sim_poles_scene(**kw)),
    "sim_street_scene": lambda **kw: _scene_arrays(_lidarcal.sim_street_scene(**kw)),
    "sim_paper_scene": lambda **kw: _scene_arrays(_lidarcal.sim_paper_scene(**kw)),
    "check": lambda **kw: sorted(
        (k, str(v))
        for k, v in _lidarcal.check(
            _corner().reference, _corner().target, _corner().reference_from_target, **kw
        )
        .to_dict()
        .items()
    ),
    "ransac_plane": lambda **kw: _plane_rows(
        [_lidarcal.ransac_plane(_corner().reference, 0.05, **kw)]
    ),
    "ransac_line": lambda **kw: [
        np.append(np.append(line.point, line.direction), line.inliers)
        for line in [_lidarcal.ransac_line(_line_points([0, 0, 0], [0, 0, 1]), 0.02, **kw)]
    ],
    "extract_planes": lambda **kw: _plane_rows(
        _lidarcal.extract_planes(_corner().reference, 3, 0.05, **kw)
    ),
    "refine_point_to_plane": lambda **kw: (
        _lidarcal.refine_point_to_plane(*_refine_inputs(), **kw).transform
    ),
    "calibrate_planes": lambda **kw: _calibrated(
        _lidarcal.calibrate_planes(_skewed_corner().reference, _skewed_corner().target, **kw)
    ),
    "calibrate_poles": lambda **kw: _calibrated(
        _lidarcal.calibrate_poles(_poles().reference, _poles().target, **kw)
    ),
    "calibrate_targetless": lambda **kw: _calibrated(
        _lidarcal.calibrate_targetless(_street().reference, _street().target, **kw)
    ),
    # Through the Python forwarders, which pass None on.
    "calibrate_auto": lambda **kw: _calibrated(
        lidarcal.calibrate(_poles().reference, _poles().target, **kw)
    ),
    "calibrate_rig": lambda **kw: [
        pose
        for rig in [
            lidarcal.calibrate_rig(_skewed_corner().reference, [_skewed_corner().target], **kw)
        ]
        for pose in (rig.transforms["target0"], rig.pose_graph.iterations)
    ],
    "refine_pose_graph": lambda **kw: lidarcal.refine_pose_graph(*_pose_graph(), **kw),
    "overlap": lambda **kw: [
        _lidarcal.overlap(
            _corner().reference, _corner().target, _corner().reference_from_target, **kw
        )
    ],
    "refine_point_to_line": lambda **kw: (
        _lidarcal.refine_point_to_line(
            np.array([[0, 0, 0, 0, 0, 1.0], [0, 0, 1, 1, 0, 0.0]]),
            [_line_points([0, 0, 0], [0, 0, 1]), _line_points([0, 0, 1], [1, 0, 0])],
            _lidarcal.se3_exp([0.05, -0.03, 0.02, 0.01, 0.02, -0.01]),
            **kw,
        ).transform
    ),
}


def _translation(x: float, y: float, z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = [x, y, z]
    return pose


def _line_points(point: list[float], direction: list[float]) -> np.ndarray:
    """200 noisy points along a line and 50 scattered ones."""
    rng = np.random.default_rng(1)
    on_line = np.outer(rng.uniform(-3, 3, 200), direction) + point
    on_line += rng.normal(0, 0.005, on_line.shape)
    return np.vstack([on_line, rng.uniform(-3, 3, (50, 3))])


def test_every_function_in_the_table_has_a_call() -> None:
    assert set(CALLS) == set(DEFAULTS)


@pytest.mark.parametrize("name", sorted(DEFAULTS))
def test_omitting_a_keyword_equals_passing_the_rust_value(name: str) -> None:
    explicit = {k: v for k, v in DEFAULTS[name].items() if v is not None}
    left_out = CALLS[name]()
    passed = CALLS[name](**explicit)
    for a, b in zip(left_out, passed, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_calibrate_method_left_out_is_the_rust_default() -> None:
    scene = _skewed_corner()
    left_out = lidarcal.calibrate(scene.reference, scene.target)
    passed = lidarcal.calibrate(scene.reference, scene.target, DEFAULTS["calibrate_rig"]["method"])
    assert left_out.method == passed.method
    np.testing.assert_array_equal(left_out.transform, passed.transform)
