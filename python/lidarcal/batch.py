"""Batch calibration and calibration monitoring over many recordings, on Dask.

:func:`run` reads a manifest (CSV or Parquet, one row per job), runs every job on a
``dask.distributed`` cluster and writes one result row per job (Parquet or CSV, by the output's
extension). ``lidarcal batch MANIFEST --output RESULTS`` is the same from the command line. Needs
``pip install 'lidarcal[fleet]'`` (dask, distributed, pyarrow, tqdm).

The manifest's columns:

* ``id`` (required, unique): names the job in the results;
* ``reference``, ``target`` (required): the two clouds, a file :func:`lidarcal.read_points` reads
  or ``BAG:/topic`` (a ROS bag, with the ``rosbag`` extra). A relative path is relative to the
  manifest's folder. The files are read **on the workers**, never shipped from the client: they
  must be readable there (a shared or identical file system);
* ``time`` (optional): for bags, the frame's time (as ``lidarcal calibrate --time``);
* ``method`` (optional, default ``auto``) and ``up`` (optional, ``"x,y,z"``): as for
  :func:`lidarcal.calibrate`;
* ``transform`` (optional): a stored ``reference_from_target`` (any file ``lidarcal calibrate
  --output`` writes, or a bare 4x4 text matrix; a file with several transforms is searched for
  the row's target). A row **with** a transform is a monitoring row: :func:`lidarcal.check` says
  whether the stored calibration still fits. A row without one is calibrated.

Each result row: ``id``, ``job`` (``calibrate`` / ``monitor``), ``status`` (``ok``, ``refused``:
a :class:`lidarcal.CalibrationError` whose ``kind`` is in ``kind``, or ``error``: a missing or
corrupt file, an unreadable transform, a bad row, a worker lost too often; ``kind`` says which and
``message`` what), ``method``, ``transform`` (16 floats, row-major), ``tx ty tz`` (m),
``roll_deg pitch_deg yaw_deg`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``), the check's ``verdict``,
``reason`` and figures, ``runtime_s`` (on the worker) and ``worker``.

Rows are written as they finish, so an interrupted run loses nothing finished, and a rerun with
the same output resumes: rows already there are skipped, never duplicated. A CSV output is
appended row by row; a Parquet output collects the finished rows in ``RESULTS.journal`` (JSON
lines) beside it and rewrites the Parquet file from it when the run ends (or when the next run
starts after a crash), so the Parquet file itself is always complete and readable.
At most ``max_in_flight`` rows are submitted at a time (default: twice the cluster's threads), so
the client's memory does not grow with the manifest.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from lidarcal.calibrate import METHOD_NAMES

__all__ = [
    "COLUMNS",
    "Summary",
    "process_row",
    "read_manifest",
    "read_results",
    "run",
    "simulate_fleet",
]

#: The check's figures copied into each row (the CheckReport attributes of the same name).
_CHECK_FIGURES = (
    "overlap",
    "agreement",
    "reverse_agreement",
    "violations",
    "reverse_violations",
    "rmse",
    "correction_rotation_deg",
    "correction_translation_m",
    "detectable_rotation_deg",
    "detectable_translation_m",
)
#: The result columns, in order.
COLUMNS = (
    "id",
    "job",
    "status",
    "kind",
    "message",
    "method",
    "transform",
    "tx",
    "ty",
    "tz",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "verdict",
    "reason",
    *_CHECK_FIGURES,
    "runtime_s",
    "worker",
)
_TEXT = ("id", "job", "status", "kind", "message", "method", "verdict", "reason", "worker")
_MANIFEST_COLUMNS = ("id", "reference", "target", "time", "method", "up", "transform")


# --------------------------------------------------------------------------------------------
# The manifest


def _arrow() -> Any:
    """pyarrow (the fleet extra; it has no type annotations), imported on first use."""
    import pyarrow  # type: ignore[import-untyped]

    return pyarrow


def _parquet() -> Any:
    """pyarrow.parquet, imported on first use."""
    import pyarrow.parquet  # type: ignore[import-untyped]

    return pyarrow.parquet


def _cell(value: Any) -> str | None:
    """A manifest cell as text, ``None`` when empty (an empty CSV cell, a Parquet null, NaN)."""
    if value is None:
        return None
    if isinstance(value, float):
        if math.isnan(value):
            return None
        if value.is_integer():  # a numeric id column: 7.0 -> "7"
            return str(int(value))
    text = str(value).strip()
    return text or None


def _is_parquet(path: Path) -> bool:
    return path.suffix.lower() in (".parquet", ".pq")


def _manifest_rows(path: Path, columns: list[str] | None = None) -> Iterator[dict[str, Any]]:
    """The manifest's rows, streamed (a batch of a Parquet file, a line of a CSV at a time)."""
    if _is_parquet(path):
        pq = _parquet()

        parquet = pq.ParquetFile(path)
        names = parquet.schema_arrow.names
        wanted = [c for c in (columns or names) if c in names]
        for batch in parquet.iter_batches(batch_size=1024, columns=wanted):
            yield from batch.to_pylist()
    else:
        with open(path, newline="") as f:
            yield from csv.DictReader(f)


