"""Calibration results in the forms robotics stacks read.

* :func:`to_dict` -- a JSON-ready dictionary: the 4x4 ``reference_from_target``, translation,
  quaternion (x, y, z, w), roll-pitch-yaw, uncertainties and the method's diagnostics;
* :func:`write_result` -- ``.yaml`` / ``.json`` (that dictionary), ``.txt`` (the 4x4 matrix) or
  ``.urdf`` (a fixed ``<joint>`` whose origin is the transform), chosen by the extension;
* :func:`static_transform_publisher` -- the ``tf2_ros`` command that publishes the transform.

Angles follow ROS (REP 103): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, the convention of URDF
``rpy`` and of ``tf2``. The target frame is the child, the reference frame the parent.

>>> import numpy as np
>>> from lidarcal.export import quaternion_xyzw, rpy
>>> yaw90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
>>> np.round(quaternion_xyzw(yaw90), 6).tolist()
[0.0, 0.0, 0.707107, 0.707107]
>>> np.round(np.degrees(rpy(yaw90)), 6).tolist()
[0.0, -0.0, 90.0]
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import (
    CalibrationResult,
    PlanarDetails,
    PoleDetails,
    SequenceResult,
    TargetlessDetails,
)

F64Array = npt.NDArray[np.float64]

#: The extensions :func:`write_result` writes.
OUTPUT_SUFFIXES = (".yaml", ".yml", ".json", ".txt", ".urdf")

__all__ = [
    "OUTPUT_SUFFIXES",
    "frame_id",
    "quaternion_xyzw",
    "rpy",
    "static_transform_publisher",
    "to_dict",
    "to_yaml",
    "write_result",
]


def quaternion_xyzw(rotation: npt.ArrayLike) -> F64Array:
    """The unit quaternion ``[x, y, z, w]`` (``w >= 0``) of a 3x3 rotation matrix."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise ValueError(f"rotation must be 3x3, got shape {r.shape}")
    # Shepperd's method: divide by the largest of the four candidate components.
    trace = float(np.trace(r))
    diag = np.diag(r)
    k = int(np.argmax([trace, *diag]))
    if k == 0:
        w = 0.5 * math.sqrt(max(1.0 + trace, 0.0))
        q = [
            (r[2, 1] - r[1, 2]) / (4 * w),
            (r[0, 2] - r[2, 0]) / (4 * w),
            (r[1, 0] - r[0, 1]) / (4 * w),
            w,
        ]
    else:
        i = k - 1
        j, m = (i + 1) % 3, (i + 2) % 3
        s = 0.5 * math.sqrt(max(1.0 + 2.0 * diag[i] - trace, 0.0))
        q = [0.0, 0.0, 0.0, (r[m, j] - r[j, m]) / (4 * s)]
        q[i] = s
        q[j] = (r[j, i] + r[i, j]) / (4 * s)
        q[m] = (r[m, i] + r[i, m]) / (4 * s)
    out = np.array(q, dtype=np.float64)
    out /= np.linalg.norm(out)
    return -out if out[3] < 0 else out


