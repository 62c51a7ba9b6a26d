"""Randomized hard-but-realistic two-sensor scenes with known ground truth, for benchmarking
how often a calibration method returns a *wrong* answer instead of refusing.

Each family draws sizes, angles, positions, sensor heights (1-2.5 m), headings (anywhere), small
tilts and now and then a sensor mounted on its side, from the seed alone::

    from lidarcal import scenarios

    s = scenarios.make("poles", 17)
    s.reference, s.target          # (N, 4) x, y, z, intensity, each in its sensor's frame
    s.reference_from_target        # (4, 4) truth: p_ref = R p_tgt + t
    s.solvable                     # True / False / None (not sure)
    s.methods                      # the methods worth calling on it

Families (:data:`FAMILIES`):

* ``corner`` -- a building corner (walls 60-120 deg apart and the ground) with clutter, sometimes
  a far wall nearly parallel to one of the corner's walls. Solvable when both sensors see both
  walls and the ground.
* ``poles`` -- two or three taped poles among distractors (a bright but untaped facade, a car, a
  box, a road sign); sometimes one pole barely seen (far, occluded or with a short band). Solvable
  is decided from the scans: the taped returns of each pole in each sensor.
* ``partial`` -- a street seen by two sensors 3-8 m apart that share only part of the view
  (solvable left None).
* ``corridor`` -- corridors (unobservable along the axis: not solvable) and rooms (solvable
  when something breaks their symmetry, not when a rectangular room is empty).
* ``repeated`` -- identical boxes, poles or columns in a row with little else: symmetric (not
  solvable) unless an asymmetric element is seen by both sensors.

The world frame of every scene is the scene's own; the truth is
``inv(world_from_reference) @ world_from_target``.

:func:`degrade` puts a scene under a condition the families never draw (:data:`CONDITIONS`):
a narrow field of view, a sparse target, spurious returns. The truth stays; what is known
about solvability is kept only where the condition cannot change it::

    s = scenarios.degrade(scenarios.make("corner", 3), "narrow-fov")
"""

from __future__ import annotations

import dataclasses
import functools
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lidarcal import sim

__all__ = ["CONDITIONS", "FAMILIES", "TAPE_INTENSITY", "Scenario", "degrade", "make"]

F64Array = npt.NDArray[np.float64]
#: Decides solvability from both scans (world frame) and their intensities: (verdict, evidence).
Judge = Callable[[F64Array, F64Array, F64Array, F64Array], tuple[bool | None, str]]

#: The scene families :func:`make` knows.
FAMILIES: tuple[str, ...] = ("corner", "poles", "partial", "corridor", "repeated")

#: The conditions :func:`degrade` knows ("none" leaves a scene as it is).
CONDITIONS: tuple[str, ...] = (
    "none",
    "narrow-fov",
    "half-fov-target",
    "sparse-target",
    "outliers",
)

#: Returns at or above this intensity count as retro-reflective tape (Velodyne's 230).
TAPE_INTENSITY = 230.0

WALL = (20.0, 70.0)
GROUND = (5.0, 40.0)
CLUTTER = (10.0, 90.0)
PAINT = (30.0, 80.0)
TAPE = (235.0, 255.0)

#: Points a sensor must put on a plane for the plane to count as seen.
PLANE_SEEN = 150
#: Taped points per pole and sensor above which a pole is well seen, and below which barely.
POLE_WELL_SEEN = 30
POLE_BARELY_SEEN = 10
#: Points a sensor must put on an asymmetric element for it to count as seen.
ELEMENT_SEEN = 80


@dataclass(frozen=True, eq=False)
class Scenario:
    """One scene: both scans in their sensors' frames, the truth and what is known about it.

    ``solvable`` is True when the scene determines the transform (a method may still refuse it:
    "refused though solvable"), False when it provably does not (a symmetry, an unobservable
    direction, a pole not seen), None when it is unclear. ``methods`` are the method names worth
    passing to :func:`lidarcal.calibrate` (always ``"auto"`` and ``"targetless"``).
    """

    family: str
    seed: int
    reference: F64Array
    target: F64Array
    reference_from_target: F64Array
    solvable: bool | None
    description: str
    methods: tuple[str, ...]


# ---------------------------------------------------------------------------------------------
# Geometry helpers.


def _rz(a: float) -> F64Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> F64Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(a: float) -> F64Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _pose(position: npt.ArrayLike, rotation: F64Array | None = None) -> F64Array:
    out = np.eye(4)
    if rotation is not None:
        out[:3, :3] = rotation
    out[:3, 3] = np.asarray(position, dtype=np.float64)
    return out


def _inv(pose: F64Array) -> F64Array:
    out = np.eye(4)
    out[:3, :3] = pose[:3, :3].T
    out[:3, 3] = -pose[:3, :3].T @ pose[:3, 3]
    return out


def _heading(a: float) -> F64Array:
    return np.array([math.cos(a), math.sin(a), 0.0])


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _chance(rng: np.random.Generator, p: float) -> bool:
    return bool(rng.uniform() < p)


def _angle_between(a: F64Array, b: F64Array) -> float:
    """Angle between two lines (directions up to sign), radians."""
    c = abs(float(a @ b)) / (float(np.linalg.norm(a)) * float(np.linalg.norm(b)))
    return math.acos(min(1.0, c))


# ---------------------------------------------------------------------------------------------
# Sensors.


@functools.lru_cache(maxsize=1)
def _hdl32() -> sim.BeamModel:
    # An HDL-32E at 20 Hz (about 1100 columns per revolution): keeps the scans modest.
    return sim.BeamModel.custom(
        np.linspace(-30.67, 10.67, 32),
        columns=1100,
        min_range=1.0,
        max_range=100.0,
        range_noise=0.01,
        name="hdl32",
    )


@dataclass(frozen=True)
class _Sensor:
    world_from_sensor: F64Array
    model: str
    noise: float | None
    dropout: float
    note: str


