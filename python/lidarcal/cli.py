"""The ``lidarcal`` command line.

``lidarcal calibrate REFERENCE TARGET [TARGET...]`` calibrates each target cloud (PCD, PLY, KITTI
``.bin``, ``.npy``, CSV/TXT, or a ROS bag with ``--topic``) to the reference and prints or writes
the transforms (``--output x.yaml|.json|.txt|.urdf``, ``--json``, ``--plot x.png``).
``lidarcal calibrate REFERENCE TARGET --sequence`` calibrates from a drive instead: every frame of
two bag topics (``drive.bag:/front``) or two folders of numbered frames, ``--start``/``--end``.

``lidarcal check REFERENCE TARGET --transform FILE`` checks a stored transform against the two
clouds (exit 0 consistent, 2 inconsistent, 3 unverifiable).

``lidarcal demo`` simulates a building corner seen by two LiDARs, calibrates it with no initial
guess and prints the ground truth, the estimate and the errors (``--json`` for scripts).

``lidarcal batch MANIFEST --output RESULTS`` calibrates or monitors every row of a manifest on
Dask (:mod:`lidarcal.batch`, the ``fleet`` extra).

``lidarcal simulate --scene corner --model vlp16 --seed 0 --output out/`` writes
``reference.pcd``, ``target.pcd`` and ``ground_truth.json`` (transforms and true geometry);
``--scene drive`` writes two folders of numbered frames with their ``times.txt`` instead.
"""

from __future__ import annotations

import contextlib
import inspect
import json
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np

import lidarcal
from lidarcal import (
    CalibrationError,
    CalibrationResult,
    SequenceResult,
    __version__,
    calibrate_planes,
    read_points,
    sim,
)
from lidarcal._lidarcal import _defaults
from lidarcal.calibrate import METHOD_NAMES
from lidarcal.export import (
    OUTPUT_SUFFIXES,
    frame_id,
    rpy,
    static_transform_publisher,
    to_dict,
    write_result,
)
from lidarcal.rosbag import split_source

# Defaults from Rust (`--help` shows them): the beam model (`Preset::default()`), the corner
# scene's options (`CornerOptions::default()`), the calibration method (`Method::default()`, as
# `RigOptions::default()` has it) and the poles' bright share (`PoleOptions::default()`).
_MODEL = _defaults()["sim_scan"]["model"]
_CORNER = _defaults()["sim_corner_scene"]
_METHOD = _defaults()["calibrate_rig"]["method"]
_MAX_BRIGHT_FRACTION = _defaults()["calibrate_poles"]["max_bright_fraction"]
# The drive's frame count: `sim.drive_scene`'s own default.
_DRIVE_FRAMES: int = inspect.signature(sim.drive_scene).parameters["frames"].default


@click.group()
@click.version_option(__version__, prog_name="lidarcal")
def main() -> None:
    """Extrinsic calibration between LiDARs."""


