"""``sensor_msgs/PointCloud2`` frames from a ROS 1 or ROS 2 bag, with no ROS installation.

:func:`read_bag` reads one frame, :func:`read_bag_frames` every frame of a topic in a time range
(with their times, for calibration from a drive).

Needs the ``rosbags`` package: ``pip install 'lidarcal[rosbag]'``. ROS 1 ``.bag`` files and ROS 2
bag directories (sqlite3 or mcap) are read with ``rosbags.highlevel.AnyReader``; the message's
fields are decoded with NumPy into the same ``(N, K)`` float64 array as
:func:`lidarcal.read_points` (``x y z`` plus the intensity when present, or the fields named),
with NaN/inf points dropped.

``lidarcal calibrate`` takes bags too: ``lidarcal calibrate top.bag side.bag --topic /points``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import INTENSITY_NAMES, FileFormatError

F64Array = npt.NDArray[np.float64]

__all__ = ["BAG_SUFFIXES", "is_bag", "read_bag", "read_bag_frames", "split_source"]

BAG_SUFFIXES = (".bag", ".db3", ".mcap")
POINTCLOUD2 = ("sensor_msgs/msg/PointCloud2", "sensor_msgs/PointCloud2")

# sensor_msgs/PointField datatypes -> NumPy type codes.
_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def is_bag(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a ROS bag: a ``.bag``/``.db3``/``.mcap`` file or a ROS 2 bag folder."""
    p = Path(path)
    return p.suffix.lower() in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").exists())


def split_source(text: str) -> tuple[Path, str | None]:
    """A cloud source as the command line and the batch manifests write it, ``FILE`` or
    ``BAG:/topic``: its path and its topic (None for a plain path). Raises ``FileNotFoundError``
    when neither names something that exists."""
    path = Path(text)
    if path.exists():
        return path, None
    head, sep, tail = text.rpartition(":/")
    if sep and Path(head).exists():
        return Path(head), "/" + tail
    raise FileNotFoundError(f"{text}: no such file")


def _find(names: Sequence[str], wanted: str) -> str | None:
    for n in names:
        if n == wanted or n.lower() == wanted.lower():
            return n
    if wanted.lower() in INTENSITY_NAMES:
        for alias in INTENSITY_NAMES:
            for n in names:
                if n.lower() == alias:
                    return n
    return None


def decode_pointcloud2(msg: Any, fields: Sequence[str] | None = None) -> tuple[F64Array, list[str]]:
    """``(points, names)`` of a deserialised PointCloud2 message; NaN/inf points dropped."""
    big = bool(msg.is_bigendian)
    names, formats, offsets = [], [], []
    for f in msg.fields:
        code = _DATATYPES.get(int(f.datatype))
        if code is None:
            raise FileFormatError(f"PointCloud2 field {f.name!r} has unknown datatype {f.datatype}")
        if f.name in names:
            continue
        names.append(f.name)
        formats.append((">" if big else "<") + code)
        offsets.append(int(f.offset))
    step = int(msg.point_step)
    count = int(msg.width) * int(msg.height)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step <= 0 or len(data) < count * step:
        raise FileFormatError(
            f"PointCloud2 data holds {len(data)} bytes, fewer than {count} points of {step} bytes"
        )
    # row_step may pad rows of organised clouds; read row by row then.
    row_step = int(msg.row_step) or int(msg.width) * step
    rows = [
        data[r * row_step : r * row_step + int(msg.width) * step] for r in range(int(msg.height))
    ]
    packed = np.concatenate(rows) if len(rows) > 1 else rows[0]
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    records = packed[: count * step].view(dtype)
    if fields is None:
        wanted = ["x", "y", "z"]
        missing = [w for w in wanted if _find(names, w) is None]
        if missing:
            raise FileFormatError(f"PointCloud2 has no field {missing[0]!r} (fields: {names})")
        if _find(names, "intensity") is not None:
            wanted.append("intensity")
    else:
        wanted = list(fields)
    columns = []
    for w in wanted:
        name = _find(names, w)
        if name is None:
            raise ValueError(f"PointCloud2 has no field {w!r} (fields: {names})")
        columns.append(records[name].astype(np.float64))
    points = np.column_stack(columns)
    return points[np.isfinite(points).all(axis=1)], wanted