def rpy(rotation: npt.ArrayLike) -> F64Array:
    """``[roll, pitch, yaw]`` in radians with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise ValueError(f"rotation must be 3x3, got shape {r.shape}")
    cos_pitch = math.hypot(r[0, 0], r[1, 0])
    pitch = math.atan2(-r[2, 0], cos_pitch)  # atan2 stays accurate near +-90 deg, asin does not
    if cos_pitch > 1e-12:
        roll = math.atan2(r[2, 1], r[2, 2])
        yaw = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: only roll -/+ yaw is determined; put it all in yaw
        roll = 0.0
        yaw = math.atan2(-r[0, 1], r[1, 1])
    return np.array([roll, pitch, yaw])


def _list(a: Any) -> Any:
    return None if a is None else np.asarray(a).tolist()


def to_dict(
    result: CalibrationResult | SequenceResult,
    *,
    reference: str | None = None,
    target: str | None = None,
    reference_frame: str | None = None,
    target_frame: str | None = None,
    transform: npt.ArrayLike | None = None,
) -> dict[str, Any]:
    """A JSON-ready summary of ``result``. ``reference`` / ``target`` name the clouds (files);
    ``reference_frame`` / ``target_frame`` are the frame ids for URDF and tf (default: the files'
    stems, cleaned to letters, digits and ``_``).

    ``transform`` reports another pose than ``result.transform`` (e.g. the one a rig's pose graph
    made of it): the pose fields are that transform, ``diagnostics["method_transform"]`` keeps
    the method's own, and the 1-sigma fields (which describe the method's pose) are left out.

    A :class:`~lidarcal.SequenceResult` (calibration from a drive) has the same pose fields; its
    ``rmse`` is the one map alignment's, ``[rmse]``, there is no ``check``, and its diagnostics
    are the drive's evidence (:func:`_sequence_diagnostics`)."""
    own = np.asarray(result.transform)
    t = own if transform is None else np.asarray(transform, dtype=np.float64)
    if t.shape != (4, 4):
        raise ValueError(f"transform must be 4x4, got shape {t.shape}")
    rotation, translation = t[:3, :3], t[:3, 3]
    angles = rpy(rotation)
    out: dict[str, Any] = {
        "reference": reference,
        "target": target,
        "reference_frame": reference_frame or _frame(reference, "reference"),
        "target_frame": target_frame or _frame(target, "target"),
        "method": result.method,
        "transform": t.tolist(),
        "translation": translation.tolist(),
        "quaternion_xyzw": quaternion_xyzw(rotation).tolist(),
        "rpy_rad": angles.tolist(),
        "rpy_deg": np.degrees(angles).tolist(),
    }
    cov = result.covariance
    if isinstance(result, SequenceResult):
        out["converged"] = bool(result.converged)
        out["rmse"] = [float(result.rmse)]  # the one alignment: the target's frames to the map
    else:
        out["converged"] = bool(result.refinement.converged)
        out["rmse"] = _list(result.rmse)
    if cov is not None and transform is None:
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        out["std_translation_m"] = sd[:3].tolist()
        out["std_rotation_deg"] = np.degrees(sd[3:]).tolist()
    if isinstance(result, SequenceResult):
        out["diagnostics"] = _sequence_diagnostics(result)
        if transform is not None:
            out["diagnostics"]["method_transform"] = own.tolist()
        return out
    refinement = result.refinement
    diagnostics: dict[str, Any] = {
        "solver": refinement.solver,
        "iterations": int(refinement.iterations),
        # NaN (a solver without a cost: ICP, none) would not survive a round trip: null.
        "cost": None if math.isnan(refinement.cost) else float(refinement.cost),
        "termination": refinement.termination,
        "inlier_counts": [
            [len(i) for i in result.inliers_reference],
            [len(i) for i in result.inliers_target],
        ],
        "timings_ms": dict(result.timings),
        "covariance": _list(cov),
    }
    if transform is not None:
        diagnostics["method_transform"] = own.tolist()
    diagnostics.update(_details(result.details))
    out["diagnostics"] = diagnostics
    out["check"] = result.check.to_dict()
    return out


def _sequence_diagnostics(result: SequenceResult) -> dict[str, Any]:
    """The evidence of a calibration from a drive: how well the target's frames, placed by the
    result, lie on the reference's map (``fitness``, the share of its samples on the map, and
    ``rmse``), how far the vehicle went, the hand-eye estimate from the motion alone and what the
    motion left unobserved."""
    direction, share = result.weakest_translation
    rot_direction, rot_share = result.weakest_rotation
    unobserved = result.unobserved_by_motion
    return {
        "fitness": float(result.fitness),
        "rmse": float(result.rmse),
        "distance_m": float(result.distance),
        "frames": len(result.reference_poses),
        "iterations": int(result.iterations),
        "hand_eye_transform": np.asarray(result.hand_eye_transform).tolist(),
        "unobserved_by_motion": _list(unobserved),
        "weakest_translation_direction": _list(direction),
        "weakest_translation_share": float(share),
        "weakest_rotation_direction": _list(rot_direction),
        "weakest_rotation_share": float(rot_share),
        "timings_ms": dict(result.timings),
        "covariance": _list(result.covariance),
    }