def _sensor(
    rng: np.random.Generator,
    position: npt.ArrayLike,
    *,
    tilt_deg: float,
    side_prob: float = 0.0,
    flip_prob: float = 0.0,
    pitch_prob: float = 0.0,
    hdl32_prob: float = 0.2,
) -> _Sensor:
    """A spinning LiDAR at ``position`` with any heading, a tilt within ``tilt_deg``, and with
    the given probabilities mounted on its side (spin axis horizontal), upside down, or pitched
    20-40 degrees down (as the side units of a road rig)."""
    t = math.radians(tilt_deg)
    rotation = _rz(_u(rng, 0.0, math.tau)) @ _ry(_u(rng, -t, t)) @ _rx(_u(rng, -t, t))
    notes = []
    u = rng.uniform()
    if u < side_prob:
        rotation = rotation @ _rx(math.copysign(math.pi / 2, rng.uniform() - 0.5))
        notes.append("on its side")
    elif u < side_prob + flip_prob:
        rotation = rotation @ _rx(math.pi)
        notes.append("upside down")
    elif u < side_prob + flip_prob + pitch_prob:
        pitch = _u(rng, 20.0, 40.0)
        rotation = rotation @ _ry(math.radians(pitch))
        notes.append(f"pitched {pitch:.0f} deg down")
    model = "hdl32" if _chance(rng, hdl32_prob) else "vlp16"
    noise = None if _chance(rng, 0.7) else _u(rng, 0.01, 0.03)
    dropout = 0.0 if _chance(rng, 0.8) else _u(rng, 0.05, 0.3)
    if noise is not None:
        notes.append(f"noise {100 * noise:.1f} cm")
    if dropout > 0:
        notes.append(f"dropout {dropout:.2f}")
    note = model + (f" ({', '.join(notes)})" if notes else "")
    return _Sensor(_pose(position, rotation), model, noise, dropout, note)


def _scan(rng: np.random.Generator, shapes: Sequence[sim.Shape], sensor: _Sensor) -> F64Array:
    model: str | sim.BeamModel = _hdl32() if sensor.model == "hdl32" else sensor.model
    return sim.scan(
        shapes,
        model,
        sensor.world_from_sensor,
        seed=int(rng.integers(0, 2**62)),
        noise=sensor.noise,
        dropout=sensor.dropout,
    )


def _world(points: F64Array, sensor: _Sensor) -> F64Array:
    pose = sensor.world_from_sensor
    out: F64Array = points[:, :3] @ pose[:3, :3].T + pose[:3, 3]
    return out


# ---------------------------------------------------------------------------------------------
# Point counts on the scene's elements (world frame), to decide solvability from the scans.


@dataclass(frozen=True)
class _Rect:
    corner: F64Array
    edge_u: F64Array
    edge_v: F64Array

    def shape(self, intensity: tuple[float, float]) -> sim.Shape:
        return sim.rectangle(self.corner, self.edge_u, self.edge_v, intensity=intensity)

    def count(self, xyz: F64Array, tol: float = 0.08) -> int:
        n = np.cross(self.edge_u, self.edge_v)
        n = n / np.linalg.norm(n)
        d = xyz - self.corner
        s = d @ self.edge_u / float(self.edge_u @ self.edge_u)
        t = d @ self.edge_v / float(self.edge_v @ self.edge_v)
        inside = (np.abs(d @ n) < tol) & (s > -0.01) & (s < 1.01) & (t > -0.01) & (t < 1.01)
        return int(np.count_nonzero(inside))


def _wall(start: npt.ArrayLike, direction: F64Array, length: float, height: float) -> _Rect:
    d = direction / np.linalg.norm(direction)
    return _Rect(np.asarray(start, dtype=np.float64), d * length, np.array([0.0, 0.0, height]))


def _floor(xmin: float, ymin: float, xmax: float, ymax: float, z: float = 0.0) -> _Rect:
    return _Rect(
        np.array([xmin, ymin, z]),
        np.array([xmax - xmin, 0.0, 0.0]),
        np.array([0.0, ymax - ymin, 0.0]),
    )


@dataclass(frozen=True)
class _Box:
    size: F64Array
    pose: F64Array

    def shape(self, intensity: tuple[float, float] = CLUTTER) -> sim.Shape:
        return sim.cuboid(self.size, self.pose, intensity=intensity)

    def count(self, xyz: F64Array, margin: float = 0.06) -> int:
        local = (xyz - self.pose[:3, 3]) @ self.pose[:3, :3]
        inside = np.all(np.abs(local) <= 0.5 * self.size + margin, axis=1)
        return int(np.count_nonzero(inside))


def _box(center_xy: npt.ArrayLike, size: npt.ArrayLike, yaw: float, z0: float = 0.0) -> _Box:
    s = np.asarray(size, dtype=np.float64)
    c = np.asarray(center_xy, dtype=np.float64)
    return _Box(s, _pose([c[0], c[1], z0 + 0.5 * s[2]], _rz(yaw)))


@dataclass(frozen=True)
class _Pole:
    base: F64Array
    axis: F64Array
    length: float
    radius: float
    band: tuple[float, float] | None

    def shape(self) -> sim.Shape:
        return sim.cylinder(
            self.base,
            self.axis,
            self.length,
            self.radius,
            intensity=PAINT,
            band=self.band,
            band_intensity=TAPE,
        )

    def tape_count(self, xyz: F64Array, intensity: F64Array) -> int:
        if self.band is None:
            return 0
        d = xyz - self.base
        along = d @ self.axis
        radial = np.linalg.norm(d - np.outer(along, self.axis), axis=1)
        near = (
            (intensity >= TAPE_INTENSITY)
            & (radial < self.radius + 0.06)
            & (along > self.band[0] - 0.05)
            & (along < self.band[1] + 0.05)
        )
        return int(np.count_nonzero(near))


def _tilted_axis(rng: np.random.Generator, max_tilt_deg: float) -> F64Array:
    tilt = math.radians(_u(rng, 0.0, max_tilt_deg))
    h = _u(rng, 0.0, math.tau)
    return np.array([math.sin(tilt) * math.cos(h), math.sin(tilt) * math.sin(h), math.cos(tilt)])


class _Layout:
    """Horizontal discs already taken, to place new objects clear of them."""

    def __init__(self) -> None:
        self.discs: list[tuple[float, float, float]] = []

    def take(self, xy: npt.ArrayLike, radius: float) -> None:
        p = np.asarray(xy, dtype=np.float64)
        self.discs.append((float(p[0]), float(p[1]), radius))

    def free(self, xy: npt.ArrayLike, radius: float) -> bool:
        p = np.asarray(xy, dtype=np.float64)
        return all(math.hypot(p[0] - x, p[1] - y) > r + radius for x, y, r in self.discs)