def _manifest_header(path: Path) -> list[str]:
    if _is_parquet(path):
        pq = _parquet()

        return list(pq.ParquetFile(path).schema_arrow.names)
    with open(path, newline="") as f:
        return next(csv.reader(f), [])


def _check_header(path: Path) -> None:
    header = _manifest_header(path)
    missing = [c for c in ("id", "reference", "target") if c not in header]
    if missing:
        raise ValueError(
            f"{path}: the manifest needs the column(s) {', '.join(missing)} (it has: "
            f"{', '.join(header) or 'none'})"
        )


def read_manifest(path: str | os.PathLike[str]) -> Iterator[dict[str, str | None]]:
    """The jobs of a manifest, streamed: one dictionary per row with the keys ``id``,
    ``reference``, ``target``, ``time``, ``method``, ``up`` and ``transform`` (text or ``None``),
    paths made absolute against the manifest's folder (``BAG:/topic`` kept). Raises
    ``ValueError`` when a required column is missing or a row has no ``id``."""
    path = Path(path)
    _check_header(path)
    base = path.resolve().parent
    for number, row in enumerate(_manifest_rows(path), 1):
        job = {c: _cell(row.get(c)) for c in _MANIFEST_COLUMNS}
        if job["id"] is None:
            raise ValueError(f"{path}: row {number} has no id")
        for key in ("reference", "target", "transform"):
            text = job[key]
            if text is not None and not Path(text).is_absolute():
                job[key] = str(base / text)
        yield job


def _manifest_ids(path: Path) -> tuple[int, set[str]]:
    """Checks the manifest's columns and ids (present, unique) before anything runs; a Parquet
    manifest's ``id`` column is read alone."""
    _check_header(path)
    seen: dict[str, int] = {}
    count = 0
    for row in _manifest_rows(path, ["id"]):
        count += 1
        job_id = _cell(row.get("id"))
        if job_id is None:
            raise ValueError(f"{path}: row {count} has no id")
        if job_id in seen:
            raise ValueError(
                f"{path}: id {job_id!r} appears twice (rows {seen[job_id]} and {count})"
            )
        seen[job_id] = count
    return count, set(seen)


# --------------------------------------------------------------------------------------------
# One row, on a worker


def _load(text: str, at: float | None) -> np.ndarray:
    """A cloud from ``FILE`` or ``BAG:/topic`` (as on the command line)."""
    from lidarcal import read_points
    from lidarcal.rosbag import is_bag, read_bag, split_source

    path, topic = split_source(text)
    if topic is not None or is_bag(path):
        return read_bag(path, topic, time=at)
    return read_points(path)