def _details(details: PlanarDetails | PoleDetails | TargetlessDetails) -> dict[str, Any]:
    """The method's own diagnostics, under the keys of the file format."""
    if isinstance(details, PlanarDetails):
        ordering = details.ordering
        return dict(
            planes_reference=_list(details.planes_reference),
            planes_target=_list(details.planes_target),
            ordering_scores=_list(ordering["scores"]),
            ordering_margin=ordering["margin"],
            used_up=ordering["used_up"],
            distance_thresholds=_list(details.distance_thresholds),
        )
    if isinstance(details, PoleDetails):
        return dict(
            poles_reference=_list(details.poles_reference),
            poles_target=_list(details.poles_target),
            pole_radii=_list(details.radii),
            intensity_thresholds=[e["intensity_threshold"] for e in details.extractions],
            hypothesis_scores=[h["score"] for h in details.hypotheses],
            hypothesis_margin=details.margin,
            ambiguous=details.ambiguous,
        )
    direction, share = details.weakest_translation
    icp = details.icp
    return dict(
        planes_reference=_list(details.planes_reference),
        planes_target=_list(details.planes_target),
        matched_planes=len(details.planes_reference),
        plane_counts=[len(f) for f in details.features],
        hypothesis_counts=list(details.hypothesis_counts),
        best_score=details.best_score,
        second_score=details.second_score,
        triplet=details.triplet,
        weakest_translation_direction=_list(direction),
        weakest_translation_share=float(share),
        icp_fitness=None if icp is None else icp["fitness"],
    )


def from_rpy(angles: npt.ArrayLike) -> F64Array:
    """The rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` of ``[roll, pitch, yaw]`` (radians): the
    inverse of :func:`rpy` and URDF's ``origin rpy``."""
    roll, pitch, yaw = (float(v) for v in np.asarray(angles, dtype=np.float64).reshape(3))
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    out: F64Array = rz @ ry @ rx
    return out


def _pick(path: Path, candidates: list[tuple[list[str], Any]], target: str | None) -> Any:
    """The one candidate (names, value) for ``target``, or the only one when ``target`` is None."""
    if not candidates:
        raise ValueError(f"{path}: holds no transform")
    if target is None:
        if len(candidates) > 1:
            listed = ", ".join(n[0] for n, _ in candidates if n)
            raise ValueError(
                f"{path}: holds {len(candidates)} transforms ({listed}); pass --target"
            )
        return candidates[0][1]
    wanted = {target, frame_id(target, target), Path(target).stem, frame_id(Path(target).stem, "")}
    for names, value in candidates:
        if wanted & set(names):
            return value
    known = ", ".join(n[0] for n, _ in candidates if n)
    raise ValueError(f"{path}: no transform for target {target!r} (it holds: {known})")


def _entry_names(e: dict[str, Any]) -> list[str]:
    names = [str(e[k]) for k in ("target_frame", "target") if e.get(k)]
    names += [Path(n).stem for n in names] + [Path(n).name for n in names]
    return names