def _place(
    rng: np.random.Generator,
    layout: _Layout,
    around: npt.ArrayLike,
    distance: tuple[float, float],
    radius: float,
    *,
    attempts: int = 50,
) -> F64Array | None:
    """A free horizontal position ``distance`` from ``around`` (any bearing), or None."""
    c = np.asarray(around, dtype=np.float64)[:2]
    for _ in range(attempts):
        p = c + _u(rng, *distance) * _heading(_u(rng, 0.0, math.tau))[:2]
        if layout.free(p, radius):
            layout.take(p, radius)
            return p
    return None


def _rig_positions(
    rng: np.random.Generator,
    reference_xy: npt.ArrayLike,
    spacing: tuple[float, float],
    heights: tuple[float, float] = (1.0, 2.5),
    ok: Callable[[F64Array], bool] | None = None,
) -> tuple[F64Array, F64Array]:
    """The reference at ``reference_xy`` and the target ``spacing`` from it (where ``ok``)."""
    r = np.asarray(reference_xy, dtype=np.float64)
    t = r + spacing[0] * _heading(0.0)[:2]
    for _ in range(100):
        t = r + _u(rng, *spacing) * _heading(_u(rng, 0.0, math.tau))[:2]
        if ok is None or ok(t):
            break
    return (
        np.array([r[0], r[1], _u(rng, *heights)]),
        np.array([t[0], t[1], _u(rng, *heights)]),
    )


# ---------------------------------------------------------------------------------------------
# Families. Each returns the shapes, both sensors, and a function of the two world-frame scans
# that gives (solvable, note).


@dataclass
class _Build:
    shapes: list[sim.Shape]
    reference: _Sensor
    target: _Sensor
    description: str
    methods: tuple[str, ...]
    judge: Judge


def _corner(rng: np.random.Generator) -> _Build:
    angle = _u(rng, 60.0, 120.0)
    a = math.radians(angle)
    d1, d2 = _heading(0.0), _heading(a)
    n1, n2 = np.array([0.0, 1.0, 0.0]), np.array([math.sin(a), -math.cos(a), 0.0])  # inward
    l1 = _u(rng, 8.0, 25.0)
    l2 = _u(rng, 2.5, 6.0) if _chance(rng, 0.25) else _u(rng, 8.0, 25.0)
    wall1 = _wall([0.0, 0.0, 0.0], d1, l1, _u(rng, 3.0, 10.0))
    wall2 = _wall([0.0, 0.0, 0.0], d2, l2, _u(rng, 3.0, 10.0))
    ground = _floor(-40.0, -40.0, 40.0, 40.0)
    flats = [ground]  # the ground, and the top of a pavement if there is one
    shapes = [wall1.shape(WALL), wall2.shape(WALL), ground.shape(GROUND)]
    notes = [f"walls {angle:.1f} deg apart, {l1:.1f} and {l2:.1f} m long"]
    # Sometimes a courtyard: a third wall turns off the far end of wall 1 (a second corner).
    inward = [(np.zeros(3), n1), (np.zeros(3), n2)]
    if _chance(rng, 0.3):
        b = math.radians(_u(rng, 60.0, 120.0))
        d3 = _heading(math.pi - b)
        wall3 = _wall([l1, 0.0, 0.0], d3, _u(rng, 6.0, 20.0), _u(rng, 3.0, 10.0))
        shapes.append(wall3.shape(WALL))
        inward.append((np.array([l1, 0.0, 0.0]), _rz(math.pi / 2) @ d3))
        notes.append(f"a second corner of {math.degrees(b):.1f} deg at the end of wall 1")

    def inside(p: F64Array, margin: float) -> bool:
        q = np.array([p[0], p[1], 0.0])
        return all(float((q - o) @ n) > margin for o, n in inward)

    reach = 0.75 * min(l1, max(l2, 6.0))
    ref_xy = np.zeros(2)
    for _ in range(200):
        theta = _u(rng, 0.15, 0.85) * a
        ref_xy = _u(rng, 3.0, max(3.5, reach)) * _heading(theta)[:2]
        if inside(ref_xy, 1.5):
            break
    p_ref, p_tgt = _rig_positions(rng, ref_xy, (0.3, 2.0), ok=lambda p: inside(np.asarray(p), 1.0))
    layout = _Layout()
    layout.take(p_ref[:2], 1.0)
    layout.take(p_tgt[:2], 1.0)

    if _chance(rng, 0.3):
        # A raised pavement along wall 1: a second horizontal plane a kerb above the road.
        width, kerb = _u(rng, 1.5, 4.0), _u(rng, 0.1, 0.2)
        x0 = _u(rng, -2.0, 0.0)
        span = l1 - x0 + _u(rng, 0.0, 3.0)
        pavement = _box([x0 + 0.5 * span, 0.5 * width], [span, width, kerb], 0.0)
        shapes.append(pavement.shape(GROUND))
        flats.append(_floor(x0, 0.0, x0 + span, width, kerb))
        for p in (p_ref, p_tgt):
            if x0 < p[0] < x0 + span and 0.0 < p[1] < width:
                p[2] += kerb
        notes.append(f"a pavement {width:.1f} m wide and {100 * kerb:.0f} cm high along wall 1")
    if _chance(rng, 0.2):
        size = np.array([_u(rng, 6.0, 12.0), 2.4, 2.6])
        half = 0.5 * float(np.linalg.norm(size[:2]))
        for _ in range(30):
            p = _u(rng, 4.0, 16.0) * _heading(_u(rng, 0.1, 0.9) * a)[:2]
            if inside(p, half + 0.1) and layout.free(p, half):
                layout.take(p, half)
                shapes.append(_box(p, size, _u(rng, 0.0, math.pi)).shape())
                notes.append(f"a {size[0]:.1f} m container")
                break

    boxes = 0
    for _ in range(int(rng.integers(0, 6))):
        car = _chance(rng, 0.25)
        size = (
            np.array([_u(rng, 4.2, 4.8), _u(rng, 1.7, 1.9), _u(rng, 1.4, 1.7)])
            if car
            else np.array([_u(rng, 0.5, 2.5), _u(rng, 0.5, 2.5), _u(rng, 0.4, 2.0)])
        )
        half = 0.5 * float(np.linalg.norm(size[:2]))
        for _ in range(30):
            p = _u(rng, 2.0, 15.0) * _heading(_u(rng, 0.1, 0.9) * a)[:2]
            if inside(p, half + 0.1) and layout.free(p, half):
                layout.take(p, half)
                shapes.append(_box(p, size, _u(rng, 0.0, math.pi)).shape())
                boxes += 1
                break
    if boxes:
        notes.append(f"{boxes} clutter boxes")
    if _chance(rng, 0.6):
        for _ in range(30):
            p = _u(rng, 2.0, 12.0) * _heading(_u(rng, 0.1, 0.9) * a)[:2]
            if inside(p, 0.5) and layout.free(p, 0.3):
                layout.take(p, 0.3)
                pole = _Pole(
                    np.array([p[0], p[1], 0.0]),
                    _tilted_axis(rng, 5.0),
                    _u(rng, 2.5, 5.0),
                    _u(rng, 0.05, 0.2),
                    None,
                )
                shapes.append(pole.shape())
                notes.append("an untaped pole")
                break
    if _chance(rng, 0.35):
        # A far wall nearly parallel to one of the corner's walls, beyond the sensors.
        k = int(rng.integers(0, 2))
        d, n = (d1, n1) if k == 0 else (d2, n2)
        beyond = max(float(p_ref @ n), float(p_tgt @ n)) + _u(rng, 4.0, 15.0)
        delta = math.radians(_u(rng, -12.0, 12.0))
        start = n * beyond + d * _u(rng, -5.0, 5.0)
        far = _wall(start, _rz(delta) @ d, _u(rng, 8.0, 30.0), _u(rng, 3.0, 10.0))
        shapes.append(far.shape(WALL))
        notes.append(
            f"a far wall {beyond:.1f} m out, {math.degrees(delta):+.1f} deg off wall {k + 1}"
        )

    side = int(rng.integers(0, 2)) if _chance(rng, 0.2) else -1
    reference = _sensor(rng, p_ref, tilt_deg=5.0, side_prob=1.0 if side == 0 else 0.0)
    target = _sensor(
        rng,
        p_tgt,
        tilt_deg=12.0,
        side_prob=1.0 if side == 1 else 0.0,
        flip_prob=0.05,
        pitch_prob=0.15,
    )

    def judge(
        ref: F64Array, tgt: F64Array, _ri: F64Array, _ti: F64Array
    ) -> tuple[bool | None, str]:
        counts = [
            [wall1.count(xyz), wall2.count(xyz), sum(f.count(xyz) for f in flats)]
            for xyz in (ref, tgt)
        ]
        seen = all(c >= PLANE_SEEN for row in counts for c in row)
        return (
            True if seen else None
        ), f"wall1/wall2/ground points ref {counts[0]} tgt {counts[1]}"

    return _Build(
        shapes, reference, target, "; ".join(notes), ("auto", "planes", "targetless"), judge
    )