class _RowError(Exception):
    """A row that cannot run; ``kind`` goes into the result."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _options(job: dict[str, str | None]) -> tuple[str, list[float] | None, float | None]:
    method = (job.get("method") or "auto").lower()
    if method not in METHOD_NAMES:
        raise _RowError("bad_row", f"method {method!r} is not one of {', '.join(METHOD_NAMES)}")
    up = None
    if job.get("up"):
        try:
            up = [float(v) for v in str(job["up"]).replace(",", " ").split()]
        except ValueError:
            up = []
        if len(up) != 3 or not all(math.isfinite(v) for v in up):
            raise _RowError("bad_row", f"up must be three numbers 'x,y,z', got {job['up']!r}")
    at = None
    if job.get("time"):
        try:
            at = float(str(job["time"]))
        except ValueError:
            raise _RowError("bad_row", f"time must be a number, got {job['time']!r}") from None
    return method, up, at


def _read_cloud(text: str | None, which: str, at: float | None) -> np.ndarray:
    if not text:
        raise _RowError("bad_row", f"the row has no {which}")
    try:
        return _load(text, at)
    except FileNotFoundError as e:
        raise _RowError("missing_file", f"{which}: {e}") from None
    except (ValueError, OSError, RuntimeError) as e:
        raise _RowError("bad_file", f"{which}: {e}") from None


def _pose_fields(transform: np.ndarray) -> dict[str, Any]:
    from lidarcal.export import rpy

    roll, pitch, yaw = (float(v) for v in np.degrees(rpy(transform[:3, :3])))
    tx, ty, tz = (float(v) for v in transform[:3, 3])
    return {
        "transform": [float(v) for v in transform.reshape(16)],
        "tx": tx,
        "ty": ty,
        "tz": tz,
        "roll_deg": roll,
        "pitch_deg": pitch,
        "yaw_deg": yaw,
    }


def _check_fields(report: Any) -> dict[str, Any]:
    out: dict[str, Any] = {"verdict": report.verdict, "reason": report.reason}
    out.update({name: float(getattr(report, name)) for name in _CHECK_FIGURES})
    return out


def _empty_row(job_id: str, job: str) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(id=job_id, job=job)
    return row


def process_row(job: dict[str, str | None]) -> dict[str, Any]:
    """Runs one manifest row (a dictionary of :func:`read_manifest`) and returns its result row.

    Runs on a worker; never raises for a bad row, a refusal or bad input: those become
    ``status`` ``refused`` / ``error`` with their ``kind`` and ``message``."""
    import lidarcal
    from lidarcal.export import read_transform

    start = time.perf_counter()
    monitor = bool(job.get("transform"))
    row = _empty_row(str(job["id"]), "monitor" if monitor else "calibrate")
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    try:
        method, up, at = _options(job)
        stored = None
        if monitor:
            try:
                stored = read_transform(str(job["transform"]))
            except ValueError as e:
                if "holds" not in str(e) or not job.get("target"):
                    raise _RowError("bad_transform", str(e)) from None
                try:  # several transforms: the one for this row's target
                    stored = read_transform(str(job["transform"]), str(job["target"]))
                except (ValueError, OSError) as e2:
                    raise _RowError("bad_transform", str(e2)) from None
            except OSError as e:
                kind = "missing_file" if isinstance(e, FileNotFoundError) else "bad_transform"
                raise _RowError(kind, f"transform: {e}") from None
        reference = _read_cloud(job.get("reference"), "reference", at)
        target = _read_cloud(job.get("target"), "target", at)
        try:
            if stored is not None:
                row.update(_pose_fields(stored))
                row.update(_check_fields(lidarcal.check(reference, target, stored)))
            else:
                result = lidarcal.calibrate(
                    reference,
                    target,
                    method,  # type: ignore[arg-type]
                    up=up,
                )
                row["method"] = result.method
                row.update(_pose_fields(np.asarray(result.transform)))
                row.update(_check_fields(result.check))
        except lidarcal.CalibrationError as e:
            row.update(status="refused", kind=getattr(e, "kind", None), message=str(e))
        except ValueError as e:
            raise _RowError("bad_input", str(e)) from None
        else:
            row["status"] = "ok"
    except _RowError as e:
        row.update(status="error", kind=e.kind, message=str(e))
    except Exception as e:  # a bug: keep the run going, say what happened
        row.update(status="error", kind="internal", message=f"{type(e).__name__}: {e}")
    row["runtime_s"] = time.perf_counter() - start
    return row


# --------------------------------------------------------------------------------------------
# Results


def _schema() -> Any:
    pa = _arrow()

    def kind(name: str) -> Any:
        if name in _TEXT:
            return pa.string()
        return pa.list_(pa.float64()) if name == "transform" else pa.float64()

    return pa.schema([(name, kind(name)) for name in COLUMNS])


def _csv_value(name: str, value: Any) -> str:
    if value is None:
        return ""
    if name == "transform":
        return " ".join(repr(float(v)) for v in value)
    if isinstance(value, float):
        return repr(value)
    # One physical line per row, so a line a crash cut short is recognisable (and dropped).
    return " ".join(str(value).splitlines())


def _from_csv(row: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in COLUMNS:
        text = row.get(name) or ""
        if not text:
            out[name] = None
        elif name in _TEXT:
            out[name] = text
        elif name == "transform":
            out[name] = [float(v) for v in text.split()]
        else:
            out[name] = float(text)
    return out


def _read_csv_rows(path: Path) -> Iterator[dict[str, Any]]:
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            yield _from_csv(row)


def read_results(path: str | os.PathLike[str]) -> Any:
    """A results file of :func:`run` (Parquet or CSV) as a ``pyarrow.Table`` with the columns of
    :data:`COLUMNS` (``transform`` a list of 16 floats; ``.to_pandas()`` for a DataFrame). A
    Parquet output's journal (rows of an interrupted run) is included."""
    pa = _arrow()
    pq = _parquet()

    path = Path(path)
    if not _is_parquet(path):
        return pa.Table.from_pylist(list(_read_csv_rows(path)), schema=_schema())
    tables = [pq.read_table(path, schema=_schema())] if path.exists() else []
    journal = _ParquetSink.journal_path(path)
    if journal.exists():
        done = set(tables[0].column("id").to_pylist()) if tables else set()
        rows = [r for r in _journal_rows(journal) if r["id"] not in done]
        tables.append(pa.Table.from_pylist(rows, schema=_schema()))
    if not tables:
        raise FileNotFoundError(f"{path}: no such file")
    return pa.concat_tables(tables)


