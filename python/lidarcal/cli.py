"""The ``lidarcal`` command line.

``lidarcal simulate --scene corner --model vlp16 --seed 0 --output out/`` writes
``reference.pcd``, ``target.pcd`` and ``ground_truth.json`` (transforms and true geometry).
"""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from lidarcal import __version__, sim


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


if __name__ == "__main__":  # pragma: no cover
    main()