def _poles(rng: np.random.Generator) -> _Build:
    ground = _floor(-50.0, -50.0, 50.0, 50.0)
    shapes = [ground.shape(GROUND)]
    p_ref, p_tgt = _rig_positions(rng, [0.0, 0.0], (0.4, 2.0))
    layout = _Layout()
    layout.take(p_ref[:2], 1.2)
    layout.take(p_tgt[:2], 1.2)
    center = 0.5 * (p_ref + p_tgt)

    n_poles = 3 if _chance(rng, 0.3) else 2
    axes = [_tilted_axis(rng, 20.0)]
    while len(axes) < n_poles:
        a = _tilted_axis(rng, 20.0)
        if len(axes) > 1 or _angle_between(a, axes[0]) >= math.radians(6.0):
            axes.append(a)
    hard = str(rng.choice(["far", "occluded", "short"])) if _chance(rng, 0.35) else ""
    poles: list[_Pole] = []
    for i, axis in enumerate(axes):
        victim = hard != "" and i == n_poles - 1
        distance = (18.0, 35.0) if victim and hard == "far" else (3.0, 9.0)
        xy = _place(rng, layout, center, distance, 0.8)
        if xy is None:
            xy = center[:2] + distance[1] * _heading(_u(rng, 0.0, math.tau))[:2]
        length = _u(rng, 2.5, 4.0)
        if victim and hard == "short":
            lo = _u(rng, 0.5, 1.5)
            band = (lo, lo + _u(rng, 0.05, 0.25))
        else:
            band = (_u(rng, 0.2, 0.8), _u(rng, 1.8, length - 0.1))
        poles.append(_Pole(np.array([xy[0], xy[1], 0.0]), axis, length, _u(rng, 0.05, 0.15), band))
    shapes.extend(p.shape() for p in poles)
    notes = [f"{n_poles} taped poles"]
    if hard == "occluded":
        victim_pole = poles[-1]
        eye = p_ref if _chance(rng, 0.5) else p_tgt
        los = eye[:2] - victim_pole.base[:2]
        dist = float(np.linalg.norm(los))
        los /= dist
        where = victim_pole.base[:2] + los * min(_u(rng, 0.8, 1.5), 0.5 * dist)
        top = victim_pole.band[1] if victim_pole.band else 2.0
        size = [_u(rng, 0.3, 0.6), _u(rng, 0.9, 1.6), top + _u(rng, -0.3, 0.5)]
        shapes.append(_box(where, size, math.atan2(los[1], los[0])).shape())
        notes.append("one pole mostly occluded")
    elif hard:
        notes.append({"far": "one pole far away", "short": "one pole with a short band"}[hard])

    if _chance(rng, 0.5):
        bearing = _u(rng, 0.0, math.tau)
        dist = _u(rng, 6.0, 15.0)
        length = _u(rng, 6.0, 20.0)
        facing = _heading(bearing)
        along = _rz(math.pi / 2) @ facing
        start = center + facing * dist - along * 0.5 * length
        lo = _u(rng, 150.0, 190.0)
        facade = _wall([start[0], start[1], 0.0], along, length, _u(rng, 3.0, 8.0))
        shapes.append(facade.shape((lo, min(220.0, lo + _u(rng, 10.0, 30.0)))))
        notes.append("a bright facade")
    if _chance(rng, 0.7):
        xy = _place(rng, layout, center, (4.0, 12.0), 2.5)
        if xy is not None:
            size = [_u(rng, 4.2, 4.8), _u(rng, 1.7, 1.9), _u(rng, 1.4, 1.7)]
            shapes.append(_box(xy, size, _u(rng, 0.0, math.pi)).shape())
            notes.append("a car")
    if _chance(rng, 0.6):
        xy = _place(rng, layout, center, (2.5, 10.0), 0.9)
        if xy is not None:
            size = [_u(rng, 0.4, 1.2), _u(rng, 0.4, 1.2), _u(rng, 0.4, 1.2)]
            shapes.append(_box(xy, size, _u(rng, 0.0, math.pi)).shape())
            notes.append("a box")
    if _chance(rng, 0.3):
        xy = _place(rng, layout, center, (3.0, 10.0), 0.5)
        if xy is not None:
            post = _Pole(np.array([xy[0], xy[1], 0.0]), np.array([0.0, 0.0, 1.0]), 2.0, 0.03, None)
            facing = center[:2] - xy
            facing /= np.linalg.norm(facing)
            across = np.array([-facing[1], facing[0], 0.0])
            corner = np.array([xy[0], xy[1], _u(rng, 1.9, 2.3)]) - 0.3 * across
            shapes.append(post.shape())
            shapes.append(sim.rectangle(corner, 0.6 * across, [0.0, 0.0, 0.6], intensity=TAPE))
            notes.append("a retro-reflective road sign")
    if _chance(rng, 0.3):
        xy = _place(rng, layout, center, (2.5, 10.0), 0.4)
        if xy is not None:
            shapes.append(
                _Pole(
                    np.array([xy[0], xy[1], 0.0]),
                    _tilted_axis(rng, 3.0),
                    _u(rng, 2.5, 5.0),
                    _u(rng, 0.05, 0.2),
                    None,
                ).shape()
            )
            notes.append("an untaped pole")

    reference = _sensor(rng, p_ref, tilt_deg=10.0, side_prob=0.1, flip_prob=0.05)
    target = _sensor(rng, p_tgt, tilt_deg=10.0, side_prob=0.1, flip_prob=0.05)

    def judge(ref: F64Array, tgt: F64Array, ri: F64Array, ti: F64Array) -> tuple[bool | None, str]:
        counts = [(p.tape_count(ref, ri), p.tape_count(tgt, ti)) for p in poles]
        well = [i for i, c in enumerate(counts) if min(c) >= POLE_WELL_SEEN]
        seen = [i for i, c in enumerate(counts) if min(c) >= POLE_BARELY_SEEN]

        def crossing(ids: list[int]) -> bool:
            return any(
                _angle_between(poles[i].axis, poles[j].axis) >= math.radians(3.0)
                for i in ids
                for j in ids
                if i < j
            )

        verdict: bool | None = True if crossing(well) else (False if not crossing(seen) else None)
        return verdict, f"tape points per pole (ref, tgt) {counts}"

    return _Build(
        shapes, reference, target, "; ".join(notes), ("auto", "targetless", "poles"), judge
    )