def _journal_rows(path: Path) -> Iterator[dict[str, Any]]:
    with open(path) as f:
        for line in f:
            if line.endswith("\n"):  # a line cut by a crash is not a row
                yield json.loads(line)


def _drop_torn_tail(path: Path) -> None:
    """Cuts a last line a crash left unfinished (no newline), so appending starts clean."""
    with open(path, "rb+") as f:
        f.seek(0, os.SEEK_END)
        size = f.tell()
        if size == 0:
            return
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return
        step = min(size, 1 << 16)
        f.seek(size - step)
        tail = f.read(step)
        cut = tail.rfind(b"\n")
        f.truncate(size - step + cut + 1 if cut >= 0 else 0)


class _CsvSink:
    """Appends rows to a CSV file, one flushed line per finished row."""

    def __init__(self, path: Path) -> None:
        self.path = path
        #: id -> (status, verdict) of the rows already in the output.
        self.done: dict[str, tuple[str | None, str | None]] = {}
        fresh = not path.exists() or path.stat().st_size == 0
        if not fresh:
            _drop_torn_tail(path)
            with open(path, newline="") as f:
                header = next(csv.reader(f), [])
            if tuple(header) != COLUMNS:
                raise ValueError(
                    f"{path}: exists and is not a lidarcal results file (its columns differ); "
                    "choose another output or remove it"
                )
            self.done = {str(r["id"]): (r["status"], r["verdict"]) for r in _read_csv_rows(path)}
        self.file: IO[str] = open(path, "a", newline="")
        self.writer = csv.writer(self.file)
        if fresh:
            self.writer.writerow(COLUMNS)
            self.file.flush()

    def write(self, row: dict[str, Any]) -> None:
        self.writer.writerow([_csv_value(name, row.get(name)) for name in COLUMNS])
        self.file.flush()

    def close(self) -> None:
        self.file.close()