@main.command()
@click.option(
    "--scene",
    "scene_name",
    type=click.Choice(["corner", "poles", "paper", "drive"]),
    default="corner",
    show_default=True,
    help="drive: a vehicle driving through a town with a front (reference) and a rear (target) "
    "unit; writes the folders reference/ and target/ of numbered frames with their times.txt, "
    "for `lidarcal calibrate reference target --sequence`.",
)
@click.option("--model", type=click.Choice(list(sim.MODELS)), default=_MODEL, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Directory to write into (created if missing).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["pcd", "npy"]),
    default="pcd",
    show_default=True,
    help="pcd: binary PCD with x y z intensity ring; npy: (N, 5) float64 arrays.",
)
@click.option("--ascii", is_flag=True, help="Write ASCII PCD instead of binary.")
@click.option(
    "--frames",
    type=click.IntRange(2, 3000),
    default=_DRIVE_FRAMES,
    show_default=True,
    help="drive: frames per unit, at 10 Hz (the vehicle turns first after about 6 s).",
)
def simulate(
    scene_name: str, model: str, seed: int, output: Path, fmt: str, ascii: bool, frames: int
) -> None:
    """Simulate a scene seen by two sensors and write one file per sensor plus ground truth.

    The paper scene samples points (no beam model); --model is ignored for it and for the drive,
    whose units have their own 64-beam model.
    """
    if scene_name == "drive":
        _simulate_drive(seed, output, fmt, ascii, frames)
        return
    try:
        if scene_name == "corner":
            scene = sim.corner_scene(model, seed=seed)
        elif scene_name == "poles":
            scene = sim.poles_scene(model, seed=seed, distractor=True)
        else:
            scene = sim.paper_scene(seed=seed)
        output.mkdir(parents=True, exist_ok=True)
        files = {}
        for name, points, rings in (
            ("reference", scene.reference, scene.reference_rings),
            ("target", scene.target, scene.target_rings),
        ):
            data = np.column_stack([points, rings.astype(np.float64)])
            path = output / f"{name}.{fmt}"
            if fmt == "pcd":
                sim.write_pcd(path, data, ascii=ascii)
            else:
                np.save(path, data)
            files[name] = path.name
        truth = {
            "scene": scene_name,
            "model": None if scene_name == "paper" else model,
            "seed": seed,
            "files": files,
            "convention": "p_reference = reference_from_target @ p_target (homogeneous)",
            "reference_from_target": scene.reference_from_target.tolist(),
            "world_from_reference": scene.world_from_reference.tolist(),
            "planes_in_reference": scene.planes.tolist(),
            "pole_axes_in_reference": scene.pole_axes.tolist(),
            "pole_radii": scene.pole_radii.tolist(),
        }
        (output / "ground_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    except (ValueError, OSError) as e:
        raise click.ClickException(str(e)) from e
    click.echo(
        f"wrote {files['reference']} ({len(scene.reference)} points), "
        f"{files['target']} ({len(scene.target)} points) and ground_truth.json to {output}"
    )


def _simulate_drive(seed: int, output: Path, fmt: str, ascii: bool, frames: int) -> None:
    """`simulate --scene drive`: output/reference/000000.pcd ... and output/target/..., each with
    its times.txt, and ground_truth.json (the extrinsic and both units' true poses)."""
    try:
        drive = sim.drive_scene(seed, frames=frames)
        files = {}
        for name, clouds in (
            ("reference", drive.reference_frames),
            ("target", drive.target_frames),
        ):
            folder = output / name
            folder.mkdir(parents=True, exist_ok=True)
            digits = max(6, len(str(len(clouds) - 1)))
            for k, cloud in enumerate(clouds):
                path = folder / f"{k:0{digits}d}.{fmt}"
                if fmt == "pcd":
                    sim.write_pcd(path, cloud, ascii=ascii)
                else:
                    np.save(path, cloud)
            (folder / "times.txt").write_text("".join(f"{t:.6f}\n" for t in drive.times))
            files[name] = name + "/"
        truth = {
            "scene": "drive",
            "seed": seed,
            "frames": frames,
            "files": files,
            "columns": ["x", "y", "z", "intensity"],
            "convention": "p_reference = reference_from_target @ p_target (homogeneous)",
            "reference_from_target": drive.reference_from_target.tolist(),
            "times": drive.times.tolist(),
            "world_from_reference": drive.world_from_reference.tolist(),
            "world_from_target": drive.world_from_target.tolist(),
        }
        (output / "ground_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    except (ValueError, OSError) as e:
        raise click.ClickException(str(e)) from e
    click.echo(
        f"wrote {frames} frames each to {output / 'reference'} and {output / 'target'} (with "
        f"times.txt) and ground_truth.json; calibrate them with: lidarcal calibrate "
        f"{output / 'reference'} {output / 'target'} --sequence"
    )


def _rpy_deg(transform: np.ndarray) -> list[float]:
    """Roll, pitch, yaw (degrees) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return [float(v) for v in np.degrees(rpy(transform[:3, :3]))]


def _errors(truth: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    """Rotation error (angle of R_true R^T, degrees) and translation error (metres)."""
    d = truth[:3, :3] @ estimate[:3, :3].T
    angle = np.arctan2(
        0.5 * np.linalg.norm([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]),
        0.5 * (np.trace(d) - 1.0),
    )
    return float(np.degrees(angle)), float(np.linalg.norm(truth[:3, 3] - estimate[:3, 3]))


@main.command()
@click.option("--model", type=click.Choice(list(sim.MODELS)), default=_MODEL, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True, help="Scene and sampler seed.")
@click.option(
    "--wall-angle",
    type=float,
    default=_CORNER["wall_angle_deg"],
    show_default=True,
    help="Angle between the two walls, degrees.",
)
@click.option(
    "--tilt",
    type=float,
    default=_CORNER["target_tilt_deg"],
    show_default=True,
    help="Largest roll/pitch of the second sensor, degrees.",
)
@click.option(
    "--clutter",
    type=int,
    default=_CORNER["clutter_boxes"],
    show_default=True,
    help="Clutter boxes.",
)
@click.option(
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the result, as `lidarcal calibrate --output` does (.yaml/.json/.txt/.urdf).",
)
@click.option(
    "--plot",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write a PNG of the clouds before/after (needs matplotlib).",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object (the fields of `lidarcal calibrate --json` plus ground truth and "
    "errors) instead of text.",
)
def demo(
    model: str,
    seed: int,
    wall_angle: float,
    tilt: float,
    clutter: int,
    output: Path | None,
    plot: Path | None,
    as_json: bool,
) -> None:
    """Simulate a building corner seen by two LiDARs and calibrate it, with no initial guess.

    Both sensors are taken to be roughly upright (gravity along +z in each frame); that is used
    only to break the tie between plane correspondences of a right-angled corner.
    """
    try:
        scene = sim.corner_scene(
            model, seed=seed, wall_angle_deg=wall_angle, target_tilt_deg=tilt, clutter_boxes=clutter
        )
        result = calibrate_planes(scene.reference, scene.target, up=[0.0, 0.0, 1.0], seed=seed)
    except (ValueError, CalibrationError) as e:
        raise click.ClickException(str(e)) from e
    truth = scene.reference_from_target
    rot_err, trans_err = _errors(truth, result.transform)
    report = to_dict(result, reference="reference", target="target")
    report.update(
        model=model,
        seed=seed,
        points=[len(scene.reference), len(scene.target)],
        ground_truth=truth.tolist(),
        rotation_error_deg=rot_err,
        translation_error_m=trans_err,
        timings_ms=result.timings,
    )
    if output is not None:
        _check_output(output)
        try:
            write_result(output, report)
        except OSError as e:
            raise click.ClickException(str(e)) from e
    if plot is not None:
        _plot(scene.reference, scene.target, result, plot, f"lidarcal demo ({model}, seed {seed})")
    if as_json:
        click.echo(json.dumps(report))
        return
    t_true, t_est = truth[:3, 3], result.transform[:3, 3]
    fmt = "[{:+.4f}, {:+.4f}, {:+.4f}]"
    click.echo(
        f"lidarcal {__version__} demo: {model} corner scene, seed {seed}, "
        f"{len(scene.reference)} + {len(scene.target)} points"
    )
    click.echo(f"  truth     rpy deg {fmt.format(*_rpy_deg(truth))}  t m {fmt.format(*t_true)}")
    click.echo(
        f"  estimate  rpy deg {fmt.format(*_rpy_deg(result.transform))}  t m {fmt.format(*t_est)}"
    )
    click.echo(f"  error     rotation {rot_err:.4f} deg, translation {100 * trans_err:.2f} cm")
    click.echo(
        f"  converged {result.refinement.converged}, plane rmse "
        f"{', '.join(f'{100 * r:.2f}' for r in result.rmse)} cm, "
        f"{result.timings['total']:.1f} ms"
    )


def _floats(text: str | None, count: int, option: str) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(np.isfinite(values)):
        raise click.BadParameter(
            f"needs {count} comma-separated numbers, got {text!r}", param_hint=option
        )
    return values


@dataclass(frozen=True)
class Source:
    """A cloud on the command line: a file, or a bag with an optional ``:/topic`` suffix."""

    text: str
    path: Path
    topic: str | None

    @property
    def frame(self) -> str:
        """A frame name for URDF / tf: the topic for bags, else the file's stem."""
        return frame_id(self.topic.strip("/") if self.topic else self.path.stem, "frame")


# click >= 8.2 makes ParamType generic; subscripting it would break older clicks at import.
class SourceType(click.ParamType):  # type: ignore[type-arg]
    """``FILE`` or ``BAG:/topic``; the file must exist."""

    name = "cloud"

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> Source:
        if isinstance(value, Source):
            return value
        text = str(value)
        try:
            return Source(text, *split_source(text))
        except FileNotFoundError:
            self.fail(f"{text}: no such file (a bag topic is given as BAG:/topic)", param, ctx)


def _crop(points: np.ndarray, crop: Sequence[float] | None, text: str) -> np.ndarray:
    if crop is None:
        return points
    lo, hi = np.array(crop[0::2]), np.array(crop[1::2])
    keep = np.all((points[:, :3] >= lo) & (points[:, :3] <= hi), axis=1)
    points = points[keep]
    if len(points) == 0:
        raise ValueError(f"{text}: no point is left inside the --crop box")
    return points


def load_cloud(
    source: Source, crop: Sequence[float] | None, topic: str | None, time: float | None
) -> np.ndarray:
    """Reads a cloud (a file or one frame of a bag) and crops it to the box, in its own frame."""
    from lidarcal.rosbag import is_bag, read_bag

    if source.topic is not None or is_bag(source.path):
        points = read_bag(source.path, source.topic or topic, time=time)
    elif source.path.is_dir():
        raise ValueError(f"{source.text}: a folder; a folder of frames is read with --sequence")
    else:
        points = read_points(source.path)
    return _crop(points, crop, source.text)


@dataclass(frozen=True)
class Recording:
    """The frames of a `--sequence` source in time order, their times (seconds) and whether they
    came from a bag (times to pair by) or a folder (frames to pair in order)."""

    frames: list[np.ndarray]
    times: np.ndarray
    bag: bool


def load_sequence(
    source: Source,
    crop: Sequence[float] | None,
    topic: str | None,
    start: float | None,
    end: float | None,
) -> Recording:
    """Every frame of a bag topic or a folder of numbered frames between ``start`` and ``end``,
    each cropped to the box."""
    from lidarcal.frames import read_folder
    from lidarcal.rosbag import is_bag, read_bag_frames

    if source.topic is not None or is_bag(source.path):
        frames, times = read_bag_frames(source.path, source.topic or topic, start=start, end=end)
        bag = True
    elif source.path.is_dir():
        frames, times, _ = read_folder(source.path, start=start, end=end)
        bag = False
    else:
        raise ValueError(
            f"{source.text}: --sequence reads a bag topic (BAG:/topic) or a folder of numbered "
            "frames, not a single file"
        )
    return Recording([_crop(f, crop, source.text) for f in frames], times, bag)


def pair_recordings(
    reference: Source, ref: Recording, target: Source, tgt: Recording
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """The frames of both taken at the same times and those times: two folders frame by frame
    (the counts must match), two bags by nearest time (see :func:`lidarcal.frames.pair_by_time`)."""
    from lidarcal.frames import pair_by_time

    if ref.bag != tgt.bag:
        raise ValueError(
            f"{reference.text} is a {'bag' if ref.bag else 'folder'} and {target.text} a "
            f"{'bag' if tgt.bag else 'folder'}; --sequence pairs two bags by time or two folders "
            "frame by frame"
        )
    if not ref.bag:
        if len(ref.frames) != len(tgt.frames):
            raise ValueError(
                f"{reference.text} has {len(ref.frames)} frames and {target.text} "
                f"{len(tgt.frames)} (after --start/--end); two folders must pair up frame by "
                "frame"
            )
        return ref.frames, tgt.frames, ref.times
    pairs = pair_by_time(ref.times, tgt.times)
    if not pairs:
        raise ValueError(
            f"no frame of {reference.text} has a frame of {target.text} within half a frame "
            "period: were they recorded together?"
        )
    return (
        [ref.frames[i] for i, _ in pairs],
        [tgt.frames[j] for _, j in pairs],
        np.array([ref.times[i] for i, _ in pairs]),
    )


def _method_kwargs(options: dict[str, Any]) -> dict[str, Any]:
    """The command's method options as keywords of `lidarcal.calibrate` / `calibrate_rig`."""
    return {
        "seed": options["seed"],
        "up": options["up"],
        "distance_threshold": options["threshold"],
        "intensity_threshold": options["intensity_threshold"],
        "vendor": options["vendor"],
        "max_bright_fraction": options["max_bright_fraction"],
    }


def _calibrate(
    method: str, reference: np.ndarray, target: np.ndarray, options: dict[str, Any]
) -> CalibrationResult:
    if method == "poles" and (reference.shape[1] < 4 or target.shape[1] < 4):
        which = "reference" if reference.shape[1] < 4 else "target"
        raise ValueError(f"--method poles needs intensity, and the {which} file has none")
    return lidarcal.calibrate(
        reference,
        target,
        method,  # type: ignore[arg-type]
        **_method_kwargs(options),
    )


def _summary(entry: dict[str, Any], parent: str, child: str) -> str:
    t = np.array(entry["transform"])
    fmt = "[{:+.4f}, {:+.4f}, {:+.4f}]"
    lines = [
        f"{entry['target']} -> {entry['reference']} ({entry['method']}, "
        f"converged {entry['converged']})",
        "  reference_from_target:",
        *("    " + " ".join(f"{v:+.6f}" for v in row) for row in t),
        f"  translation m     {fmt.format(*entry['translation'])}",
        f"  rpy deg           {fmt.format(*entry['rpy_deg'])}",
        "  quaternion xyzw   [{:+.6f}, {:+.6f}, {:+.6f}, {:+.6f}]".format(
            *entry["quaternion_xyzw"]
        ),
    ]
    if "std_translation_m" in entry:
        sd_t = 100 * np.array(entry["std_translation_m"])
        sd_r = np.array(entry["std_rotation_deg"])
        plain = "[{:.4f}, {:.4f}, {:.4f}]"
        lines.append(
            f"  1-sigma (noise)   translation {plain.format(*sd_t)} cm, "
            f"rotation {plain.format(*sd_r)} deg"
        )
    if entry["method"] == "sequence":
        d = entry["diagnostics"]
        rot, trans = _errors(np.array(d["hand_eye_transform"]), t)
        lines.append(
            f"  drive             {d['frames']} frames, {d['distance_m']:.0f} m; map fitness "
            f"{100 * d['fitness']:.0f} %, rmse {100 * d['rmse']:.2f} cm"
        )
        lines.append(
            f"  hand-eye          {rot:.3f} deg / {100 * trans:.1f} cm from the result "
            "(the motion alone)"
        )
    else:
        rmse = ", ".join(f"{100 * r:.2f}" for r in entry["rmse"])
        lines.append(f"  feature rmse cm   {rmse}")
    if "rig" in entry:
        edges = entry["rig"]["edges"]
        worst_r = max(e["rotation_residual_deg"] for e in edges)
        worst_t = max(e["translation_residual_m"] for e in edges)
        how = "direct" if entry["rig"]["direct"] else "placed through another target"
        lines.append(
            f"  rig               {how}; {len(edges)} edge(s), largest residual "
            f"{worst_r:.3f} deg / {100 * worst_t:.1f} cm"
        )
    lines.append("  " + static_transform_publisher(t, parent, child))
    return "\n".join(lines)


def _check_output(output: Path) -> None:
    if output.suffix.lower() not in OUTPUT_SUFFIXES:
        raise click.BadParameter("use .yaml, .json, .txt or .urdf", param_hint="--output")


def _plot(
    reference: np.ndarray,
    target: np.ndarray,
    result: CalibrationResult | np.ndarray,
    png: Path,
    title: str,
) -> None:
    try:
        from lidarcal.plot import overlay
    except ImportError as e:
        raise click.ClickException(str(e)) from e
    try:
        overlay(reference, target, result, path=png, title=title)
    except ImportError as e:
        raise click.ClickException(str(e)) from e
    except OSError as e:
        raise click.ClickException(f"{png}: {e}") from e


def _error_entry(
    reference: Source, target: Source, error: Exception | str, kind: str | None = None
) -> dict[str, Any]:
    """The result entry of a target that could not be calibrated; ``kind`` is the
    :class:`CalibrationError` kind (``None`` for bad input or a file problem)."""
    if isinstance(error, CalibrationError):
        kind = getattr(error, "kind", kind)
    return {"reference": reference.text, "target": target.text, "error": str(error), "kind": kind}


def _rig_entries(
    reference: Source,
    ref_points: np.ndarray,
    clouds: list[tuple[Source, np.ndarray]],
    method: str,
    options: dict[str, Any],
    plot: Path | None,
) -> list[dict[str, Any]]:
    """`--rig`: every target to the reference and to each other, made consistent by the pose
    graph of :func:`lidarcal.calibrate_rig`. One entry per target, as without `--rig`, whose pose
    is the refined one; `rig` in each entry lists that target's edges and their residuals."""
    named: dict[str, tuple[Source, np.ndarray]] = {}
    for source, points in clouds:
        name, k = source.frame, 2
        while name in named or name == "reference":
            name, k = f"{source.frame}_{k}", k + 1
        named[name] = (source, points)

    try:
        rig = lidarcal.calibrate_rig(
            ref_points,
            {name: points for name, (_, points) in named.items()},
            method=method,  # type: ignore[arg-type]
            require_all=False,
            **_method_kwargs(options),
        )
    except (ValueError, CalibrationError) as e:
        return [_error_entry(reference, s, e) for s, _ in named.values()]
    entries: list[dict[str, Any]] = []
    for name, (source, points) in named.items():
        touching = [e for e in rig.edges if name in (e.a, e.b) and e.result is not None]
        if name not in rig.transforms or not touching:
            reasons = "; ".join(
                f"{a} -> {b}: {m}" for (a, b), m in rig.failures.items() if name in (a, b)
            )
            message = f"not connected to the reference ({reasons})"
            kinds = [k for (a, b), k in rig.failure_kinds.items() if name in (a, b) and k]
            entries.append(_error_entry(reference, source, message, kinds[0] if kinds else None))
            continue
        # The direct edge when there is one, else the edge through which the target was placed.
        edge = next((e for e in touching if e.a == "reference"), touching[0])
        assert edge.result is not None
        entry = to_dict(
            edge.result,
            reference=reference.text,
            target=source.text,
            reference_frame=reference.frame,
            target_frame=source.frame,
            transform=rig.transforms[name],
        )
        entry["rig"] = {
            "direct": name in rig.direct,
            "edges": [
                {
                    "a": e.a,
                    "b": e.b,
                    "method": e.method,
                    "rotation_residual_deg": e.rotation_residual_deg,
                    "translation_residual_m": e.translation_residual_m,
                }
                for e in touching
            ],
        }
        entries.append(entry)
        if plot is not None:
            png = (
                plot.with_name(f"{plot.stem}_{source.frame}{plot.suffix}")
                if len(named) > 1
                else plot
            )
            _plot(ref_points, points, rig.transforms[name], png, f"{source.path.name} (rig)")
            entry["plot"] = str(png)
    return entries


#: The options of `calibrate` that do not apply to `--sequence` (parameter name, option).
_NOT_FOR_SEQUENCE = (
    ("method", "--method"),
    ("up", "--up"),
    ("threshold", "--threshold"),
    ("intensity_threshold", "--intensity-threshold"),
    ("vendor", "--vendor"),
    ("max_bright_fraction", "--max-bright-fraction"),
    ("bag_time", "--time"),
    ("rig", "--rig"),
)


def _sequence_options(targets: tuple[Source, ...]) -> None:
    """Refuses what `--sequence` does not take: several targets, the single-cloud options."""
    ctx = click.get_current_context()
    for name, option in _NOT_FOR_SEQUENCE:
        if ctx.get_parameter_source(name) not in (None, click.core.ParameterSource.DEFAULT):
            raise click.BadParameter(
                "does not apply to --sequence (--start/--end pick the frames)", param_hint=option
            )
    if len(targets) != 1:
        raise click.BadParameter(
            f"--sequence calibrates one TARGET to the REFERENCE, got {len(targets)} targets",
            param_hint="TARGETS",
        )


def _sequence_entry(
    reference: Source,
    target: Source,
    crop: Sequence[float] | None,
    topic: str | None,
    start: float | None,
    end: float | None,
    plot: Path | None,
) -> dict[str, Any]:
    """`--sequence`: reads and pairs both recordings (a problem there is a one-line error),
    calibrates them with :func:`lidarcal.calibrate_sequence` and returns the result's entry, or
    an error entry (with the kind of a refusal) as the other methods do."""
    ctx = click.get_current_context()
    try:
        ref = load_sequence(reference, crop, topic, start, end)
        tgt = load_sequence(target, crop, topic, start, end)
        ref_frames, tgt_frames, times = pair_recordings(reference, ref, target, tgt)
    except (ValueError, OSError) as e:
        raise click.ClickException(str(e)) from e
    try:
        result = lidarcal.calibrate_sequence(ref_frames, tgt_frames, seed=ctx.params["seed"])
    except (ValueError, CalibrationError) as e:
        return _error_entry(reference, target, e)
    entry = to_dict(
        result,
        reference=reference.text,
        target=target.text,
        reference_frame=reference.frame,
        target_frame=target.frame,
    )
    entry["sequence"] = {
        "frames": len(times),
        "read": [len(ref.frames), len(tgt.frames)],
        "time_span_s": [float(times[0]), float(times[-1])],
    }
    if plot is not None:
        _plot_sequence(result, times - times[0], plot, f"{target.text} -> {reference.text}")
        entry["plot"] = str(plot)
    return entry


def _plot_sequence(result: SequenceResult, times: np.ndarray, png: Path, title: str) -> None:
    try:
        from lidarcal.plot import trajectories

        trajectories(result, times=times, path=png, title=title)
    except ImportError as e:
        raise click.ClickException(str(e)) from e
    except OSError as e:
        raise click.ClickException(f"{png}: {e}") from e


@main.command()
@click.argument("reference", type=SourceType())
@click.argument("targets", nargs=-1, required=True, type=SourceType())
@click.option(
    "--method",
    type=click.Choice(METHOD_NAMES),
    default=_METHOD,
    show_default=True,
    help="auto: try every method that applies and keep the certified result that fits best "
    "(refused when two disagree). planes: a wall corner (three planes) seen by both sensors. "
    "targetless: the planes of any scene (streets, facades, ground). poles: two or more poles "
    "wrapped in retro-reflective tape (the clouds need intensity).",
)
@click.option(
    "--crop",
    metavar="XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX",
    help="Keep only points inside this box (metres, each cloud in its own frame).",
)
@click.option(
    "--up",
    metavar="X,Y,Z",
    help="planes: the up direction (against gravity) in both sensors' frames, e.g. 0,0,1 for two "
    "upright sensors; used only to tell the walls of a right-angled corner apart.",
)
@click.option(
    "--threshold",
    type=float,
    help="planes, targetless: RANSAC inlier distance (m); default from the noise.",
)
@click.option(
    "--intensity-threshold", type=float, help="poles: intensity above which a return is tape."
)
@click.option(
    "--vendor",
    type=click.Choice(["velodyne", "hesai", "leishen", "robosense"]),
    help="poles: take that vendor's tape threshold.",
)
@click.option(
    "--max-bright-fraction",
    type=click.FloatRange(0.0, 1.0, min_open=True),
    help="poles: refuse when more than this share of a cloud is at or above the intensity "
    f"threshold (default {_MAX_BRIGHT_FRACTION:g}; tape is a small part of a scene). Use 1 for "
    "clouds cropped to the poles.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="RANSAC seed.")
@click.option("--topic", help="For bags: the PointCloud2 topic (needed if there are several).")
@click.option(
    "--time",
    "bag_time",
    type=float,
    help="For bags: seconds from the start (or Unix time) of the frame.",
)
@click.option(
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the result(s): .yaml or .json (matrix, translation, quaternion xyzw, "
    "roll-pitch-yaw, uncertainty, diagnostics), .txt (4x4 matrices) or .urdf (fixed joints).",
)
@click.option(
    "--plot",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write a PNG of the clouds before/after with the matched features and residuals "
    "(needs matplotlib). With several targets, one file per target: NAME_<target>.png.",
)
@click.option(
    "--rig",
    is_flag=True,
    help="Several targets: also calibrate the targets to each other where they overlap and "
    "refine all poses together (a pose graph), so the set is consistent; a target the reference "
    "barely sees can be placed through another. Each result's `rig` field lists its edges.",
)
@click.option(
    "--sequence",
    is_flag=True,
    help="Calibrate from a drive: REFERENCE and TARGET are two bag topics (BAG:/topic; frames "
    "paired by nearest time) or two folders of numbered frames (PCD/PLY/bin/npy, with an "
    "optional times.txt; paired frame by frame). Both sensors' odometry, hand-eye calibration of "
    "the motions, then the target's frames aligned to the reference's map. The vehicle must "
    "move and turn.",
)
@click.option(
    "--start",
    type=float,
    help="--sequence: the first frame's time, seconds from the start of the bag or folder (or a "
    "Unix time); for a folder without times.txt, frames from its first.",
)
@click.option("--end", type=float, help="--sequence: the last frame's time, as --start.")
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object on stdout: the result for one target, or "
    '{"results": [...]} for several.',
)
def calibrate(
    reference: Source,
    targets: tuple[Source, ...],
    method: str,
    crop: str | None,
    up: str | None,
    threshold: float | None,
    intensity_threshold: float | None,
    vendor: str | None,
    max_bright_fraction: float | None,
    seed: int,
    topic: str | None,
    bag_time: float | None,
    output: Path | None,
    plot: Path | None,
    rig: bool,
    sequence: bool,
    start: float | None,
    end: float | None,
    as_json: bool,
) -> None:
    """Calibrate each TARGET cloud to the REFERENCE cloud, with no initial guess.

    The result is the 4x4 transform reference_from_target: p_reference = R p_target + t.
    Files may be PCD, PLY, KITTI .bin, .npy, CSV/TXT, or ROS bags: BAG:/topic picks a topic
    (or --topic for all bags), --time the frame.

    \b
    Examples:
      lidarcal calibrate top.pcd front.pcd --up 0,0,1 --output front.yaml --plot front.png
      lidarcal calibrate top.pcd left.pcd right.pcd --crop -20,20,-20,20,-3,10 --json
      lidarcal calibrate drive.bag:/top/points drive.bag:/left/points --time 12.5
      lidarcal calibrate top.pcd left.pcd right.pcd rear.pcd --rig --output rig.urdf
      lidarcal calibrate drive.bag:/front drive.bag:/rear --sequence --start 5 --end 25
      lidarcal calibrate drive/reference drive/target --sequence --output rear.yaml

    Exits with status 1 and a one-line message if a calibration fails; the other targets are
    still calibrated and reported.
    """
    crop_box = _floats(crop, 6, "--crop")
    if crop_box is not None and any(
        lo > hi for lo, hi in zip(crop_box[0::2], crop_box[1::2], strict=True)
    ):
        raise click.BadParameter("each minimum must not exceed its maximum", param_hint="--crop")
    options = {
        "up": _floats(up, 3, "--up"),
        "threshold": threshold,
        "intensity_threshold": intensity_threshold,
        "vendor": vendor,
        "max_bright_fraction": max_bright_fraction,
        "seed": seed,
    }
    if output is not None:
        _check_output(output)
    entries: list[dict[str, Any]] = []
    if sequence:
        _sequence_options(targets)
        entries.append(_sequence_entry(reference, targets[0], crop_box, topic, start, end, plot))
    else:
        for name, value in (("--start", start), ("--end", end)):
            if value is not None:
                raise click.BadParameter("needs --sequence", param_hint=name)
        try:
            ref_points = load_cloud(reference, crop_box, topic, bag_time)
        except (ValueError, OSError) as e:
            raise click.ClickException(str(e)) from e

        if rig:
            loaded: list[tuple[Source, np.ndarray]] = []
            for target in targets:
                try:
                    loaded.append((target, load_cloud(target, crop_box, topic, bag_time)))
                except (ValueError, OSError) as e:
                    entries.append(_error_entry(reference, target, e))
            if loaded:
                entries.extend(_rig_entries(reference, ref_points, loaded, method, options, plot))
                order = {t.text: i for i, t in enumerate(targets)}
                entries.sort(key=lambda e: order.get(e["target"], 0))
        else:
            show_progress = len(targets) > 1 and sys.stderr.isatty()
            with contextlib.ExitStack() as stack:
                items: Iterable[Source] = targets
                if show_progress:
                    items = stack.enter_context(
                        click.progressbar(
                            targets,
                            label="calibrating",
                            file=sys.stderr,
                            item_show_func=lambda p: p.text if p is not None else None,
                        )
                    )
                for target in items:
                    try:
                        tgt_points = load_cloud(target, crop_box, topic, bag_time)
                        result = _calibrate(method, ref_points, tgt_points, options)
                    except (ValueError, OSError, CalibrationError) as e:
                        entries.append(_error_entry(reference, target, e))
                        continue
                    entry = to_dict(
                        result,
                        reference=reference.text,
                        target=target.text,
                        reference_frame=reference.frame,
                        target_frame=target.frame,
                    )
                    entries.append(entry)
                    if plot is not None:
                        png = plot
                        if len(targets) > 1:
                            png = plot.with_name(f"{plot.stem}_{target.frame}{plot.suffix}")
                        title = f"{target.path.name} -> {reference.path.name}"
                        _plot(ref_points, tgt_points, result, png, title)
                        entry["plot"] = str(png)

    for entry in entries:
        if entry.get("diagnostics", {}).get("ambiguous"):
            click.echo(
                f"Warning: {entry['target']}: another hypothesis fits almost as well "
                "(diagnostics.ambiguous); check the plot before trusting this result",
                err=True,
            )

    good = [e for e in entries if "error" not in e]
    if output is not None and good:
        try:
            write_result(output, good)
        except OSError as e:
            raise click.ClickException(str(e)) from e
    if as_json:
        click.echo(json.dumps(entries[0] if len(entries) == 1 else {"results": entries}))
    else:
        for entry in good:
            click.echo(_summary(entry, entry["reference_frame"], entry["target_frame"]))
        if output is not None and good:
            click.echo(f"wrote {output}")
    failures = [
        (f" [{e['kind']}]" if e.get("kind") else "") + f": {e['target']}: {e['error']}"
        for e in entries
        if "error" in e
    ]
    for message in failures:
        click.echo(f"Error{message}", err=True)
    if failures:
        sys.exit(1)


#: Exit status of ``lidarcal check`` per verdict.
CHECK_EXIT = {"consistent": 0, "inconsistent": 2, "unverifiable": 3}


@main.command("check")
@click.argument("reference", type=SourceType())
@click.argument("target", type=SourceType())
@click.option(
    "--transform",
    "transform_file",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="The reference_from_target to check: a result this tool wrote (.yaml, .json, .txt, "
    ".urdf) or a bare 4x4 text matrix.",
)
@click.option(
    "--target",
    "target_name",
    help="Which transform of a file holding several: the target's file name, stem or frame id "
    "(for URDF the joint's child link).",
)
@click.option(
    "--crop",
    metavar="XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX",
    help="Keep only points inside this box (metres, each cloud in its own frame).",
)
@click.option("--topic", help="For bags: the PointCloud2 topic (needed if there are several).")
@click.option("--time", "bag_time", type=float, help="For bags: the frame's time.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
def check_command(
    reference: Source,
    target: Source,
    transform_file: Path,
    target_name: str | None,
    crop: str | None,
    topic: str | None,
    bag_time: float | None,
    as_json: bool,
) -> None:
    """Check a stored transform against what REFERENCE and TARGET see now.

    Prints the verdict (consistent, inconsistent or unverifiable), its reason and the evidence:
    overlap, agreement with the other cloud's surface, points in the other sensor's free space,
    the correction a local re-alignment applies and the smallest errors this scene detects.

    \b
    Examples:
      lidarcal check top.pcd left.pcd --transform rig.yaml --target left
      lidarcal check top.pcd left.pcd --transform left_to_top.txt --json

    Exit status: 0 consistent, 2 inconsistent, 3 unverifiable, 1 for an error.
    """
    from lidarcal.export import read_transform

    crop_box = _floats(crop, 6, "--crop")
    try:
        transform = read_transform(transform_file, target_name)
        ref_points = load_cloud(reference, crop_box, topic, bag_time)
        tgt_points = load_cloud(target, crop_box, topic, bag_time)
        report = lidarcal.check(ref_points, tgt_points, transform)
    except (ValueError, OSError) as e:
        raise click.ClickException(str(e)) from e
    if as_json:
        out = {
            "reference": reference.text,
            "target": target.text,
            "transform": transform.tolist(),
            **report.to_dict(),
        }
        click.echo(json.dumps(out))
    else:
        click.echo(f"{target.text} -> {reference.text}: {report.verdict}")
        click.echo(f"  {report.reason}")
        click.echo(
            f"  overlap {100 * report.overlap:.0f} %, agreement {100 * report.agreement:.0f} % / "
            f"{100 * report.reverse_agreement:.0f} %, free-space violations "
            f"{100 * report.violations:.1f} % / {100 * report.reverse_violations:.1f} %"
        )
        click.echo(
            f"  correction {report.correction_rotation_deg:.3f} deg / "
            f"{100 * report.correction_translation_m:.1f} cm (agreement "
            f"{100 * report.agreement_gain:+.1f} points there); detects "
            f"{report.detectable_rotation_deg:.2f} deg / "
            f"{100 * report.detectable_translation_m:.1f} cm"
        )
    sys.exit(CHECK_EXIT[report.verdict])


@main.command("batch")
@click.argument("manifest", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="The results: .parquet or .csv, one row per job. Rows already in it are skipped "
    "(a rerun resumes).",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    help="Worker processes of the local Dask cluster (default: the core count).",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run on an existing Dask cluster (e.g. tcp://head:8786) instead of a local one.",
)
@click.option(
    "--max-in-flight",
    type=click.IntRange(min=1),
    help="Rows submitted at a time (default: twice the cluster's threads).",
)
@click.option(
    "--progress/--no-progress",
    default=None,
    help="Show a progress bar (default: when stderr is a terminal).",
)
def batch_command(
    manifest: Path,
    output: Path,
    workers: int | None,
    scheduler: str | None,
    max_in_flight: int | None,
    progress: bool | None,
) -> None:
    """Calibrate or monitor every row of MANIFEST (CSV or Parquet) on Dask.

    Columns: id, reference, target (files or BAG:/topic, read on the workers; relative to the
    manifest's folder), optional time, method, up, and transform: a stored result, which makes
    the row a monitoring row (lidarcal check) instead of a calibration. Needs
    pip install 'lidarcal[fleet]'.

    \b
    Examples:
      lidarcal batch fleet.csv --output results.parquet
      lidarcal batch fleet.parquet --output results.csv --scheduler tcp://head:8786

    Exit status: 1 when some row is an error (a missing or corrupt file, a bad row), else 2 when
    some monitoring row is inconsistent, else 0. Refusals are outcomes: they are counted in the
    closing summary and the results file, and leave the status alone.
    """
    if workers is not None and scheduler is not None:
        raise click.BadParameter("give --workers or --scheduler, not both", param_hint="--workers")
    try:
        from lidarcal import batch
    except ImportError as e:  # pragma: no cover - the fleet extra is missing
        raise click.ClickException(f"{e}; pip install 'lidarcal[fleet]'") from e
    try:
        summary = batch.run(
            manifest,
            output,
            workers=workers,
            scheduler=scheduler,
            max_in_flight=max_in_flight,
            progress=progress,
        )
    except (ValueError, OSError, ImportError) as e:
        raise click.ClickException(str(e)) from e
    click.echo(str(summary))
    for message in summary.errors:
        click.echo(f"Error {message}", err=True)
    if summary.error:
        sys.exit(1)
    if summary.inconsistent:
        sys.exit(2)


if __name__ == "__main__":  # pragma: no cover
    main()