def _partial(rng: np.random.Generator) -> _Build:
    w = _u(rng, 6.0, 12.0)
    ground = _floor(-50.0, -w - 3.0, 50.0, w + 3.0)
    shapes = [ground.shape(GROUND)]
    layout = _Layout()
    facades = 0
    for sign in (-1.0, 1.0):
        x = -45.0 + _u(rng, 0.0, 5.0)
        while x < 45.0:
            width = min(_u(rng, 5.0, 20.0), 45.0 - x)
            y = sign * (w + _u(rng, 0.0, 1.5))
            shapes.append(_wall([x, y, 0.0], _heading(0.0), width, _u(rng, 4.0, 12.0)).shape(WALL))
            facades += 1
            x += width + (0.0 if _chance(rng, 0.3) else _u(rng, 1.0, 8.0))
    notes = [f"street {2 * w:.1f} m wide, {facades} facade segments"]
    if _chance(rng, 0.3):
        x = math.copysign(_u(rng, 20.0, 40.0), rng.uniform() - 0.5)
        shapes.append(_wall([x, -w, 0.0], _heading(math.pi / 2), 2 * w, 8.0).shape(WALL))
        notes.append(f"a cross wall at x={x:.0f}")

    ref_xy = np.array([_u(rng, -10.0, 10.0), _u(rng, -w + 2.5, w - 2.5)])
    p_ref = np.array([ref_xy[0], ref_xy[1], _u(rng, 1.0, 2.5)])
    p_tgt = p_ref.copy()
    for _ in range(100):
        direction = _u(rng, -0.6, 0.6) + (math.pi if _chance(rng, 0.5) else 0.0)
        xy = ref_xy + _u(rng, 3.0, 8.0) * _heading(direction)[:2]
        if abs(xy[1]) < w - 1.5:
            p_tgt = np.array([xy[0], xy[1], _u(rng, 1.0, 2.5)])
            break
    layout.take(p_ref[:2], 1.0)
    layout.take(p_tgt[:2], 1.0)
    notes.append(f"sensors {np.linalg.norm(p_tgt - p_ref):.1f} m apart")

    if _chance(rng, 0.4):
        # A parked truck next to one sensor hides one side of the street from it.
        eye = p_ref if _chance(rng, 0.5) else p_tgt
        y = eye[1] + math.copysign(_u(rng, 2.0, 3.0), rng.uniform() - 0.5)
        size = [_u(rng, 6.0, 8.0), 2.5, _u(rng, 2.8, 3.5)]
        xy = np.array([eye[0] + _u(rng, -2.0, 2.0), y])
        shapes.append(_box(xy, size, _u(rng, -0.1, 0.1)).shape())
        layout.take(xy, 4.2)
        notes.append("a truck beside one sensor")
    cars = 0
    for _ in range(int(rng.integers(2, 9))):
        sign = 1.0 if _chance(rng, 0.5) else -1.0
        xy = np.array([_u(rng, -40.0, 40.0), sign * (w - _u(rng, 1.5, 2.5))])
        if layout.free(xy, 2.5):
            layout.take(xy, 2.5)
            size = [_u(rng, 4.2, 4.8), _u(rng, 1.7, 1.9), _u(rng, 1.4, 1.7)]
            shapes.append(_box(xy, size, _u(rng, -0.05, 0.05)).shape())
            cars += 1
    posts = 0
    for _ in range(int(rng.integers(2, 7))):
        sign = 1.0 if _chance(rng, 0.5) else -1.0
        xy = np.array([_u(rng, -40.0, 40.0), sign * (w - _u(rng, 0.5, 1.0))])
        if layout.free(xy, 0.4):
            layout.take(xy, 0.4)
            shapes.append(
                _Pole(
                    np.array([xy[0], xy[1], 0.0]),
                    np.array([0.0, 0.0, 1.0]),
                    _u(rng, 2.5, 6.0),
                    _u(rng, 0.05, 0.3),
                    None,
                ).shape()
            )
            posts += 1
    notes.append(f"{cars} cars, {posts} posts and trunks")

    reference = _sensor(rng, p_ref, tilt_deg=8.0, side_prob=0.1, hdl32_prob=0.3)
    target = _sensor(rng, p_tgt, tilt_deg=8.0, side_prob=0.1, pitch_prob=0.15)

    def judge(
        ref: F64Array, tgt: F64Array, _ri: F64Array, _ti: F64Array
    ) -> tuple[bool | None, str]:
        return None, ""

    return _Build(shapes, reference, target, "; ".join(notes), ("auto", "targetless"), judge)


