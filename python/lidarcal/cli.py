"""The ``lidarcal`` command line.

``lidarcal demo`` simulates a building corner seen by two LiDARs, calibrates it with no initial
guess and prints the ground truth, the estimate and the errors (``--json`` for scripts).

``lidarcal simulate --scene corner --model vlp16 --seed 0 --output out/`` writes
``reference.pcd``, ``target.pcd`` and ``ground_truth.json`` (transforms and true geometry).
"""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from lidarcal import CalibrationError, __version__, calibrate_planes, sim


@click.group()
@click.version_option(__version__, prog_name="lidarcal")
def main() -> None:
    """Extrinsic calibration between LiDARs."""


@main.command()
@click.option(
    "--scene",
    "scene_name",
    type=click.Choice(["corner", "poles", "paper"]),
    default="corner",
    show_default=True,
)
@click.option("--model", type=click.Choice(list(sim.MODELS)), default="vlp16", show_default=True)
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
def simulate(scene_name: str, model: str, seed: int, output: Path, fmt: str, ascii: bool) -> None:
    """Simulate a scene seen by two sensors and write one file per sensor plus ground truth.

    The paper scene samples points (no beam model); --model is ignored for it.
    """
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


def _rpy_deg(transform: np.ndarray) -> list[float]:
    """Roll, pitch, yaw (degrees) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r = transform[:3, :3]
    pitch = np.arcsin(np.clip(-r[2, 0], -1.0, 1.0))
    roll = np.arctan2(r[2, 1], r[2, 2])
    yaw = np.arctan2(r[1, 0], r[0, 0])
    return [float(np.degrees(a)) for a in (roll, pitch, yaw)]


def _errors(truth: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    """Rotation error (angle of R_true R^T, degrees) and translation error (metres)."""
    d = truth[:3, :3] @ estimate[:3, :3].T
    angle = np.arctan2(
        0.5 * np.linalg.norm([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]),
        0.5 * (np.trace(d) - 1.0),
    )
    return float(np.degrees(angle)), float(np.linalg.norm(truth[:3, 3] - estimate[:3, 3]))


@main.command()
@click.option("--model", type=click.Choice(list(sim.MODELS)), default="vlp16", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True, help="Scene and sampler seed.")
@click.option(
    "--wall-angle",
    type=float,
    default=90.0,
    show_default=True,
    help="Angle between the two walls, degrees.",
)
@click.option(
    "--tilt",
    type=float,
    default=10.0,
    show_default=True,
    help="Largest roll/pitch of the second sensor, degrees.",
)
@click.option("--clutter", type=int, default=4, show_default=True, help="Clutter boxes.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
def demo(
    model: str, seed: int, wall_angle: float, tilt: float, clutter: int, as_json: bool
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
    report = {
        "method": result.method,
        "model": model,
        "seed": seed,
        "points": [len(scene.reference), len(scene.target)],
        "transform": result.transform.tolist(),
        "ground_truth": truth.tolist(),
        "rotation_error_deg": rot_err,
        "translation_error_m": trans_err,
        "converged": result.converged,
        "rmse": result.rmse.tolist(),
        "timings_ms": result.timings,
    }
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
        f"  converged {result.converged}, plane rmse "
        f"{', '.join(f'{100 * r:.2f}' for r in result.rmse)} cm, "
        f"{result.timings['total']:.1f} ms"
    )


if __name__ == "__main__":  # pragma: no cover
    main()