def _open(path: str | os.PathLike[str]) -> Any:
    """An opened ``AnyReader`` of the bag at ``path``."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("reading bags needs rosbags: pip install 'lidarcal[rosbag]'") from e
    from rosbags.typesys import Stores, get_typestore

    bag = Path(path)
    if not bag.exists():
        raise FileNotFoundError(f"{bag}: no such file or directory")
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # rosbags raises its own error types for corrupt bags
        raise FileFormatError(f"{bag}: not a readable ROS bag ({e})") from e
    return reader


def _connections(reader: Any, bag: Path, topic: str | None) -> tuple[str, list[Any]]:
    """The topic (the only PointCloud2 one when ``topic`` is None) and its connections."""
    clouds = [c for c in reader.connections if c.msgtype in POINTCLOUD2]
    available = sorted({c.topic for c in clouds})
    if topic is None:
        if len(available) != 1:
            raise ValueError(
                f"{bag}: name the topic; PointCloud2 topics: {', '.join(available) or 'none'}"
            )
        topic = available[0]
    chosen = [c for c in clouds if c.topic == topic]
    if not chosen:
        raise ValueError(
            f"{bag}: no PointCloud2 topic {topic!r}; there are: {', '.join(available) or 'none'}"
        )
    return topic, chosen


def _stamp(reader: Any, time: float) -> int:
    """Nanoseconds of a time given as seconds from the bag's start (below 1e9) or Unix time."""
    ns = round(time * 1e9)
    return ns if time >= 1e9 else int(reader.start_time) + ns


def read_bag(
    path: str | os.PathLike[str],
    topic: str | None = None,
    *,
    time: float | None = None,
    fields: Sequence[str] | None = None,
) -> F64Array:
    """One PointCloud2 frame of a bag as an ``(N, K)`` float64 array.

    ``topic`` may be omitted when the bag has exactly one PointCloud2 topic. ``time`` picks the
    message nearest to it: seconds from the start of the bag if below 1e9, otherwise a Unix time in
    seconds; default the first message.
    """
    bag = Path(path)
    reader = _open(bag)
    try:
        topic, chosen = _connections(reader, bag, topic)
        stamp = None if time is None else _stamp(reader, time)
        best: tuple[int, Any] | None = None
        for connection, timestamp, raw in reader.messages(connections=chosen):
            if stamp is None:
                best = (timestamp, reader.deserialize(raw, connection.msgtype))
                break
            if best is None or abs(timestamp - stamp) < abs(best[0] - stamp):
                best = (timestamp, (connection, raw))
        if best is None:
            raise ValueError(f"{bag}: topic {topic!r} has no messages")
        msg = best[1]
        if isinstance(msg, tuple):
            msg = reader.deserialize(msg[1], msg[0].msgtype)
        points, _ = decode_pointcloud2(msg, fields)
        return points
    finally:
        reader.close()


def read_bag_frames(
    path: str | os.PathLike[str],
    topic: str | None = None,
    *,
    start: float | None = None,
    end: float | None = None,
    fields: Sequence[str] | None = None,
) -> tuple[list[F64Array], F64Array]:
    """Every PointCloud2 frame of a topic between ``start`` and ``end`` (inclusive; seconds from
    the start of the bag if below 1e9, otherwise Unix times; default the whole bag), in time
    order: ``(frames, times)``, a list of ``(N, K)`` float64 arrays as :func:`read_bag` gives and
    their Unix times in seconds.

    A frame's time is its header stamp (when the sensor measured it), or the time it was
    recorded when the stamp is zero; ``start`` and ``end`` select on the same times.
    """
    bag = Path(path)
    reader = _open(bag)
    try:
        topic, chosen = _connections(reader, bag, topic)
        lo = None if start is None else _stamp(reader, start)
        hi = None if end is None else _stamp(reader, end)
        found: list[tuple[int, F64Array]] = []
        for connection, timestamp, raw in reader.messages(connections=chosen):
            msg = reader.deserialize(raw, connection.msgtype)
            header = msg.header.stamp
            stamp = int(header.sec) * 10**9 + int(header.nanosec)
            stamp = stamp or int(timestamp)
            if (lo is not None and stamp < lo) or (hi is not None and stamp > hi):
                continue
            points, _ = decode_pointcloud2(msg, fields)
            found.append((stamp, points))
        if not found:
            span = "".join(
                f" {word} {bound:g} s"
                for word, bound in (("from", start), ("to", end))
                if bound is not None
            )
            raise ValueError(f"{bag}: topic {topic!r} has no messages{span}")
        found.sort(key=lambda item: item[0])
        return [p for _, p in found], np.array([t for t, _ in found], dtype=np.float64) / 1e9
    finally:
        reader.close()