def _corridor(rng: np.random.Generator) -> _Build:
    if _chance(rng, 0.4):
        return _hallway(rng)
    return _room(rng)


def _hallway(rng: np.random.Generator) -> _Build:
    w = _u(rng, 1.8, 5.0)
    half = 100.0
    floor = _floor(-half, -0.5 * w, half, 0.5 * w)
    shapes = [
        floor.shape(GROUND),
        _wall([-half, -0.5 * w, 0.0], _heading(0.0), 2 * half, 4.5).shape(WALL),
        _wall([-half, 0.5 * w, 0.0], _heading(0.0), 2 * half, 4.5).shape(WALL),
    ]
    ceiling = _u(rng, 2.4, 4.0) if _chance(rng, 0.5) else None
    if ceiling is not None:
        shapes.append(_floor(-half, -0.5 * w, half, 0.5 * w, ceiling).shape(WALL))
    top = min(2.5, (ceiling or 4.0) - 0.3)
    margin = min(0.6, 0.25 * w)

    def ok(p: F64Array) -> bool:
        return abs(float(p[1])) < 0.5 * w - margin

    ref_xy = np.array([_u(rng, -2.0, 2.0), _u(rng, -0.5 * w + margin, 0.5 * w - margin)])
    p_ref, p_tgt = _rig_positions(rng, ref_xy, (0.3, 1.5), (1.0, top), ok=ok)
    notes = [f"corridor {w:.1f} m wide" + (f", ceiling at {ceiling:.1f} m" if ceiling else "")]
    end: _Rect | None = None
    periodic = False
    u = rng.uniform()
    if u < 0.3:
        x = math.copysign(_u(rng, 6.0, 40.0), rng.uniform() - 0.5)
        end = _wall([x, -0.5 * w, 0.0], _heading(math.pi / 2), w, 4.5)
        shapes.append(end.shape(WALL))
        notes.append(f"dead end {abs(x - ref_xy[0]):.0f} m away")
    elif u < 0.55:
        period = _u(rng, 3.0, 6.0)
        for sign in (-1.0, 1.0):
            for x in np.arange(-40.0, 40.0, period):
                shapes.append(_box([x, sign * (0.5 * w - 0.1)], [0.5, 0.2, 4.5], 0.0).shape(WALL))
        periodic = True
        notes.append(f"pilasters every {period:.1f} m over 80 m")
    reference = _sensor(rng, p_ref, tilt_deg=5.0, side_prob=0.1)
    target = _sensor(rng, p_tgt, tilt_deg=12.0, side_prob=0.15)

    def judge(
        ref: F64Array, tgt: F64Array, _ri: F64Array, _ti: F64Array
    ) -> tuple[bool | None, str]:
        if end is not None:
            counts = (end.count(ref), end.count(tgt))
            seen = min(counts) >= PLANE_SEEN
            return (True if seen else None), f"end wall points (ref, tgt) {counts}"
        if periodic:
            return None, "periodic pilasters: ambiguous by the period, or pinned by their ends"
        return False, "no structure along the corridor"

    return _Build(shapes, reference, target, "; ".join(notes), ("auto", "targetless"), judge)