class _ParquetSink:
    """Journals finished rows (JSON lines) and folds them into the Parquet file on close."""

    #: Rows per Parquet row group when the journal is folded in.
    CHUNK = 4096

    @staticmethod
    def journal_path(path: Path) -> Path:
        return path.with_name(path.name + ".journal")

    def __init__(self, path: Path) -> None:
        self.path = path
        self.journal = self.journal_path(path)
        #: id -> (status, verdict) of the rows already in the output.
        self.done: dict[str, tuple[str | None, str | None]] = {}
        if path.exists():
            pq = _parquet()

            names = pq.ParquetFile(path).schema_arrow.names
            if tuple(names) != COLUMNS:
                raise ValueError(
                    f"{path}: exists and is not a lidarcal results file (its columns differ); "
                    "choose another output or remove it"
                )
            table = pq.read_table(path, columns=["id", "status", "verdict"])
            self.done = {str(r["id"]): (r["status"], r["verdict"]) for r in table.to_pylist()}
        if self.journal.exists():
            _drop_torn_tail(self.journal)
            for r in _journal_rows(self.journal):
                self.done.setdefault(str(r["id"]), (r["status"], r["verdict"]))
        self.file: IO[str] = open(self.journal, "a")

    def write(self, row: dict[str, Any]) -> None:
        self.file.write(json.dumps(row) + "\n")
        self.file.flush()

    def close(self) -> None:
        self.file.close()
        self.fold()

    def fold(self) -> None:
        """Rewrites the Parquet file with the journal's rows added (a chunk at a time, so memory
        stays bounded), atomically, then removes the journal."""
        pa = _arrow()
        pq = _parquet()

        if not self.journal.exists():
            return
        schema = _schema()
        tmp = self.path.with_name(self.path.name + ".tmp")
        seen: set[str] = set()
        with pq.ParquetWriter(tmp, schema) as writer:
            if self.path.exists():
                for batch in pq.ParquetFile(self.path).iter_batches(batch_size=self.CHUNK):
                    seen.update(str(v) for v in batch.column("id").to_pylist())
                    writer.write_table(pa.Table.from_batches([batch], schema=schema))
            rows = (r for r in _journal_rows(self.journal) if r["id"] not in seen)
            while chunk := list(itertools.islice(rows, self.CHUNK)):
                writer.write_table(pa.Table.from_pylist(chunk, schema=schema))
        os.replace(tmp, self.path)
        self.journal.unlink()


def _sink(path: Path) -> _CsvSink | _ParquetSink:
    suffix = path.suffix.lower()
    if _is_parquet(path):
        return _ParquetSink(path)
    if suffix in (".csv", ".txt"):
        return _CsvSink(path)
    raise ValueError(f"{path}: the output must end in .parquet or .csv")


# --------------------------------------------------------------------------------------------
# The run


