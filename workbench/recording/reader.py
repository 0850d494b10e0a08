"""Reading a workbench ``.rrd`` back into numpy arrays (tests, the ``inspect`` command, exports).

The file is read once with ``rr.chunk.RrdReader(path).stream()``; each chunk becomes an Arrow
record batch (``chunk.to_record_batch()``), so no server and no DataFusion are involved
(Rerun 0.41 Python API reference, ``rerun.chunk.RrdReader``). Accessors gather one component of
one entity across all chunks,
drop rows where it is null, and sort the rows by the requested timeline (stable, so rows logged at
the same time keep file order).

Times come back as float seconds for duration timelines (``time``) and as integers for sequence
timelines (``step``, ``iteration``, ``sample``); :meth:`RecordingData.times` gives the raw integer
nanoseconds too. Geometry comes back as float64 arrays of what Rerun stored (float32 for
positions, sizes and quaternions, so compare with float32 tolerance); quaternions are xyzw.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import rerun as rr

from workbench.recording import layout

__all__ = ["RecordingError", "RecordingData", "read_recording", "rerun_executable", "verify"]

_PROPERTIES = "/__properties"


class RecordingError(ValueError):
    """The file is not a complete workbench recording (partial, no footer, undecodable)."""


def read_recording(path: str | os.PathLike[str]) -> RecordingData:
    """Load every chunk of the first recording in ``path`` into a :class:`RecordingData`.

    Raises ``FileNotFoundError`` if the file is missing and :class:`RecordingError` if it is a
    ``.partial`` file of a run still in progress (or interrupted), has no RRD footer (the writer
    never disconnected), cannot be decoded, or holds no recording.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording not found: {p}")
    if p.name.endswith(".partial"):
        raise RecordingError(f"{p} is a partial recording (run in progress or interrupted)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the SDK warns about missing footers; we raise below instead
        try:
            reader = rr.chunk.RrdReader(p)
            stores = reader.recordings()
        except (RuntimeError, ValueError) as e:
            raise RecordingError(f"cannot decode {p}: {e}") from e
        if not stores:
            raise RecordingError(f"{p} holds no recording")
        try:
            reader.store(store=stores[0])  # reads the manifest only; fails without a footer
        except (RuntimeError, ValueError) as e:
            raise RecordingError(f"{p} has no RRD footer (incomplete recording): {e}") from e
        try:
            chunks = [(c.entity_path, c.is_static, c.to_record_batch()) for c in reader.stream(store=stores[0])]
        except (RuntimeError, ValueError) as e:
            raise RecordingError(f"cannot decode {p}: {e}") from e
    return RecordingData(
        path=p,
        application_id=stores[0].application_id,
        recording_id=stores[0].recording_id,
        chunks=chunks,
        file_size=p.stat().st_size,
    )


def verify(path: str | os.PathLike[str]) -> tuple[bool, str]:
    """Run ``rerun rrd verify <path>``; returns (ok, CLI output).

    The ``rerun`` executable is looked up next to ``sys.executable`` (the venv) first, then on
    ``PATH``. ok is False when the CLI is missing, fails, or reports a missing footer. The CLI in
    0.41 exits 0 for a file it cannot recognise as RRD at all ("0 files verified without error"),
    so ok also requires it to report exactly one verified file.
    """
    cmd = rerun_executable()
    if cmd is None:
        return False, "rerun CLI not found next to the Python interpreter or on PATH"
    try:
        proc = subprocess.run([cmd, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.TimeoutExpired) as e:
        return False, f"rerun rrd verify failed to run: {e}"
    out = (proc.stdout + proc.stderr).strip()
    m = re.search(r"(\d+) files? verified without error", out)
    return proc.returncode == 0 and m is not None and int(m.group(1)) == 1, out


def rerun_executable() -> str | None:
    """The ``rerun`` command-line tool (viewer, ``rrd verify``): next to ``sys.executable`` (the
    venv) first, then on ``PATH``; None if there is none."""
    exe = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    return str(exe) if exe.is_file() and os.access(exe, os.X_OK) else shutil.which("rerun")


def _kind(field: pa.Field) -> str:
    meta = field.metadata or {}
    return meta.get(b"rerun:kind", b"").decode()


class RecordingData:
    """All chunks of one recording, with accessors that return numpy arrays.

    Attributes: ``path``, ``application_id``, ``recording_id``, ``recording_name`` (None if not
    set), ``file_size`` [bytes]. Entity arguments are absolute entity paths (see ``layout``);
    ``archetype_field`` names look like ``"Scalars:scalars"`` or ``"TextDocument:text"``.
    """

    def __init__(
        self,
        path: Path,
        application_id: str,
        recording_id: str,
        chunks: list[tuple[str, bool, pa.RecordBatch]],
        file_size: int,
    ) -> None:
        self.path = path
        self.application_id = application_id
        self.recording_id = recording_id
        self.file_size = file_size
        self._temporal: dict[str, list[pa.RecordBatch]] = defaultdict(list)
        self._static: dict[str, list[pa.RecordBatch]] = defaultdict(list)
        self._timeline_types: dict[str, pa.DataType] = {}
        for entity, is_static, batch in chunks:
            (self._static if is_static else self._temporal)[entity].append(batch)
            if not is_static:
                for field in batch.schema:
                    if _kind(field) == "index":
                        self._timeline_types.setdefault(field.name, field.type)
        try:
            self.recording_name: str | None = self.static_component(_PROPERTIES, "RecordingInfo:name")[0]
        except KeyError:
            self.recording_name = None

    # ------------------------------------------------------------------ structure
    def entities(self) -> list[str]:
        """Sorted entity paths holding data (recording properties under ``/__properties`` excluded)."""
        names = set(self._temporal) | set(self._static)
        return sorted(e for e in names if not e.startswith(_PROPERTIES))

    def timelines(self) -> list[str]:
        """Sorted timeline names used by temporal data."""
        return sorted(self._timeline_types)

    def components(self, entity: str) -> list[str]:
        """Sorted component names (``Archetype:field``) logged on ``entity``, temporal or static."""
        out = set()
        for batch in self._temporal.get(entity, []) + self._static.get(entity, []):
            out.update(f.name for f in batch.schema if _kind(f) == "data")
        return sorted(out)

    def row_count(self, entity: str, timeline: str = layout.TIME) -> int:
        """Number of temporal rows of ``entity`` on ``timeline`` (static rows not counted)."""
        n = 0
        for batch in self._temporal.get(entity, []):
            i = batch.schema.get_field_index(timeline)
            if i >= 0:
                n += len(batch) - batch.column(i).null_count
        return n

    def _to_time(self, raw: np.ndarray, timeline: str) -> np.ndarray:
        typ = self._timeline_types[timeline]
        if pa.types.is_duration(typ) or pa.types.is_timestamp(typ):
            return raw.astype(np.float64) / 1e9
        return raw

    def time_range(self, timeline: str = layout.TIME) -> tuple[Any, Any]:
        """(first, last) value of ``timeline`` over all entities: seconds (duration) or ints (sequence)."""
        if timeline not in self._timeline_types:
            raise KeyError(f"no timeline {timeline!r}; have {self.timelines()}")
        lo, hi = None, None
        for batches in self._temporal.values():
            for batch in batches:
                i = batch.schema.get_field_index(timeline)
                if i < 0:
                    continue
                col = batch.column(i).cast(pa.int64())
                mm = pc.min_max(col).as_py()
                if mm["min"] is None:
                    continue
                lo = mm["min"] if lo is None else min(lo, mm["min"])
                hi = mm["max"] if hi is None else max(hi, mm["max"])
        if lo is None:
            raise KeyError(f"timeline {timeline!r} has no rows")
        a, b = self._to_time(np.array([lo, hi], dtype=np.int64), timeline)
        return (float(a), float(b)) if a.dtype.kind == "f" else (int(a), int(b))

    # ------------------------------------------------------------------ generic access
    def _gather(self, entity: str, component: str, timeline: str) -> tuple[np.ndarray, pa.ListArray]:
        """(raw int64 times sorted, list-array of non-null cells) of one component on one timeline."""
        times, cells = [], []
        for batch in self._temporal.get(entity, []):
            ti = batch.schema.get_field_index(timeline)
            ci = batch.schema.get_field_index(component)
            if ti < 0 or ci < 0:
                continue
            col = batch.column(ci)
            tcol = batch.column(ti)
            keep = pc.and_(col.is_valid(), tcol.is_valid())
            times.append(pc.filter(tcol, keep).cast(pa.int64()).to_numpy())
            cells.append(pc.filter(col, keep))
        if not cells:
            if entity not in self._temporal and entity not in self._static:
                raise KeyError(f"no entity {entity!r} in {self.path}")
            raise KeyError(f"entity {entity!r} has no temporal {component!r} on timeline {timeline!r}")
        t = np.concatenate(times)
        order = np.argsort(t, kind="stable")
        arr = pa.concat_arrays(cells) if len(cells) > 1 else cells[0]
        return t[order], arr.take(pa.array(order))

    def times(self, entity: str, component: str, timeline: str = layout.TIME, *, raw: bool = False) -> np.ndarray:
        """Sorted times (n,) of the rows of ``component`` on ``entity``: seconds/ints, or raw int64 (ns)."""
        t, _ = self._gather(entity, component, timeline)
        return t if raw else self._to_time(t, timeline)

    def static_component(self, entity: str, archetype_field: str) -> Any:
        """Python value (list of instances) of the last static cell of ``archetype_field`` on ``entity``."""
        for batch in reversed(self._static.get(entity, [])):
            i = batch.schema.get_field_index(archetype_field)
            if i >= 0:
                col = batch.column(i)
                for j in range(len(col) - 1, -1, -1):
                    if col[j].is_valid:
                        return col[j].as_py()
        raise KeyError(f"no static {archetype_field!r} on {entity!r}")

    def properties(self) -> dict[str, dict[str, Any]]:
        """Recording properties ``{name: {key: value}}`` from ``send_property`` (and ``RecordingInfo``)."""
        out: dict[str, dict[str, Any]] = {}
        for entity, batches in self._static.items():
            if not entity.startswith(_PROPERTIES):
                continue
            name = entity[len(_PROPERTIES) :].strip("/") or "RecordingInfo"
            for batch in batches:
                for f, col in zip(batch.schema, batch.columns, strict=True):
                    if _kind(f) == "data":
                        key = f.name.split(":")[-1]
                        val = col[len(col) - 1].as_py()
                        out.setdefault(name, {})[key] = val[0] if isinstance(val, list) and len(val) == 1 else val
        return out

    # ------------------------------------------------------------------ typed accessors
    def scalars(self, entity: str, timeline: str = layout.TIME) -> tuple[np.ndarray, np.ndarray]:
        """``Scalars`` of ``entity``: times (n,) and values (n, k), sorted by ``timeline``."""
        t, cells = self._gather(entity, "Scalars:scalars", timeline)
        return self._to_time(t, timeline), _fixed_rows(cells, entity)

    def transforms(self, entity: str, timeline: str = layout.TIME) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``Transform3D`` rows: times (n,), translation (n, 3) [m], quaternion xyzw (n, 4)."""
        t, tr = self._gather(entity, "Transform3D:translation", timeline)
        t2, q = self._gather(entity, "Transform3D:quaternion", timeline)
        if not np.array_equal(t, t2):
            raise RecordingError(f"{entity}: translation and quaternion rows differ")
        return self._to_time(t, timeline), _vec_rows(tr, 3, entity)[:, 0], _vec_rows(q, 4, entity)[:, 0]

    def translations(self, entity: str, timeline: str = layout.TIME) -> tuple[np.ndarray, np.ndarray]:
        """``Transform3D`` translations alone: times (n,), translation (n, 3) [m] (entities whose pose
        carries no rotation, such as the entry's ``/world/vehicle``)."""
        t, tr = self._gather(entity, "Transform3D:translation", timeline)
        return self._to_time(t, timeline), _vec_rows(tr, 3, entity)[:, 0]

    def has_temporal(self, entity: str, component: str, timeline: str = layout.TIME) -> bool:
        """True if ``entity`` has at least one non-null temporal ``component`` row on ``timeline``."""
        for batch in self._temporal.get(entity, []):
            ti = batch.schema.get_field_index(timeline)
            ci = batch.schema.get_field_index(component)
            if ti >= 0 and ci >= 0 and batch.column(ci).null_count < len(batch):
                return True
        return False

    def meshes(
        self, entity: str, timeline: str = layout.TIME
    ) -> list[tuple[float | None, np.ndarray, np.ndarray, int]]:
        """Every ``Mesh3D`` of ``entity``: [(t or None if static, vertices (v, 3) [m], triangles (f, 3) int,
        albedo colour as packed 0xRRGGBBAA int (0xC8C8C8FF if none))], the static one first, then by time."""
        out: list[tuple[float | None, np.ndarray, np.ndarray, int]] = []

        def colour(cells: Any) -> int:
            return int(cells[0]) if cells else 0xC8C8C8FF

        try:
            v = np.asarray(self.static_component(entity, "Mesh3D:vertex_positions"), dtype=np.float64)
            f = np.asarray(self.static_component(entity, "Mesh3D:triangle_indices"), dtype=np.int64)
            try:
                c = colour(self.static_component(entity, "Mesh3D:albedo_factor"))
            except KeyError:
                c = 0xC8C8C8FF
            out.append((None, v.reshape(-1, 3), f.reshape(-1, 3), c))
        except KeyError:
            pass
        if self.has_temporal(entity, "Mesh3D:vertex_positions", timeline):
            t, vc = self._gather(entity, "Mesh3D:vertex_positions", timeline)
            _, fc = self._gather(entity, "Mesh3D:triangle_indices", timeline)
            try:
                _, cc = self._gather(entity, "Mesh3D:albedo_factor", timeline)
                cols = [colour(x) for x in cc.to_pylist()]
            except KeyError:
                cols = [0xC8C8C8FF] * len(t)
            tt = self._to_time(t, timeline)
            for i in range(len(t)):
                v = np.asarray(vc[i].as_py(), dtype=np.float64).reshape(-1, 3)
                f = np.asarray(fc[i].as_py(), dtype=np.int64).reshape(-1, 3)
                out.append((float(tt[i]), v, f, cols[i]))
        return out

    def clear_times(self, entity: str, timeline: str = layout.TIME) -> np.ndarray:
        """Times (n,) at which ``entity`` was cleared (``rr.Clear``), sorted; empty if never."""
        if not self.has_temporal(entity, "Clear:is_recursive", timeline):
            return np.zeros(0)
        t, _ = self._gather(entity, "Clear:is_recursive", timeline)
        return np.asarray(self._to_time(t, timeline), dtype=np.float64)

    def ellipsoids(
        self, entity: str, timeline: str = layout.TIME
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``Ellipsoids3D`` rows: times (n,), centers and half_sizes (n, k, 3) [m], quaternions (n, k, 4)."""
        t, c = self._gather(entity, "Ellipsoids3D:centers", timeline)
        _, h = self._gather(entity, "Ellipsoids3D:half_sizes", timeline)
        _, q = self._gather(entity, "Ellipsoids3D:quaternions", timeline)
        return (
            self._to_time(t, timeline),
            _vec_rows(c, 3, entity),
            _vec_rows(h, 3, entity),
            _vec_rows(q, 4, entity),
        )

    def line_strips(self, entity: str, timeline: str = layout.TIME) -> tuple[np.ndarray, list[list[np.ndarray]]]:
        """``LineStrips3D`` rows: times (n,) and, per row, a list of strips, each an (m, 3) array [m]."""
        t, cells = self._gather(entity, "LineStrips3D:strips", timeline)
        row_len = pc.list_value_length(cells).to_numpy(zero_copy_only=False)
        inner = pc.list_flatten(cells)
        strip_len = pc.list_value_length(inner).to_numpy(zero_copy_only=False)
        pts = _fsl_to_numpy(pc.list_flatten(inner), 3)
        strips = np.split(pts, np.cumsum(strip_len)[:-1]) if len(strip_len) else []
        bounds = np.concatenate([[0], np.cumsum(row_len)])
        return self._to_time(t, timeline), [strips[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def points(self, entity: str, timeline: str = layout.TIME) -> tuple[np.ndarray, list[np.ndarray]]:
        """``Points3D`` rows: times (n,) and, per row, positions (k_i, 3) [m]."""
        t, cells = self._gather(entity, "Points3D:positions", timeline)
        row_len = pc.list_value_length(cells).to_numpy(zero_copy_only=False)
        pts = _fsl_to_numpy(pc.list_flatten(cells), 3)
        return self._to_time(t, timeline), np.split(pts, np.cumsum(row_len)[:-1]) if len(row_len) else []

    def text_log(self, entity: str = layout.EVENTS, timeline: str = layout.TIME) -> list[tuple[Any, str, str | None]]:
        """``TextLog`` rows sorted by time: [(t, text, level)] (level None if not logged)."""
        t, text = self._gather(entity, "TextLog:text", timeline)
        try:
            t2, level = self._gather(entity, "TextLog:level", timeline)
            levels = [x[0] if x else None for x in level.to_pylist()]
            if not np.array_equal(t, t2):
                raise RecordingError(f"{entity}: text and level rows differ")
        except KeyError:
            levels = [None] * len(t)
        tt = self._to_time(t, timeline)
        return [(tt[i].item(), x[0], levels[i]) for i, x in enumerate(text.to_pylist())]

    def text_document(self, entity: str = layout.REPORT) -> str:
        """Text of the static ``TextDocument`` on ``entity`` (the markdown report)."""
        return self.static_component(entity, "TextDocument:text")[0]

    # ------------------------------------------------------------------ overview
    def summary(self) -> dict[str, Any]:
        """Plain-dict overview for the CLI ``inspect`` command.

        Keys: path, file_size_bytes, application_id, recording_id, recording_name,
        timelines {name: {"type", "range"}}, entities {path: {"rows": {timeline: n},
        "static": bool, "components": [...]}}, properties.
        """
        timelines = {}
        for name in self.timelines():
            typ = self._timeline_types[name]
            kind = (
                "duration" if pa.types.is_duration(typ) else "timestamp" if pa.types.is_timestamp(typ) else "sequence"
            )
            timelines[name] = {"type": kind, "range": list(self.time_range(name))}
        entities = {}
        for e in self.entities():
            rows = {tl: self.row_count(e, tl) for tl in self.timelines()}
            entities[e] = {
                "rows": {tl: n for tl, n in rows.items() if n},
                "static": bool(self._static.get(e)),
                "components": self.components(e),
            }
        return {
            "path": str(self.path),
            "file_size_bytes": self.file_size,
            "application_id": self.application_id,
            "recording_id": self.recording_id,
            "recording_name": self.recording_name,
            "timelines": timelines,
            "entities": entities,
            "properties": self.properties(),
        }


def _fsl_to_numpy(arr: pa.Array, width: int) -> np.ndarray:
    """Fixed-size-list<float> array -> (N, width) float64."""
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    if len(arr) == 0:
        return np.zeros((0, width))
    return arr.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, width)


def _vec_rows(cells: pa.ListArray, width: int, entity: str) -> np.ndarray:
    """List<fixed_size_list[width]> cells with the same instance count k -> (n, k, width)."""
    lens = pc.list_value_length(cells).to_numpy(zero_copy_only=False)
    if len(lens) and np.any(lens != lens[0]):
        raise RecordingError(f"{entity}: instance counts vary between rows ({lens.min()}..{lens.max()})")
    k = int(lens[0]) if len(lens) else 0
    return _fsl_to_numpy(pc.list_flatten(cells), width).reshape(len(lens), k, width)


def _fixed_rows(cells: pa.ListArray, entity: str) -> np.ndarray:
    """List<double> cells with the same length k -> (n, k) float64."""
    lens = pc.list_value_length(cells).to_numpy(zero_copy_only=False)
    if len(lens) and np.any(lens != lens[0]):
        raise RecordingError(f"{entity}: series count varies between rows ({lens.min()}..{lens.max()})")
    k = int(lens[0]) if len(lens) else 0
    flat = pc.list_flatten(cells).to_numpy(zero_copy_only=False).astype(np.float64)
    return flat.reshape(len(lens), k)