def _room(rng: np.random.Generator) -> _Build:
    length, width = _u(rng, 4.0, 15.0), _u(rng, 3.0, 10.0)
    skew = math.radians(_u(rng, 4.0, 20.0)) if _chance(rng, 0.25) else 0.0
    corners = np.array(
        [[0.0, 0.0], [length, 0.0], [length + width * math.tan(skew), width], [0.0, width]]
    )
    height = _u(rng, 2.5, 4.0)
    ceiling = _chance(rng, 0.5)
    door = int(rng.integers(0, 4)) if _chance(rng, 0.4) else -1
    walls: list[_Rect] = []
    skewed_wall = _wall([length, 0.0, 0.0], np.append(corners[2] - corners[1], 0.0), 1.0, 1.0)
    for i in range(4):
        a, b = np.append(corners[i], 0.0), np.append(corners[(i + 1) % 4], 0.0)
        edge = b - a
        span = float(np.linalg.norm(edge))
        if i == 1:
            skewed_wall = _wall(a, edge, span, height)
        if i == door and span > 2.5:
            at = _u(rng, 0.5, span - 1.7)
            gap = _u(rng, 0.9, 1.2)
            lintel = a + edge / span * at + np.array([0.0, 0.0, 2.1])
            walls.append(_wall(a, edge, at, height))
            walls.append(_wall(a + edge / span * (at + gap), edge, span - at - gap, height))
            walls.append(_wall(lintel, edge, gap, height - 2.1))
        else:
            walls.append(_wall(a, edge, span, height))
            if i == door:
                door = -1
    xmax = float(corners[:, 0].max())
    floor = _floor(-0.1, -0.1, xmax + 0.1, width + 0.1)
    shapes = [floor.shape(GROUND), *(r.shape(WALL) for r in walls)]
    if ceiling:
        shapes.append(_floor(-0.1, -0.1, xmax + 0.1, width + 0.1, height).shape(WALL))

    def inside(p: F64Array, margin: float) -> bool:
        for i in range(4):
            a, b = corners[i], corners[(i + 1) % 4]
            e = (b - a) / np.linalg.norm(b - a)
            if e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0]) < margin:  # left of each edge
                return False
        return True

    top = min(2.5, height - 0.3)
    ref_xy = np.array([0.5 * length, 0.5 * width])
    for _ in range(100):
        ref_xy = np.array([_u(rng, 0.0, length), _u(rng, 0.0, width)])
        if inside(ref_xy, 0.8):
            break
    p_ref, p_tgt = _rig_positions(
        rng, ref_xy, (0.3, 1.5), (1.0, top), ok=lambda p: inside(np.asarray(p), 0.6)
    )
    layout = _Layout()
    layout.take(p_ref[:2], 0.8)
    layout.take(p_tgt[:2], 0.8)
    boxes: list[_Box] = []
    n_boxes = 0 if _chance(rng, 0.35) else int(rng.integers(1, 6))
    for _ in range(n_boxes):
        size = np.array([_u(rng, 0.4, 2.0), _u(rng, 0.4, 1.2), _u(rng, 0.4, 2.0)])
        half = 0.5 * float(np.linalg.norm(size[:2]))
        for _ in range(40):
            xy = np.array([_u(rng, 0.0, xmax), _u(rng, 0.0, width)])
            if inside(xy, half + 0.05) and layout.free(xy, half):
                layout.take(xy, half)
                boxes.append(_box(xy, size, _u(rng, 0.0, math.pi) if _chance(rng, 0.5) else 0.0))
                break
    shapes.extend(b.shape() for b in boxes)
    notes = [
        f"room {length:.1f} x {width:.1f} m"
        + (f", one wall skewed {math.degrees(skew):.1f} deg" if skew else "")
        + (", ceiling" if ceiling else "")
        + (", a door" if door >= 0 else "")
        + f", {len(boxes)} furniture boxes"
    ]
    reference = _sensor(rng, p_ref, tilt_deg=5.0, side_prob=0.1)
    target = _sensor(rng, p_tgt, tilt_deg=12.0, side_prob=0.15)

    def judge(
        ref: F64Array, tgt: F64Array, _ri: F64Array, _ti: F64Array
    ) -> tuple[bool | None, str]:
        counts = [(b.count(ref), b.count(tgt)) for b in boxes]
        if any(min(c) >= ELEMENT_SEEN for c in counts):
            return True, f"furniture points (ref, tgt) {counts}"
        if skew >= math.radians(8.0):
            seen = min(skewed_wall.count(ref), skewed_wall.count(tgt)) >= PLANE_SEEN
            if seen:
                return True, "the skewed wall breaks the symmetry"
        if not boxes and skew == 0.0 and door < 0:
            return False, "an empty rectangular room: symmetric under a half turn"
        return None, f"weak asymmetry; furniture points (ref, tgt) {counts}"

    return _Build(
        shapes, reference, target, "; ".join(notes), ("auto", "planes", "targetless"), judge
    )