def read_transform(path: str | Path, target: str | None = None) -> F64Array:
    """Reads a 4x4 ``reference_from_target`` from a file this package wrote (``.yaml``/``.yml``,
    ``.json``, ``.txt``, ``.urdf``) or from a bare 4x4 text matrix. ``target`` picks one of
    several (a target file name, its stem or its frame id; for URDF the joint's child link).
    Raises ``ValueError`` naming the file and the problem, ``OSError`` when it cannot be read."""
    path = Path(path)
    ext = path.suffix.lower()
    text = path.read_text()
    if ext in (".json", ".yaml", ".yml"):
        if ext == ".json":
            try:
                data = json.loads(text)
            except json.JSONDecodeError as e:
                raise ValueError(f"{path}: not valid JSON ({e})") from e
        else:
            try:
                import yaml
            except ImportError as e:  # pragma: no cover - pyyaml is a dependency
                raise ValueError(f"{path}: reading YAML needs PyYAML") from e
            try:
                data = yaml.safe_load(text)
            except yaml.YAMLError as e:
                raise ValueError(f"{path}: not valid YAML ({e})") from e
        if isinstance(data, dict) and "results" in data:
            data = data["results"]
        items = data if isinstance(data, list) else [data]
        found = [
            (_entry_names(e), e["transform"])
            for e in items
            if isinstance(e, dict) and "transform" in e
        ]
        matrix = np.asarray(_pick(path, found, target), dtype=np.float64)
    elif ext == ".urdf":
        import xml.etree.ElementTree as ET

        try:
            root = ET.fromstring(text)
        except ET.ParseError as e:
            raise ValueError(f"{path}: not valid URDF/XML ({e})") from e
        joints = []
        for joint in root.iter("joint"):
            child, origin = joint.find("child"), joint.find("origin")
            if child is None:
                continue
            pose = np.eye(4)
            if origin is not None:
                try:
                    xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
                    angles = [float(v) for v in origin.get("rpy", "0 0 0").split()]
                except ValueError as e:
                    raise ValueError(f"{path}: a joint origin is not numeric ({e})") from e
                if len(xyz) != 3 or len(angles) != 3:
                    raise ValueError(f"{path}: a joint origin needs 3 xyz and 3 rpy values")
                pose[:3, :3] = from_rpy(angles)
                pose[:3, 3] = xyz
            joints.append(([str(child.get("link"))], pose))
        matrix = np.asarray(_pick(path, joints, target))
    else:
        blocks: list[tuple[list[str], list[list[float]]]] = []
        rows: list[list[float]] = []
        names: list[str] = []
        for number, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if not line:
                continue
            if line.startswith("#"):
                if "<-" in line:
                    name = line.rsplit("<-", 1)[1].strip()
                    names = [name, Path(name).stem, Path(name).name]
                continue
            try:
                rows.append([float(v) for v in line.replace(",", " ").split()])
            except ValueError as e:
                raise ValueError(f"{path}:{number}: not a row of numbers: {line!r}") from e
            if len(rows) == 4:
                blocks.append((names, rows))
                rows, names = [], []
        if rows:
            raise ValueError(f"{path}: {len(rows)} trailing row(s); a transform is 4 rows of 4")
        matrix = np.asarray(_pick(path, blocks, target), dtype=np.float64)
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"{path}: the transform must be a finite 4x4 matrix, got {matrix.shape}")
    return matrix


