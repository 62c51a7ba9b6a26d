"""Scan simulator: multi-beam LiDAR models, shapes and scenes with ground truth.

Points come back in the sensor frame as ``(N, 4)`` float64 arrays ``[x, y, z, intensity]``
(``(N, 5)`` with the ring index when ``with_ring=True``), ring-major: ring 0 (the lowest beam)
first, then by azimuth counter-clockwise from the sensor's +x axis. The same ``seed`` gives
bit-identical points on any number of threads.

A keyword left ``None`` takes its default from the Rust core (the options structs of
``lidarcal::sim``), as each function's docstring says; ``lidarcal._lidarcal._defaults()`` lists
them all, and a test holds these docstrings to it.

Example::

    import numpy as np
    from lidarcal import sim

    ground = sim.rectangle([-20, -20, 0], [40, 0, 0], [0, 40, 0])
    pose = np.eye(4)
    pose[2, 3] = 2.0  # 2 m above the ground
    points = sim.scan([ground], model="vlp16", sensor_pose=pose, seed=0, with_ring=True)
    assert points.shape[1] == 5 and np.allclose(points[:, 2], -2.0, atol=0.1)

    scene = sim.corner_scene("vlp16", seed=1)
    T = scene.reference_from_target  # (4, 4) ground truth

    drive = sim.drive_scene(seed=0, frames=20)  # a front and a rear unit on a moving vehicle
    poses = drive.world_from_reference  # (20, 4, 4) true poses of the front unit
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import (
    BeamModel,
    DriveScene,
    Scene,
    Shape,
    sim_corner_scene,
    sim_corridor_scene,
    sim_drive_scene,
    sim_paper_scene,
    sim_poles_scene,
    sim_scan,
    sim_street_scene,
    write_pcd,
)

__all__ = [
    "MODELS",
    "BeamModel",
    "DriveScene",
    "Scene",
    "Shape",
    "corner_scene",
    "corridor_scene",
    "cuboid",
    "cylinder",
    "drive_scene",
    "paper_scene",
    "poles_scene",
    "rectangle",
    "scan",
    "street_scene",
    "write_pcd",
]

#: Names of the preset beam models.
MODELS = ("vlp16", "hdl32", "hdl64", "os128")

Model = str | BeamModel
Intensity = tuple[float, float]


def rectangle(
    corner: npt.ArrayLike,
    edge_u: npt.ArrayLike,
    edge_v: npt.ArrayLike,
    *,
    intensity: Intensity | None = None,
) -> Shape:
    """A rectangle ``corner + s * edge_u + t * edge_v`` (``s, t`` in [0, 1], edges orthogonal).

    Default (Rust ``IntensityRange::WALL``): ``intensity=(20, 70)``.

    >>> wall = rectangle([0, 0, 0], [10, 0, 0], [0, 0, 3])
    """
    return Shape.rectangle(corner, edge_u, edge_v, intensity=intensity)


def cuboid(
    size: npt.ArrayLike,
    pose: npt.ArrayLike | None = None,
    *,
    intensity: Intensity | None = None,
) -> Shape:
    """A box of full ``size`` centred at the origin of ``pose`` (4x4 ``world_from_box``).

    Default (Rust ``IntensityRange::CLUTTER``): ``intensity=(10, 90)``.

    >>> crate = cuboid([1.0, 1.0, 1.0])
    """
    return Shape.cuboid(size, pose, intensity=intensity)


def cylinder(
    base: npt.ArrayLike,
    direction: npt.ArrayLike,
    length: float,
    radius: float,
    *,
    intensity: Intensity | None = None,
    band: tuple[float, float] | None = None,
    band_intensity: Intensity | None = None,
) -> Shape:
    """A finite cylinder (a pole), optionally with a taped ``band`` (metres from the base).

    Defaults (Rust ``IntensityRange::POLE`` and ``RETROREFLECTIVE``): ``intensity=(30, 80)``,
    ``band_intensity=(235, 255)``.

    >>> pole = cylinder([5, 0, 0], [0, 0, 1], 3.0, 0.1, band=(0.5, 2.5))
    """
    return Shape.cylinder(
        base,
        direction,
        length,
        radius,
        intensity=intensity,
        band=band,
        band_intensity=band_intensity,
    )


def scan(
    shapes: Sequence[Shape],
    model: Model | None = None,
    sensor_pose: npt.ArrayLike | None = None,
    *,
    seed: int = 0,
    noise: float | None = None,
    dropout: float | None = None,
    with_ring: bool = False,
) -> npt.NDArray[np.float64]:
    """One revolution of ``model`` at ``sensor_pose`` (4x4 ``world_from_sensor``, default identity).

    ``noise`` overrides the model's range noise (metres, 1 sigma); ``dropout`` is the probability
    that a return is lost. Raises ``ValueError`` for bad input (unknown model, non-rigid pose,
    dropout outside [0, 1], negative noise).

    Defaults (Rust ``Preset::default()`` and ``ScanOptions::default()``): ``model='vlp16'``,
    ``dropout=0``.
    """
    return sim_scan(
        shapes,
        model,
        sensor_pose,
        seed=seed,
        noise=noise,
        dropout=dropout,
        with_ring=with_ring,
    )


def corner_scene(
    model: Model | None = None,
    *,
    seed: int = 0,
    clutter_boxes: int | None = None,
    extra_walls: int | None = None,
    noise: float | None = None,
    dropout: float | None = None,
    wall_angle_deg: float | None = None,
    target_tilt_deg: float | None = None,
    target_relative_yaw_deg: float | None = None,
) -> Scene:
    """A building corner (two walls and the ground) scanned by two spinning LiDARs.

    ``scene.planes`` holds wall 1, wall 2, the ground and any extra walls in the reference frame.
    ``wall_angle_deg`` is the angle between the walls (90 makes a cube corner with the ground,
    which the planar method can only match with ``up``); the target sensor is tilted by up to
    ``target_tilt_deg`` and turned by ``target_relative_yaw_deg`` (random when None); ``noise``
    None is the model's own.

    Defaults (Rust ``CornerOptions::default()``): ``model='vlp16'``, ``clutter_boxes=4``,
    ``extra_walls=0``, ``dropout=0``, ``wall_angle_deg=90``, ``target_tilt_deg=10``.

    >>> scene = corner_scene("vlp16", seed=0, clutter_boxes=0)
    >>> scene.planes.shape
    (3, 4)
    """
    return sim_corner_scene(
        model,
        seed=seed,
        clutter_boxes=clutter_boxes,
        extra_walls=extra_walls,
        noise=noise,
        dropout=dropout,
        wall_angle_deg=wall_angle_deg,
        target_tilt_deg=target_tilt_deg,
        target_relative_yaw_deg=target_relative_yaw_deg,
    )


def poles_scene(
    model: Model | None = None,
    *,
    seed: int = 0,
    radius: float | None = None,
    distance: float | None = None,
    distractor: bool | None = None,
    noise: float | None = None,
    dropout: float | None = None,
    max_tilt_deg: float | None = None,
    target_upside_down: bool | None = None,
) -> Scene:
    """Two non-parallel taped poles and the ground, optionally a bright road sign.

    ``scene.pole_axes`` and ``scene.pole_radii`` hold the truth. Each sensor's roll and pitch are
    drawn within ``max_tilt_deg``; ``target_upside_down`` adds a 180 degree roll to the target.

    Defaults (Rust ``PolesOptions::default()``, the noise its ``POLES_RANGE_NOISE``):
    ``model='vlp16'``, ``radius=0.1``, ``distance=5``, ``distractor=False``, ``noise=0.006``,
    ``dropout=0``, ``max_tilt_deg=15``, ``target_upside_down=False``.

    >>> scene = poles_scene(seed=0)
    >>> scene.pole_axes.shape
    (2, 6)
    """
    return sim_poles_scene(
        model,
        seed=seed,
        radius=radius,
        distance=distance,
        distractor=distractor,
        noise=noise,
        dropout=dropout,
        max_tilt_deg=max_tilt_deg,
        target_upside_down=target_upside_down,
    )


def street_scene(
    *,
    seed: int = 0,
    side: str | None = None,
    target_tilt_deg: float | None = None,
    clutter: bool | None = None,
    cross_wall: bool | None = None,
    noise: float | None = None,
    target_offset: float | None = None,
) -> Scene:
    """A street (road, kerbs, pavements, facades with gaps; parked cars, trees and poles with
    ``clutter``) scanned by a roof HDL-64E (the reference) and a wide-angle side unit tilted
    ``target_tilt_deg`` down on the ``side`` ("left" or "right"), as on the real road rigs.
    ``target_offset`` (metres, in [-5, 5]) moves the side unit along the vehicle (-3: at the back
    of a car), where the street's own planes no longer fix its position.

    Defaults (Rust ``StreetOptions::default()``): ``side='left'``, ``target_tilt_deg=45``,
    ``clutter=True``, ``cross_wall=False``, ``target_offset=0``; ``noise`` None is each model's own.
    """
    if side is not None and side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return sim_street_scene(
        seed=seed,
        side=None if side is None else "left" if side == "left" else "right",
        target_tilt_deg=target_tilt_deg,
        clutter=clutter,
        cross_wall=cross_wall,
        noise=noise,
        target_offset=target_offset,
    )


def corridor_scene(seed: int = 0) -> Scene:
    """A floor and two parallel walls longer than the sensors' range: the translation along the
    corridor is unobservable, and :func:`lidarcal.calibrate_targetless` must refuse it."""
    return sim_corridor_scene(seed=seed)


def paper_scene(
    alpha_deg: float | None = None, configuration: int | None = 1, seed: int = 0
) -> Scene:
    """The planar-surfaces paper's synthetic protocol (9500 sampled points per sensor).

    ``configuration`` is 1 or 2 (the paper's Table II) or ``None`` (drawn from ``seed``).
    Default (Rust ``PaperOptions::default()``): ``alpha_deg=90``.

    >>> paper_scene(60.0, 2).reference.shape
    (9500, 4)
    """
    return sim_paper_scene(alpha_deg=alpha_deg, configuration=configuration, seed=seed)


def drive_scene(
    seed: int = 0,
    *,
    frames: int = 200,
    rate_hz: float = 10.0,
    body_motion: bool = True,
    ground: bool = True,
    field_of_view_deg: float = 120.0,
    range_noise: float | None = None,
) -> DriveScene:
    """A vehicle driving an S through a town, with two units that never see the same thing.

    The vehicle drives a staircase route (blocks of 40-55 m joined by 90 degree arcs of 9 m
    radius, alternately left and right) at 7 m/s on flat ground (z = 0) for ``frames`` frames at
    ``rate_hz`` (20 s and two or three turns by default), past facades, cross walls at the
    junctions, parked cars, trees and poles. The reference unit is at the front (about 1.8 m
    forward, 0.6-1.1 m up, looking forward), the target at the rear (about 2.5 m back, looking
    backward), each with a few degrees and centimetres of random mounting error, both a 64-beam
    model (-25 to +15 degrees, 0.2 degree columns, 0.5-100 m, ``range_noise`` None: 1 cm) limited
    to ``field_of_view_deg`` about its +x axis: at 120 degrees their fields never meet. Both units
    scan at the same instants (no motion distortion). A default frame holds about 37,500 points
    from the front unit and 36,000 from the rear one; the drive takes about 11 s on two cores.

    ``body_motion`` adds pitch and roll of about 0.5-1.5 degrees (sinusoids and the lean in turns)
    and a centimetre of bounce; without it the motion is planar, which leaves the units' height
    offset unobservable from motion. ``ground=False`` drops the ground's returns.

    The result holds ``reference_frames`` and ``target_frames`` (lists of read-only ``(N, 4)``
    float64 arrays ``[x, y, z, intensity]``, each in its unit's frame), ``reference_labels`` and
    ``target_labels`` (the shape each point hit, 0 the ground), ``reference_from_target``
    ``(4, 4)``, ``world_from_reference`` and ``world_from_target`` ``(K, 4, 4)`` and ``times``
    ``(K,)``. Raises ``ValueError`` for options out of range (frames in 2..3000, rate in (0, 100]
    Hz, field of view in (0, 360] degrees, noise in [0, 10] m).

    >>> drive = drive_scene(seed=0, frames=2)
    >>> drive.world_from_reference.shape, drive.reference_frames[0].shape[1]
    ((2, 4, 4), 4)
    """
    return sim_drive_scene(
        seed,
        frames=frames,
        rate_hz=rate_hz,
        body_motion=body_motion,
        ground=ground,
        field_of_view_deg=field_of_view_deg,
        range_noise=range_noise,
    )
