"""Recordings as sequences of frames, for calibration from a drive (``calibrate_sequence``).

* :func:`read_folder` -- a folder of numbered frames (``000000.pcd``, ``scan_17.bin``, ...: PCD,
  PLY, KITTI ``.bin`` or ``.npy``, read with :func:`lidarcal.read_points`) in the order of the
  numbers, with their times from a ``times.txt`` beside them (one time per line, in that order,
  as KITTI writes it) or, without one, the numbers themselves;
* :func:`pair_by_time` -- which frames of two recordings were taken together: the nearest in
  time, each frame used once, none further apart than half a frame period;
* :func:`in_range` -- which times fall between a start and an end given as ``--start``/``--end``
  take them (from the first frame, or absolute times from 1e9 on).

>>> import numpy as np
>>> from lidarcal.frames import pair_by_time
>>> pair_by_time(np.array([0.0, 0.1, 0.2, 0.3]), np.array([0.01, 0.21, 0.32, 0.4]))
[(0, 0), (2, 1), (3, 2)]
"""

from __future__ import annotations

import itertools
import os
import re
from pathlib import Path

import numpy as np
import numpy.typing as npt

from lidarcal._lidarcal import read_points

F64Array = npt.NDArray[np.float64]

#: The extensions :func:`read_folder` reads as frames; other files in the folder are ignored.
FRAME_SUFFIXES = (".pcd", ".ply", ".bin", ".npy")

#: The name of the file holding a folder's frame times.
TIMES_FILE = "times.txt"

#: Times from this on are absolute (Unix seconds); below it, seconds from the first frame.
ABSOLUTE_TIME = 1e9

__all__ = [
    "FRAME_SUFFIXES",
    "TIMES_FILE",
    "in_range",
    "numbered_frames",
    "pair_by_time",
    "read_folder",
]

_NUMBER = re.compile(r"(\d+)(?!.*\d)")  # the last run of digits


def numbered_frames(folder: str | os.PathLike[str]) -> list[tuple[int, Path]]:
    """The frame files of ``folder`` as ``(number, path)`` sorted by the number in the name (its
    last run of digits). Raises ``ValueError`` for a folder without frames, a frame without a
    number or two frames with the same number."""
    root = Path(folder)
    if not root.is_dir():
        raise ValueError(f"{root}: not a folder of frames")
    files = sorted(p for p in root.iterdir() if p.is_file() and p.suffix.lower() in FRAME_SUFFIXES)
    if not files:
        raise ValueError(
            f"{root}: no frames (numbered {', '.join(s[1:] for s in FRAME_SUFFIXES)} files)"
        )
    numbered: list[tuple[int, Path]] = []
    unnumbered = []
    for path in files:
        match = _NUMBER.search(path.stem)
        if match is None:
            unnumbered.append(path.name)
        else:
            numbered.append((int(match.group(1)), path))
    if unnumbered:
        raise ValueError(
            f"{root}: frame names must hold their number (e.g. 000042.pcd); "
            f"{len(unnumbered)} do not: {', '.join(unnumbered[:3])}"
            + (", ..." if len(unnumbered) > 3 else "")
        )
    numbered.sort(key=lambda item: item[0])
    for (a, pa), (b, pb) in itertools.pairwise(numbered):
        if a == b:
            raise ValueError(f"{root}: {pa.name} and {pb.name} have the same number {a}")
    return numbered


def _times(root: Path, numbered: list[tuple[int, Path]]) -> F64Array:
    path = root / TIMES_FILE
    if not path.exists():
        return np.array([float(n) for n, _ in numbered])
    values = []
    for line_number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            values.append(float(line.split()[0]))
        except ValueError as e:
            raise ValueError(f"{path}:{line_number}: not a time: {line!r}") from e
    if len(values) != len(numbered):
        raise ValueError(
            f"{path}: {len(values)} time(s) for {len(numbered)} frame(s); it needs one line per "
            "frame, in the order of the frame numbers"
        )
    times = np.array(values)
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise ValueError(f"{path}: the times must be finite and increase from line to line")
    return times


def in_range(times: F64Array, start: float | None, end: float | None) -> npt.NDArray[np.bool_]:
    """Which ``times`` lie in ``[start, end]``: bounds below 1e9 count from ``times[0]``, larger
    ones are absolute; None is open."""
    keep = np.ones(len(times), dtype=bool)
    if len(times) == 0:
        return keep
    for bound, above in ((start, True), (end, False)):
        if bound is None:
            continue
        at = bound if bound >= ABSOLUTE_TIME else times[0] + bound
        keep &= times >= at if above else times <= at
    return keep


def read_folder(
    folder: str | os.PathLike[str], *, start: float | None = None, end: float | None = None
) -> tuple[list[F64Array], F64Array, list[Path]]:
    """The frames of a folder between ``start`` and ``end`` (see :func:`in_range`): ``(frames,
    times, paths)``, in the order of the numbers in the file names.

    The times come from the folder's ``times.txt`` (one per line, in that order; blank lines and
    ``#`` comments skipped), else they are the frame numbers (so ``start`` / ``end`` count frames
    from the first). Raises ``ValueError`` for a folder without frames, unnumbered frames, a
    ``times.txt`` that does not match, or a range that holds no frame."""
    root = Path(folder)
    numbered = numbered_frames(root)
    times = _times(root, numbered)
    keep = in_range(times, start, end)
    if not keep.any():
        raise ValueError(
            f"{root}: no frame between --start {start} and --end {end} "
            f"(its {len(times)} frames span {times[0]:g} to {times[-1]:g})"
        )
    paths = [p for (_, p), k in zip(numbered, keep, strict=True) if k]
    frames = [read_points(p) for p in paths]
    return frames, times[keep], paths


def pair_by_time(a: F64Array, b: F64Array) -> list[tuple[int, int]]:
    """Pairs ``(i, j)`` of indices into two increasing time arrays, frames taken together: ``b[j]``
    is the nearest of ``b`` to ``a[i]`` and ``a[i]`` the nearest of ``a`` to ``b[j]``, at most
    half a frame period apart (the smaller median period of the two; with a single frame on a
    side, any distance). In time order; the frames without such a partner are left out."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if len(a) == 0 or len(b) == 0:
        return []
    periods = [float(np.median(np.diff(t))) for t in (a, b) if len(t) > 1]
    tolerance = 0.5 * min(periods) if periods else np.inf

    def nearest(sorted_times: F64Array, queries: F64Array) -> npt.NDArray[np.int64]:
        k = np.clip(np.searchsorted(sorted_times, queries), 1, max(len(sorted_times) - 1, 1))
        lo = np.clip(k - 1, 0, len(sorted_times) - 1)
        hi = np.clip(k, 0, len(sorted_times) - 1)
        pick: npt.NDArray[np.int64] = np.where(
            np.abs(sorted_times[lo] - queries) <= np.abs(sorted_times[hi] - queries), lo, hi
        )
        return pick

    a_to_b = nearest(b, a)
    b_to_a = nearest(a, b)
    return [
        (i, int(j))
        for i, j in enumerate(a_to_b)
        if b_to_a[j] == i and abs(a[i] - b[j]) <= tolerance
    ]