@dataclass
class Summary:
    """What a :func:`run` did: rows in the manifest, ``skipped`` (already in the output) and
    ``written`` by this run; the outcomes count both, so they describe the whole manifest
    (``inconsistent`` / ``unverifiable``: the verdicts of ``ok`` rows). ``errors``: the first
    few error rows of this run, as text."""

    rows: int = 0
    skipped: int = 0
    written: int = 0
    ok: int = 0
    refused: int = 0
    error: int = 0
    inconsistent: int = 0
    unverifiable: int = 0
    seconds: float = 0.0
    output: str = ""
    errors: list[str] = field(default_factory=list)

    def add(self, row: dict[str, Any], skipped: bool = False) -> None:
        """Counts one row: written by this run, or ``skipped`` (found in the output)."""
        if skipped:
            self.skipped += 1
        else:
            self.written += 1
        status = row.get("status")
        if status == "ok":
            self.ok += 1
            if row.get("verdict") == "inconsistent":
                self.inconsistent += 1
            elif row.get("verdict") == "unverifiable":
                self.unverifiable += 1
        elif status == "refused":
            self.refused += 1
        else:
            self.error += 1
            if len(self.errors) < 5 and not skipped:
                self.errors.append(f"{row['id']} [{row.get('kind')}]: {row.get('message')}")

    def __str__(self) -> str:
        rate = self.written / self.seconds if self.seconds > 0 else 0.0
        return (
            f"{self.written} row(s) in {self.seconds:.1f} s ({rate:.2f} rows/s), "
            f"{self.skipped} already done; of all {self.skipped + self.written}: "
            f"ok {self.ok} (inconsistent {self.inconsistent}, "
            f"unverifiable {self.unverifiable}), refused {self.refused}, error {self.error} "
            f"-> {self.output}"
        )


def _require_fleet() -> None:
    try:
        import distributed  # noqa: F401

        _arrow()
        import tqdm  # noqa: F401
    except ImportError as e:
        raise ImportError(
            f"lidarcal.batch needs the fleet extra: pip install 'lidarcal[fleet]' ({e})"
        ) from e


def _local_client(workers: int | None) -> tuple[Any, Any]:
    from distributed import Client, LocalCluster

    n = workers or os.cpu_count() or 1
    # One row per core: one thread per worker process, and the calibration's own rayon pool
    # limited to one thread too (rows are the parallelism; two levels would fight over cores).
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # a free port: no clash with another cluster's 8787
        env={"RAYON_NUM_THREADS": "1"},
    )
    return Client(cluster), cluster