def _yaml_scalar(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and not math.isfinite(v):
            return ".nan" if math.isnan(v) else (".inf" if v > 0 else "-.inf")
        return repr(v)
    return json.dumps(str(v))  # a JSON string is a valid YAML double-quoted scalar


def _yaml(v: Any, indent: int) -> list[str]:
    pad = "  " * indent
    if isinstance(v, dict):
        lines = []
        for key, item in v.items():
            if isinstance(item, (dict, list)) and item and not _flat(item):
                lines.append(f"{pad}{key}:")
                lines.extend(_yaml(item, indent + 1))
            else:
                lines.append(f"{pad}{key}: {_inline(item)}")
        return lines
    if isinstance(v, list):
        lines = []
        for item in v:
            if isinstance(item, (dict, list)) and item and not _flat(item):
                sub = _yaml(item, indent + 1)
                lines.append(f"{pad}- {sub[0].lstrip()}")
                lines.extend(sub[1:])
            else:
                lines.append(f"{pad}- {_inline(item)}")
        return lines
    return [f"{pad}{_yaml_scalar(v)}"]


def _flat(v: Any) -> bool:
    """A list of scalars or of lists of scalars (a matrix), written inline."""
    if isinstance(v, list):
        return all(not isinstance(x, (dict, list)) or (isinstance(x, list) and _flat(x)) for x in v)
    return False


def _inline(v: Any) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_inline(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{}" if not v else json.dumps(v)
    return _yaml_scalar(v)


def to_yaml(data: dict[str, Any] | list[dict[str, Any]]) -> str:
    """YAML text of :func:`to_dict` output (or a list of them); no YAML library needed."""
    return "\n".join(_yaml(data, 0)) + "\n"


def frame_id(text: str, default: str) -> str:
    """``text`` as a URDF / tf frame id: letters, digits and ``_`` (others become ``_``)."""
    cleaned = "".join(c if c.isalnum() or c == "_" else "_" for c in text)
    return cleaned or default


def _frame(name: str | None, default: str) -> str:
    return frame_id(Path(name).stem, default) if name else default


def static_transform_publisher(
    transform: npt.ArrayLike, parent: str, child: str, *, ros1: bool = False
) -> str:
    """The ``tf2_ros static_transform_publisher`` command publishing ``parent <- child``."""
    t = np.asarray(transform, dtype=np.float64)
    x, y, z = (f"{v:.6f}" for v in t[:3, 3])
    qx, qy, qz, qw = (f"{v:.9f}" for v in quaternion_xyzw(t[:3, :3]))
    if ros1:
        return (
            f"rosrun tf2_ros static_transform_publisher {x} {y} {z} {qx} {qy} {qz} {qw} "
            f"{parent} {child}"
        )
    return (
        f"ros2 run tf2_ros static_transform_publisher --x {x} --y {y} --z {z} --qx {qx} "
        f"--qy {qy} --qz {qz} --qw {qw} --frame-id {parent} --child-frame-id {child}"
    )


def _urdf(entries: Sequence[dict[str, Any]]) -> str:
    parent = entries[0]["reference_frame"]
    # Link and joint names must be unique: number repeated frames (two files with one stem).
    links = [parent]
    for e in entries:
        name, k = e["target_frame"], 2
        while name in links:
            name, k = f"{e['target_frame']}_{k}", k + 1
        links.append(name)
    lines = ['<?xml version="1.0"?>', '<robot name="lidarcal_calibration">']
    lines += [f"  <link name={quoteattr(name)}/>" for name in links]
    for child, e in zip(links[1:], entries, strict=True):
        xyz = " ".join(f"{v:.9g}" for v in e["translation"])
        angles = " ".join(f"{v:.9g}" for v in e["rpy_rad"])
        lines += [
            f'  <joint name={quoteattr(f"{parent}_to_{child}")} type="fixed">',
            f"    <parent link={quoteattr(parent)}/>",
            f"    <child link={quoteattr(child)}/>",
            f'    <origin xyz="{xyz}" rpy="{angles}"/>',
            "  </joint>",
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def write_result(path: str | Path, entries: dict[str, Any] | Sequence[dict[str, Any]]) -> None:
    """Writes :func:`to_dict` output (one, or a list for several targets) by extension:
    ``.yaml``/``.yml``, ``.json``, ``.txt`` (the 4x4 matrices, one block per target with a
    comment line) or ``.urdf`` (one fixed joint per target)."""
    path = Path(path)
    items = [entries] if isinstance(entries, dict) else list(entries)
    if not items:
        raise ValueError("no results to write")
    ext = path.suffix.lower()
    single: Any = items[0] if len(items) == 1 else items
    if ext in (".yaml", ".yml"):
        text = to_yaml(single)
    elif ext == ".json":
        text = json.dumps(single, indent=2) + "\n"
    elif ext == ".txt":
        blocks = []
        for e in items:
            matrix = "\n".join(" ".join(f"{v: .9f}" for v in row) for row in e["transform"])
            blocks.append(f"# reference_from_target: {e['reference']} <- {e['target']}\n{matrix}")
        text = "\n".join(blocks) + "\n"
    elif ext == ".urdf":
        text = _urdf(items)
    else:
        raise ValueError(
            f"{path}: unknown output extension {ext!r}; use .yaml, .json, .txt or .urdf"
        )
    path.write_text(text)