def _repeated(rng: np.random.Generator) -> _Build:
    ground = _floor(-60.0, -60.0, 60.0, 60.0)
    shapes = [ground.shape(GROUND)]
    layout = _Layout()
    kind = str(rng.choice(["boxes", "poles", "colonnade"], p=[0.35, 0.35, 0.3]))
    symmetric = True
    taped = False
    wall_side = 0.0
    if kind == "boxes":
        n = 3 if _chance(rng, 0.35) else 2
        size = [_u(rng, 0.8, 3.0), _u(rng, 0.8, 3.0), _u(rng, 0.8, 2.5)]
        spacing = size[0] + _u(rng, 0.3, 3.0)
        for i in range(n):
            xy = [(i - 0.5 * (n - 1)) * spacing, 0.0]
            shapes.append(_box(xy, size, 0.0).shape())
            layout.take(xy, 0.5 * math.hypot(size[0], size[1]))
        what = f"{n} identical boxes {spacing:.1f} m apart"
    elif kind == "poles":
        n = int(rng.integers(3, 7))
        spacing = _u(rng, 1.5, 4.0)
        radius, length = _u(rng, 0.05, 0.15), _u(rng, 2.5, 4.0)
        taped = _chance(rng, 0.5)
        band = (_u(rng, 0.3, 0.8), _u(rng, 1.8, length - 0.1)) if taped else None
        for i in range(n):
            x = (i - 0.5 * (n - 1)) * spacing
            pole = _Pole(np.array([x, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), length, radius, band)
            shapes.append(pole.shape())
            layout.take([x, 0.0], 0.3)
        what = f"{n} identical {'taped ' if taped else ''}poles {spacing:.1f} m apart"
    else:
        n = int(rng.integers(5, 11))
        spacing = _u(rng, 2.5, 5.0)
        radius, length = _u(rng, 0.2, 0.4), _u(rng, 3.0, 6.0)
        for i in range(n):
            x = (i - 0.5 * (n - 1)) * spacing
            shapes.append(
                _Pole(
                    np.array([x, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), length, radius, None
                ).shape()
            )
            layout.take([x, 0.0], radius + 0.3)
        what = f"a colonnade of {n} columns {spacing:.1f} m apart"
        if _chance(rng, 0.5):
            wall_side = 1.0 if _chance(rng, 0.5) else -1.0
            span = (n - 1) * spacing + 2 * _u(rng, 0.5, 5.0)
            y = wall_side * _u(rng, 2.0, 4.0)
            shapes.append(
                _wall([-0.5 * span, y, 0.0], _heading(0.0), span, length + 0.5).shape(WALL)
            )
            layout.take([0.0, y], 0.0)
            symmetric = False
            what += f" with a wall {abs(y):.1f} m behind"

    def ok(p: npt.ArrayLike) -> bool:
        q = np.asarray(p, dtype=np.float64)
        return layout.free(q, 0.8) and abs(float(q[1])) > 1.2 and q[1] * wall_side <= 0

    ref_xy = np.array([0.0, -5.0])
    for _ in range(200):
        ref_xy = _u(rng, 3.0, 8.0) * _heading(_u(rng, 0.0, math.tau))[:2]
        if ok(ref_xy):
            break
    p_ref, p_tgt = _rig_positions(rng, ref_xy, (0.3, 2.0), ok=ok)
    layout.take(p_ref[:2], 0.8)
    layout.take(p_tgt[:2], 0.8)
    notes = [what]
    element: _Box | None = None
    if _chance(rng, 0.45):
        spot = _place(rng, layout, 0.5 * (p_ref + p_tgt), (2.0, 7.0), 0.8)
        if spot is not None:
            element = _box(
                spot,
                [_u(rng, 0.4, 1.2), _u(rng, 0.4, 1.2), _u(rng, 0.4, 1.2)],
                _u(rng, 0.0, math.pi),
            )
            shapes.append(element.shape())
            notes.append("one odd box")
    reference = _sensor(rng, p_ref, tilt_deg=8.0, side_prob=0.1)
    target = _sensor(rng, p_tgt, tilt_deg=10.0, side_prob=0.1)

    def judge(
        ref: F64Array, tgt: F64Array, _ri: F64Array, _ti: F64Array
    ) -> tuple[bool | None, str]:
        if element is not None:
            counts = (element.count(ref), element.count(tgt))
            if min(counts) >= ELEMENT_SEEN:
                return True, f"odd box points (ref, tgt) {counts}"
            return None, f"odd box barely seen (ref, tgt) {counts}"
        if symmetric:
            return False, "symmetric under a half turn about the row's middle"
        return None, "periodic row, pinned only by its ends"

    methods = ("auto", "targetless", "poles") if taped else ("auto", "targetless")
    return _Build(shapes, reference, target, "; ".join(notes), methods, judge)


_BUILDERS = {
    "corner": _corner,
    "poles": _poles,
    "partial": _partial,
    "corridor": _corridor,
    "repeated": _repeated,
}


def make(family: str, seed: int) -> Scenario:
    """The scene ``seed`` of ``family`` (one of :data:`FAMILIES`); the same seed gives the same
    scene. Raises ``ValueError`` for an unknown family or a negative seed."""
    if family not in _BUILDERS:
        raise ValueError(f"unknown family {family!r}; expected one of {', '.join(FAMILIES)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng([zlib.crc32(family.encode()), int(seed)])
    build = _BUILDERS[family](rng)
    reference = _scan(rng, build.shapes, build.reference)
    target = _scan(rng, build.shapes, build.target)
    solvable, evidence = build.judge(
        _world(reference, build.reference),
        _world(target, build.target),
        reference[:, 3],
        target[:, 3],
    )
    truth = _inv(build.reference.world_from_sensor) @ build.target.world_from_sensor
    distance = float(np.linalg.norm(truth[:3, 3]))
    description = (
        f"{family} {seed}: {build.description}; reference {build.reference.note}, "
        f"target {build.target.note}, {distance:.2f} m apart"
        + (f"; {evidence}" if evidence else "")
    )
    return Scenario(
        family=family,
        seed=int(seed),
        reference=reference,
        target=target,
        reference_from_target=truth,
        solvable=solvable,
        description=description,
        methods=build.methods,
    )


def _field_of_view(cloud: F64Array, width_deg: float, rng: np.random.Generator) -> F64Array:
    """The returns of ``cloud`` (sensor frame) within a horizontal field of view ``width_deg``
    wide, facing where most returns are give or take 30 degrees (a solid-state unit, or a
    spinning one whose rear view the vehicle blocks)."""
    xy = cloud[:, :2]
    norms = np.maximum(np.linalg.norm(xy, axis=1), 1e-9)
    mean = (xy / norms[:, None]).mean(axis=0)
    centre = math.atan2(mean[1], mean[0]) + math.radians(_u(rng, -30.0, 30.0))
    off = (np.arctan2(xy[:, 1], xy[:, 0]) - centre + math.pi) % math.tau - math.pi
    out: F64Array = cloud[np.abs(off) < math.radians(width_deg) / 2.0]
    return out


def _spurious(cloud: F64Array, share: float, rng: np.random.Generator) -> F64Array:
    """``cloud`` with ``share`` more returns (dust, rain, a dirty window): any direction, 1-15 m
    out, intensities of paint or clutter (under the tape's), shuffled in among the others."""
    k = int(share * len(cloud))
    direction = rng.normal(size=(k, 3))
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    extra = np.hstack(
        [direction * rng.uniform(1.0, 15.0, size=(k, 1)), rng.uniform(*CLUTTER, size=(k, 1))]
    )
    out: F64Array = np.vstack([cloud, extra])[rng.permutation(len(cloud) + k)]
    return out


def degrade(scene: Scenario, condition: str) -> Scenario:
    """``scene`` under ``condition`` (one of :data:`CONDITIONS`), the same for the same scene:

    * ``narrow-fov`` -- each sensor keeps a 120 degree horizontal field of view facing where most
      of its returns are, give or take 30 degrees;
    * ``half-fov-target`` -- the target alone keeps 180 degrees so;
    * ``sparse-target`` -- the target keeps a random quarter of its returns;
    * ``outliers`` -- 3 % more returns in each cloud, anywhere 1-15 m out.

    ``solvable`` is kept under ``outliers``, and when False (less data resolves no symmetry); it
    becomes None (not sure) otherwise. Raises ``ValueError`` for an unknown condition.
    """
    if condition not in CONDITIONS:
        raise ValueError(
            f"unknown condition {condition!r}; expected one of {', '.join(CONDITIONS)}"
        )
    if condition == "none":
        return scene
    rng = np.random.default_rng(
        [zlib.crc32(scene.family.encode()), scene.seed, zlib.crc32(condition.encode())]
    )
    reference, target = scene.reference, scene.target
    if condition == "narrow-fov":
        reference = _field_of_view(reference, 120.0, rng)
        target = _field_of_view(target, 120.0, rng)
    elif condition == "half-fov-target":
        target = _field_of_view(target, 180.0, rng)
    elif condition == "sparse-target":
        target = target[rng.uniform(size=len(target)) < 0.25]
    else:
        reference = _spurious(reference, 0.03, rng)
        target = _spurious(target, 0.03, rng)
    keeps = scene.solvable is False or condition == "outliers"
    return dataclasses.replace(
        scene,
        reference=reference,
        target=target,
        solvable=scene.solvable if keeps else None,
        description=f"{scene.description}; condition {condition}",
    )