def run(
    manifest: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    client: Any = None,
    workers: int | None = None,
    scheduler: str | None = None,
    max_in_flight: int | None = None,
    progress: bool | None = None,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> Summary:
    """Runs every row of ``manifest`` not yet in ``output`` on Dask and writes its result row.

    ``client``: a ``distributed.Client`` to use (left open); else ``scheduler``, the address of a
    running scheduler; else a ``LocalCluster`` of ``workers`` processes (default the core count)
    started and closed here. ``max_in_flight`` bounds the rows submitted at a time (default twice
    the cluster's threads). ``progress`` shows a bar with rows per second and the ETA on stderr
    (default: when stderr is a terminal). ``on_row`` is called with each result row after it is
    written. Returns a :class:`Summary`. Raises ``ValueError`` for a manifest without the
    required columns or with a missing or repeated id, or an output that is not ``.parquet`` /
    ``.csv`` or holds something else; a bad row only gives an error row."""
    _require_fleet()
    manifest, output = Path(manifest), Path(output)
    total, ids = _manifest_ids(manifest)
    sink = _sink(output)
    summary = Summary(rows=total, output=str(output))
    for job_id in ids:
        if job_id in sink.done:
            status, verdict = sink.done[job_id]
            summary.add({"id": job_id, "status": status, "verdict": verdict}, skipped=True)
    del ids
    owned: list[Any] = []
    start = time.perf_counter()
    try:
        if client is None:
            if scheduler is not None:
                from distributed import Client

                client = Client(scheduler)
                owned.append(client)
            else:
                client, cluster = _local_client(workers)
                owned += [cluster, client]  # closed in reverse: the client first
        if max_in_flight is None:
            threads = sum(client.nthreads().values()) or 1
            max_in_flight = max(2, 2 * threads)
        if progress is None:
            progress = sys.stderr.isatty()
        jobs = (j for j in read_manifest(manifest) if str(j["id"]) not in sink.done)
        _drive(
            client, jobs, sink, summary, max_in_flight, total - summary.skipped, progress, on_row
        )
    finally:
        summary.seconds = time.perf_counter() - start
        sink.close()
        for thing in reversed(owned):
            thing.close()
    return summary


def _drive(
    client: Any,
    jobs: Iterator[dict[str, str | None]],
    sink: _CsvSink | _ParquetSink,
    summary: Summary,
    max_in_flight: int,
    pending: int,
    progress: bool,
    on_row: Callable[[dict[str, Any]], None] | None,
) -> None:
    """Keeps at most ``max_in_flight`` rows on the cluster; writes each as it finishes."""
    import uuid

    from distributed import as_completed
    from tqdm import tqdm

    bar = tqdm(total=pending, unit="row", disable=not progress, file=sys.stderr, dynamic_ncols=True)
    running: dict[Any, dict[str, str | None]] = {}
    queue = as_completed()

    def submit() -> bool:
        job = next(jobs, None)
        if job is None:
            return False
        # The key names the row (the dashboard shows it); the uuid keeps reruns apart.
        key = f"lidarcal-row-{uuid.uuid4().hex}-{job['id']}"
        future = client.submit(process_row, job, key=key)
        running[future] = job
        queue.add(future)
        return True

    try:
        for _ in range(max_in_flight):
            if not submit():
                break
        for future in queue:
            job = running.pop(future)
            try:
                row = future.result()
            except Exception as e:  # the task itself failed: KilledWorker (lost too often)
                row = _empty_row(str(job["id"]), "monitor" if job.get("transform") else "calibrate")
                row.update(
                    status="error",
                    kind="worker_lost",
                    message=f"{type(e).__name__}: {e}",
                )
            future.release()
            sink.write(row)
            summary.add(row)
            bar.update(1)
            bar.set_postfix(
                {
                    "ok": summary.ok,
                    "refused": summary.refused,
                    "error": summary.error,
                    "inconsistent": summary.inconsistent,
                },
                refresh=False,
            )
            if on_row is not None:
                on_row(row)
            submit()
    finally:
        for future in running:
            future.cancel()
        bar.close()


# --------------------------------------------------------------------------------------------
# A simulated fleet


def simulate_fleet(
    folder: str | os.PathLike[str],
    vehicles: int = 50,
    *,
    bumped: Sequence[int] = (),
    bump_deg: float = 2.0,
    calibrate: bool = False,
    seed: int = 0,
) -> Path:
    """Writes a simulated fleet into ``folder`` and returns its manifest (``manifest.csv``).

    Vehicle ``v`` is a :func:`lidarcal.sim.street_scene` (seed ``seed + v``): a roof HDL-64E and a
    side unit tilted 45 degrees, each vehicle with its own mounting. Its clouds go to
    ``vNNN_reference.pcd`` / ``vNNN_target.pcd`` and its stored extrinsic to ``vNNN_stored.txt``.
    The vehicles in ``bumped`` had their side sensor knocked by ``bump_deg`` degrees (about an
    axis of the vehicle's own, from ``seed``) since the stored extrinsic was made: their clouds
    show the new pose, the file keeps the old one. The manifest has one monitoring row per vehicle
    (id ``vNNN``) and, with ``calibrate``, one calibration row too (id ``vNNN-cal``)."""
    from lidarcal import sim, so3_exp, write_points

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    lines = ["id,reference,target,transform"]
    for v in range(vehicles):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        scene = sim.street_scene(seed=seed + v)
        actual = np.asarray(scene.reference_from_target)
        stored = actual.copy()
        if v in bumped:  # actual = stored @ bump: the file keeps the pose before the knock
            bump = np.eye(4)
            bump[:3, :3] = so3_exp(np.radians(bump_deg) * axis)
            stored = actual @ np.linalg.inv(bump)
        name = f"v{v:03d}"
        write_points(folder / f"{name}_reference.pcd", scene.reference)
        write_points(folder / f"{name}_target.pcd", scene.target)
        np.savetxt(folder / f"{name}_stored.txt", stored)
        clouds = f"{name}_reference.pcd,{name}_target.pcd"
        lines.append(f"{name},{clouds},{name}_stored.txt")
        if calibrate:
            lines.append(f"{name}-cal,{clouds},")
    manifest = folder / "manifest.csv"
    manifest.write_text("\n".join(lines) + "\n")
    return manifest
