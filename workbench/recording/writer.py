"""Atomic, columnar writing of workbench recordings (``.rrd``) with the Rerun 0.41 SDK.

:func:`open_recording` creates one recording per run, logs into ``<final>.<pid>.partial`` in the
same directory, and publishes it with an atomic ``os.replace`` only after the RRD footer has been
written, so an interrupted run never leaves a half-written file at the final path
(Rerun 0.41 Python API reference, ``rerun.RecordingStream.save``). Inside the block Rerun's strict
mode is on, so bad input raises instead of being dropped with a warning.

:class:`Recorder` is the only logging surface the rest of the workbench sees. It takes numpy
arrays and **times in float seconds** from the scenario's reference event; they are rounded to
integer nanoseconds (:func:`to_ns`) on the ``time`` timeline. An optional integer
``step`` array adds the ``step`` sequence timeline to the same rows. Every time series is sent
with ``send_columns`` (one call per entity, no Python loop over time); styling that never changes
(series names/colours, fill modes) is logged once as static data on fields that are never logged
over time.

Geometry conventions: positions/translations in metres in the entity's parent frame, expressed
relative to a local origin (Rerun stores float32); quaternions scalar-last ``[x, y, z, w]``,
Hamilton, ``q_parent_child`` (rotates child-frame vectors into the parent frame), as in
``scipy.spatial.transform.Rotation``. Colours are RGB or RGBA, integers 0–255 (or floats 0–1).
Entity paths and timelines come from :mod:`workbench.recording.layout` (docs/RECORDING.md).
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from workbench.core.rotation import dcm_to_quat
from workbench.estimation.health import health_markdown
from workbench.io.results import OutputError
from workbench.recording import layout

__all__ = [
    "to_ns",
    "open_recording",
    "remove_stale_partials",
    "Recorder",
    "covariance_ellipsoids",
    "PALETTE",
    "PALETTE_NAMES",
]

_GREY = (150, 150, 150, 255)
_PALETTE = (
    (31, 119, 180, 255),
    (255, 127, 14, 255),
    (44, 160, 44, 255),
    (214, 39, 40, 255),
    (148, 103, 189, 255),
    (140, 86, 75, 255),
    (227, 119, 194, 255),
    (188, 189, 34, 255),
    (23, 190, 207, 255),
)
#: what a reader calls the colours of :data:`PALETTE` (for a view title naming them instead of a legend)
PALETTE_NAMES = ("blue", "orange", "green", "red", "purple", "brown", "pink", "olive", "cyan")
#: the colours series_with_bounds gives its k series when no colour is given
PALETTE = _PALETTE
_LEVELS = frozenset({"INFO", "WARN", "ERROR", "DEBUG", "TRACE", "CRITICAL"})
#: time bins of the value extents a Recorder keeps per call that logs a series (Recorder.value_range)
_RANGE_BINS = 256


def to_ns(t_s: Any) -> np.ndarray:
    """Float seconds (any shape) -> ``timedelta64[ns]`` array, **rounded** to the nearest nanosecond.

    ``rr.TimeColumn(duration=float_array)`` truncates ``t*1e9``, so 2.05 s would land
    at 2049999999 ns; rounding keeps a 10 ms grid exactly on ``k * 10_000_000`` ns.
    """
    t = np.asarray(t_s, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError("times must be finite seconds")
    return np.round(t * 1e9).astype(np.int64).astype("timedelta64[ns]")


@contextlib.contextmanager
def open_recording(
    final_path: str | os.PathLike[str],
    name: str,
    blueprint: Any = None,
    application_id: str = layout.APPLICATION_ID,
    properties: dict[str, dict[str, Any]] | None = None,
) -> Iterator[Recorder]:
    """Open a new recording that appears at ``final_path`` only if the ``with`` block succeeds.

    Parameters
    ----------
    final_path : path of the published ``.rrd``; parent directories are created.
    name : recording name shown in the Viewer (the scenario name).
    blueprint : optional ``rerun.blueprint.Blueprint`` (or view/container) embedded as the default
        layout; it applies because it is saved under the same ``application_id``.
    application_id : Rerun application id (``edl-workbench``).
    properties : optional ``{property_name: {key: value}}`` sent with ``send_property``.

    Yields a :class:`Recorder`. The data goes to ``<final>.<pid>.partial`` in the same directory.
    On success: flush, disconnect (writes the RRD footer), fsync, then ``os.replace`` onto
    ``final_path``. On any exception, including ``KeyboardInterrupt``, the stream is disconnected,
    the partial file deleted and the exception re-raised; an existing file at ``final_path`` is
    left untouched. Partials of killed runs beside ``final_path`` are removed first
    (:func:`remove_stale_partials`). A folder or file that cannot be written (read-only, missing,
    full disk) raises :class:`workbench.io.results.OutputError` naming the path. Rerun strict mode
    is switched on (process-wide) for the duration of the block
    and restored afterwards, so logging errors raise ``ValueError``/``TypeError``.
    """
    final = Path(final_path)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError.wrap(err, final.parent, "cannot create the recording folder") from err
    remove_stale_partials(final)
    tmp = final.with_name(f"{final.name}.{os.getpid()}.partial")
    previous_strict = rr.strict_mode()
    rr.set_strict_mode(True)
    stream = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
    try:
        try:
            try:
                # a read-only or missing folder is found here, not in Rerun's writer thread
                with open(tmp, "wb"):
                    pass
                os.remove(tmp)
                stream.save(str(tmp), default_blueprint=blueprint)
            except OSError as err:
                raise OutputError.wrap(err, tmp, "cannot write the recording") from err
            stream.set_log_time_enabled(False)
            stream.send_recording_name(name)
            recorder = Recorder(stream)
            for prop_name, values in (properties or {}).items():
                recorder.property(prop_name, values)
            yield recorder
            try:
                stream.flush()
                stream.disconnect()
                with open(tmp, "rb") as f:
                    os.fsync(f.fileno())
                os.replace(tmp, final)
            except OSError as err:
                raise OutputError.wrap(err, final, "cannot write the recording") from err
            except RuntimeError as err:  # Rerun's file writer died (e.g. "No space left on device")
                raise OutputError(
                    f"cannot write the recording {final}: Rerun's file writer failed ({err}); "
                    f"{_space_note(final.parent)}"
                ) from err
        except BaseException:
            with contextlib.suppress(Exception):
                stream.disconnect()
            with contextlib.suppress(FileNotFoundError):
                os.remove(tmp)
            raise
    finally:
        rr.set_strict_mode(previous_strict)


def _space_note(folder: Path) -> str:
    """A hint for a failed write: the free space left in ``folder``."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return "is the disk full or the folder not writable?"
    return f"{free / 1e6:.1f} MB free in {folder}" + (" (the disk is full)" if free < 64e6 else "")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def remove_stale_partials(final_path: str | os.PathLike[str]) -> list[Path]:
    """Delete ``<final>.<pid>.partial`` files left beside ``final_path`` by runs that were killed
    (SIGKILL, power loss: no cleanup could run), i.e. whose ``pid`` is no longer a live process.

    A partial of a live process (a run in progress, or a reused pid) is left alone. Returns the
    files removed; files that cannot be removed are skipped (the new run does not need them gone).
    """
    final = Path(final_path)
    removed = []
    try:
        candidates = list(final.parent.glob(f"{glob.escape(final.name)}.*.partial"))
    except OSError:
        return removed
    for p in candidates:
        pid = p.name[len(final.name) + 1 : -len(".partial")]
        if not pid.isdigit() or int(pid) == os.getpid() or _pid_alive(int(pid)):
            continue
        try:
            p.unlink()
            removed.append(p)
        except OSError:
            pass
    return removed


def covariance_ellipsoids(covariances: Any, nsigma: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Principal-axis ellipsoids of covariance matrices, vectorised over leading axes.

    ``covariances`` (..., 3, 3) [m²] (symmetrised here) -> ``half_sizes`` (..., 3) [m] =
    ``nsigma * sqrt(eigenvalues)`` (negative round-off eigenvalues clipped to 0) and
    ``quaternions`` (..., 4) xyzw of the eigenvector matrix ``V`` (columns = principal axes, sign
    fixed so det V = +1): ``Σ = R(q) diag((half_sizes/nsigma)²) R(q)ᵀ``. The ellipsoid is in the
    frame the covariance is expressed in.
    """
    cov = np.asarray(covariances, dtype=np.float64)
    if cov.shape[-2:] != (3, 3):
        raise ValueError(f"covariances must be (..., 3, 3), got {cov.shape}")
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    w, v = np.linalg.eigh(cov)
    flip = np.linalg.det(v) < 0
    v[..., :, 0] = np.where(flip[..., None], -v[..., :, 0], v[..., :, 0])
    half_sizes = nsigma * np.sqrt(np.clip(w, 0.0, None))
    return half_sizes, dcm_to_quat(v)


def _as_colors(c: Any) -> np.ndarray:
    a = np.asarray(c)
    if a.shape[-1:] not in ((3,), (4,)):
        raise ValueError(f"colours must end in 3 (RGB) or 4 (RGBA) channels, got shape {a.shape}")
    if np.issubdtype(a.dtype, np.integer):
        if a.min(initial=0) < 0 or a.max(initial=0) > 255:
            raise ValueError("integer colours must be in 0..255")
        return a.astype(np.uint8)
    return a.astype(np.float32)


def _per_series(value: Any, k: int, what: str) -> list[Any]:
    """Broadcast one value or a list of ``k`` values to a list of ``k`` (series styling)."""
    if isinstance(value, str | int | float) or (what == "colors" and np.ndim(value) == 1):
        return [value] * k
    out = list(value)
    if len(out) != k:
        raise ValueError(f"{what}: expected {k} entries (one per series), got {len(out)}")
    return out


def _one_row(columns: rr.ComponentColumnList) -> list[rr.ComponentColumn]:
    """Re-partition archetype columns so that each column is a single row (any instance count)."""
    return [c.partition([len(c.component_batch.as_arrow_array())]) for c in columns]


def _split(value: Any, n: int, counts: np.ndarray, item_ndim: int, what: str) -> tuple[str, np.ndarray] | None:
    """Classify per-instance styling as static or per-step.

    ``item_ndim`` is 1 for colours (each item is RGB/RGBA), 0 for radii. Returns
    ``("static", array)`` for one item or one per instance (applies to every step),
    ``("temporal", flat)`` for per-step values (array ``(n, k, ...)`` or ragged list of ``n``),
    flattened to match the flattened instances, or ``None``.
    """
    if value is None:
        return None
    try:
        a = np.asarray(value)
        ragged = a.dtype == object
    except ValueError:
        ragged = True
    if ragged:
        items = list(value)
        if len(items) != n:
            raise ValueError(f"{what}: per-step list must have {n} entries, got {len(items)}")
        parts = [np.asarray(v).reshape((-1,) + np.shape(v)[np.ndim(v) - item_ndim :]) for v in items]
        flat = np.concatenate(parts) if parts else np.zeros((0,))
    elif a.ndim <= item_ndim + 1:
        return "static", a
    elif a.ndim == item_ndim + 2:
        if a.shape[0] != n:
            raise ValueError(f"{what}: per-step array must have {n} rows, got {a.shape[0]}")
        flat = a.reshape((-1,) + a.shape[2:])
    else:
        raise ValueError(f"{what}: unexpected shape {a.shape}")
    if len(flat) != int(np.sum(counts)):
        raise ValueError(f"{what}: {len(flat)} per-step values for {int(np.sum(counts))} instances")
    return "temporal", flat


class Recorder:
    """Columnar logging into one open Rerun recording (see module docstring for conventions).

    Create it with :func:`open_recording`. ``t`` arguments are 1-D float seconds (n,), ``step``
    optional 1-D integers (n,) for the ``step`` timeline. The underlying
    ``rr.RecordingStream`` is available as :attr:`stream` for anything not covered here.
    """

    def __init__(self, stream: rr.RecordingStream) -> None:
        self.stream = stream
        self._extents: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {}

    def value_range(self, origin: str, t0: float | None = None, t1: float | None = None) -> tuple[float, float] | None:
        """(min, max) of the finite values :meth:`scalars` and :meth:`scatter` (so also
        :meth:`series_with_bounds`) logged against ``time`` at ``origin`` and below it, between
        ``t0`` and ``t1`` [s] when given (to the resolution of :data:`_RANGE_BINS` time bins per
        call: a bin that overlaps the window counts whole); None when there are none. A layout
        sent after the run sets a plot's y range from it."""
        root = origin.rstrip("/")
        lo, hi = np.inf, -np.inf
        for e, chunks in self._extents.items():
            if e != root and not e.startswith(root + "/"):
                continue
            for b0, b1, vmin, vmax in chunks:
                m = np.ones(b0.size, bool)
                if t0 is not None:
                    m &= b1 >= t0
                if t1 is not None:
                    m &= b0 <= t1
                if m.any():
                    lo, hi = min(lo, float(vmin[m].min())), max(hi, float(vmax[m].max()))
        return (lo, hi) if lo <= hi else None

    def _note_range(self, entity: str, t: Any, v: np.ndarray) -> None:
        """Keep the extents of the finite ``v`` (n,) or (n, k) logged against ``t`` (n,) [s] of
        ``entity``, per time bin (first and last time, min, max)."""
        if t is None:
            return
        t = np.asarray(t, dtype=np.float64)
        w = v.reshape(t.size, -1)
        ok = np.isfinite(w)
        vmin = np.where(ok, w, np.inf).min(axis=1)
        vmax = np.where(ok, w, -np.inf).max(axis=1)
        keep = ok.any(axis=1) & np.isfinite(t)
        if not keep.any():
            return
        order = np.argsort(t[keep], kind="stable")
        t, vmin, vmax = t[keep][order], vmin[keep][order], vmax[keep][order]
        idx = np.unique(np.linspace(0, t.size, min(_RANGE_BINS, t.size) + 1).astype(int)[:-1])
        chunk = (
            t[idx],
            np.maximum.reduceat(t, idx),
            np.minimum.reduceat(vmin, idx),
            np.maximum.reduceat(vmax, idx),
        )
        self._extents.setdefault(entity, []).append(chunk)

    # ------------------------------------------------------------------ helpers
    def _index(
        self, t: Any, step: Any = None, sequences: dict[str, Any] | None = None
    ) -> tuple[list[rr.TimeColumn], int]:
        """The index columns of n rows: ``t`` (n,) [s] on ``time`` (None: no ``time`` index, then
        ``sequences`` must give one), ``step`` (n,) integers on ``step``, ``sequences`` {timeline:
        (n,) integers} on other sequence timelines (e.g. :data:`layout.MACH_DESCENDING`)."""
        cols: dict[str, Any] = {} if step is None else {layout.STEP: step}
        cols.update(sequences or {})
        idx: list[rr.TimeColumn] = []
        n = None
        if t is not None:
            t = np.asarray(t, dtype=np.float64)
            if t.ndim != 1:
                raise ValueError(f"t must be 1-D seconds, got shape {t.shape}")
            idx.append(rr.TimeColumn(layout.TIME, duration=to_ns(t)))
            n = len(t)
        if not idx and not cols:
            raise ValueError("rows need an index: t [s] or a sequence timeline")
        for name, values in cols.items():
            s = np.asarray(values)
            if s.ndim != 1 or (n is not None and len(s) != n) or not np.issubdtype(s.dtype, np.integer):
                raise ValueError(f"{name} must be 1-D integers of {n} rows, got {s.dtype} {s.shape}")
            n = len(s)
            idx.append(rr.TimeColumn(name, sequence=s.astype(np.int64)))
        return idx, int(n)

    @staticmethod
    def _check_rows(name: str, a: np.ndarray, n: int) -> None:
        if a.shape[0] != n:
            raise ValueError(f"{name}: {a.shape[0]} rows for {n} times")

    def _send(self, entity: str, idx: list[rr.TimeColumn], columns: Any) -> None:
        self.stream.send_columns(entity, indexes=idx, columns=columns)

    def _log_static(self, entity: str, archetype: Any) -> None:
        self.stream.log(entity, archetype, static=True)

    def _log_row(self, entity: str, archetype: Any, columns: Any, static: bool, t: float | None) -> None:
        """Log one row: static (``static=True``, ``t=None``) or at time ``t`` [s] (``static=False``)."""
        if static and t is None:
            self._log_static(entity, archetype())
        elif not static and t is not None:
            idx, _ = self._index([t])
            self._send(entity, idx, _one_row(columns()))
        else:
            raise ValueError("give either static=True (no t), or static=False with a time t [s]")

    # ------------------------------------------------------------------ scene basics
    def view_coordinates(self, entity: str = layout.WORLD) -> None:
        """Declare ``entity`` right-handed, Z up (static). Sets only the Viewer's eye/up-axis/grid."""
        self._log_static(entity, rr.ViewCoordinates.RIGHT_HAND_Z_UP)

    def static_transform(
        self,
        entity: str,
        translation: Any = None,
        quaternion_xyzw: Any = None,
        mat3x3: Any = None,
    ) -> None:
        """Static pose of ``entity`` in its parent: translation (3,) [m], rotation xyzw (4,) or 3x3 matrix.

        The rotation maps child-frame vectors into the parent frame (``q_parent_child``). Give at
        most one of ``quaternion_xyzw`` and ``mat3x3``.
        """
        if quaternion_xyzw is not None and mat3x3 is not None:
            raise ValueError("give quaternion_xyzw or mat3x3, not both")
        kwargs: dict[str, Any] = {}
        if translation is not None:
            kwargs["translation"] = np.asarray(translation, dtype=np.float64).reshape(3)
        if quaternion_xyzw is not None:
            kwargs["quaternion"] = rr.Quaternion(xyzw=np.asarray(quaternion_xyzw, dtype=np.float64).reshape(4))
        if mat3x3 is not None:
            kwargs["mat3x3"] = np.asarray(mat3x3, dtype=np.float64).reshape(3, 3)
        self._log_static(entity, rr.Transform3D(**kwargs))

    def axes(self, entity: str, length: float) -> None:
        """Draw the frame axes of ``entity`` (static), each ``length`` [m] long."""
        self._log_static(entity, rr.TransformAxes3D(axis_length=float(length)))

    def poses(self, entity: str, t: Any, translation: Any, quaternion_xyzw: Any, *, step: Any = None) -> None:
        """Per-step pose of ``entity`` in its parent frame.

        translation (n, 3) [m], quaternion_xyzw (n, 4) ``q_parent_entity``; both go in one
        ``Transform3D`` call because the archetype is atomic (a row with only a translation
        resets the rotation). Children (meshes) follow the pose.
        """
        idx, n = self._index(t, step)
        p = np.asarray(translation, dtype=np.float64)
        q = np.asarray(quaternion_xyzw, dtype=np.float64)
        if p.shape != (n, 3) or q.shape != (n, 4):
            raise ValueError(f"poses: need translation ({n}, 3) and quaternion ({n}, 4), got {p.shape}, {q.shape}")
        self._send(entity, idx, rr.Transform3D.columns(translation=p, quaternion=q))

    # ------------------------------------------------------------------ time series
    def scalars(
        self,
        entity: str,
        t: Any,
        values: Any,
        *,
        step: Any = None,
        sequences: dict[str, Any] | None = None,
        names: str | Sequence[str] | None = None,
        colors: Any = None,
        widths: float | Sequence[float] | None = None,
    ) -> None:
        """Time series ``values`` (n,) or (n, k) — k series in one entity — drawn as lines.

        ``names``/``colors``/``widths`` (one, or one per series) go into a static
        ``SeriesLines`` on the same entity, logged only when given. Units are the caller's (SI).
        ``sequences`` {timeline: (n,) integers} indexes the rows on other sequence timelines too
        (``t`` None: on those only), e.g. a flight condition as the x axis.
        """
        idx, n = self._index(t, step, sequences)
        v = np.asarray(values, dtype=np.float64)
        if v.ndim not in (1, 2):
            raise ValueError(f"scalars: values must be (n,) or (n, k), got {v.shape}")
        self._check_rows(f"scalars {entity}", v, n)
        k = 1 if v.ndim == 1 else v.shape[1]
        self._send(entity, idx, rr.Scalars.columns(scalars=v))
        self._note_range(entity, t, v)
        if names is not None or colors is not None or widths is not None:
            style: dict[str, Any] = {}
            if names is not None:
                style["names"] = _series_names(names, k)
            if colors is not None:
                style["colors"] = _as_colors(_per_series(colors, k, "colors"))
            if widths is not None:
                style["widths"] = np.asarray(_per_series(widths, k, "widths"), dtype=np.float32)
            self._log_static(entity, rr.SeriesLines(**style))

    def scatter(
        self,
        entity: str,
        t: Any,
        values: Any,
        *,
        names: str | Sequence[str],
        colors: Any,
        marker: str = "circle",
        size: float = 2.0,
        step: Any = None,
        sequences: dict[str, Any] | None = None,
    ) -> None:
        """Raw measurements ``values`` (n,) or (n, k) drawn as markers (static ``SeriesPoints``).

        ``marker`` is a Rerun marker shape name ("circle", "cross", "diamond", ...), ``size`` in
        UI points; ``names``/``colors`` one or one per series; ``sequences`` as :meth:`scalars`.
        """
        idx, n = self._index(t, step, sequences)
        v = np.asarray(values, dtype=np.float64)
        if v.ndim not in (1, 2):
            raise ValueError(f"scatter: values must be (n,) or (n, k), got {v.shape}")
        self._check_rows(f"scatter {entity}", v, n)
        k = 1 if v.ndim == 1 else v.shape[1]
        self._send(entity, idx, rr.Scalars.columns(scalars=v))
        self._note_range(entity, t, v)
        self._log_static(
            entity,
            rr.SeriesPoints(
                names=_series_names(names, k),
                colors=_as_colors(_per_series(colors, k, "colors")),
                markers=[marker] * k,
                marker_sizes=np.full(k, size, dtype=np.float32),
            ),
        )

    def series_with_bounds(
        self,
        root: str,
        t: Any,
        value: Any,
        sigma: Any,
        *,
        nsigma: float = 3.0,
        truth: Any = None,
        names: str | Sequence[str] | None = None,
        step: Any = None,
        color: Any = None,
        truth_style: tuple[Any, float] | None = None,
        gap_s: float | None = None,
    ) -> None:
        """Estimate with ±nσ bounds (and truth) under ``root``, for one TimeSeriesView at ``root``.

        Logs ``root/value``, ``root/plus_{nsigma:g}sigma`` (value + nσ), ``root/minus_{nsigma:g}sigma``
        (value − nσ) and, if given, ``root/truth``. ``value``, ``sigma`` (1σ, same units, ≥ 0) and
        ``truth`` are (n,) or (n, k). Bounds are thin grey lines; truth is a thinner line in a lighter
        tint of the estimate colour (Rerun 0.41 has no dashed style), or ``truth_style`` (colour, width
        [UI points]) for all of them, e.g. a wide translucent band that stays visible under other
        estimates drawn in the same view. ``names`` default to the last part of ``root``
        (``name[i]`` for k > 1); ``color`` is one colour or one per series. A NaN value or σ is a gap
        in the line and its bounds (Rerun breaks a line at NaN), never a zero. ``gap_s`` [s]: where two
        consecutive ``t`` are further apart (a data blackout the estimate was bridged across), a NaN
        row at the midpoint breaks the estimate and its bounds (the truth is drawn through); with
        ``t`` only, not ``step``.
        """
        v = np.asarray(value, dtype=np.float64)
        s = np.broadcast_to(np.asarray(sigma, dtype=np.float64), v.shape)
        if v.ndim not in (1, 2):
            raise ValueError(f"series_with_bounds: value must be (n,) or (n, k), got {v.shape}")
        if np.any(s < 0):
            raise ValueError("series_with_bounds: sigma must be >= 0")
        if gap_s is not None and step is None:
            t, v, s, truth = _break_gaps(np.asarray(t, dtype=np.float64), gap_s, v, s, truth)
        k = 1 if v.ndim == 1 else v.shape[1]
        base = root.rstrip("/").rsplit("/", 1)[-1]
        labels = _series_names(names if names is not None else base, k)
        if color is None:
            cols = np.array([_PALETTE[i % len(_PALETTE)] for i in range(k)], dtype=np.uint8)
        else:
            cols = _as_colors(_per_series(color, k, "color"))
            if cols.dtype != np.uint8:
                cols = np.round(np.clip(cols, 0, 1) * 255).astype(np.uint8)
            if cols.shape[1] == 3:
                cols = np.concatenate([cols, np.full((k, 1), 255, np.uint8)], axis=1)
        plus, minus = layout.bound_names(nsigma)
        sym = f"{nsigma:g}σ"
        self.scalars(f"{root}/{layout.VALUE}", t, v, step=step, names=labels, colors=cols, widths=1.5)
        grey = [_GREY] * k
        self.scalars(
            f"{root}/{plus}",
            t,
            v + nsigma * s,
            step=step,
            names=[f"{lab} +{sym}" for lab in labels],
            colors=grey,
            widths=0.5,
        )
        self.scalars(
            f"{root}/{minus}",
            t,
            v - nsigma * s,
            step=step,
            names=[f"{lab} −{sym}" for lab in labels],
            colors=grey,
            widths=0.5,
        )
        if truth is not None:
            tr = np.asarray(truth, dtype=np.float64)
            if tr.shape != v.shape:
                raise ValueError(f"series_with_bounds: truth shape {tr.shape} != value shape {v.shape}")
            if truth_style is None:
                tint = cols.astype(np.float64)
                tint[:, :3] = 0.45 * tint[:, :3] + 0.55 * 255.0
                truth_cols, truth_width = tint.astype(np.uint8), 1.0
            else:
                truth_cols, truth_width = [truth_style[0]] * k, float(truth_style[1])
            self.scalars(
                f"{root}/{layout.TRUTH_SERIES}",
                t,
                tr,
                step=step,
                names=[f"{lab} truth" for lab in labels],
                colors=truth_cols,
                widths=truth_width,
            )

    def events(self, entries: Sequence[tuple[float, str, str]], entity: str = layout.EVENTS) -> None:
        """Key events as a ``TextLog``: ``entries`` = [(t [s], text, level)], level INFO/WARN/ERROR/DEBUG."""
        if not entries:
            return
        t, text, level = zip(*entries, strict=True)
        level = [str(lv).upper() for lv in level]
        bad = sorted(set(level) - _LEVELS)
        if bad:
            raise ValueError(f"events: unknown levels {bad}")
        idx, _ = self._index(np.asarray(t, dtype=np.float64))
        self._send(entity, idx, rr.TextLog.columns(text=[str(x) for x in text], level=level))

    def report(self, markdown: str, entity: str = layout.REPORT) -> None:
        """The scorecard as a static markdown ``TextDocument``."""
        self._log_static(entity, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN))

    def health(self, health: dict, entity: str = layout.HEALTH) -> None:
        """The health verdict (``summary["health"]``, :mod:`workbench.estimation.health`) as a static
        markdown ``TextDocument``: the verdict and every check that is not OK."""
        self._log_static(entity, rr.TextDocument(health_markdown(health), media_type=rr.MediaType.MARKDOWN))

    def property(self, name: str, values: dict[str, Any]) -> None:
        """Recording property ``name`` (stored under ``/__properties/<name>``) from a flat dict."""
        self.stream.send_property(name, rr.AnyValues(**values))

    # ------------------------------------------------------------------ 3D geometry
    def ellipsoids(
        self,
        entity: str,
        t: Any,
        centers: Any,
        covariances: Any,
        *,
        nsigma: float = 3.0,
        color: Any = None,
        line_radius: float | None = None,
        label: str | None = None,
        fill: bool = True,
        step: Any = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per-step nσ covariance ellipsoids (transparent fill + wireframe, or the wireframe only
        when not ``fill``; ``line_radius`` the wireframe's [m], negative: screen points; None: the
        viewer's default; ``label`` a text shown at each ellipsoid's centre, e.g. its σ level, in
        ``color``, whose alpha is also the fill's).

        ``centers`` (n, 3) or (n, k, 3) [m] and ``covariances`` (n, 3, 3) or (n, k, 3, 3) [m²], both
        in the frame of ``entity``'s parent chain (log a world covariance under ``/world`` with the
        position as centre, a body covariance under the body with centres at 0). Returns the logged
        ``(half_sizes, quaternions)`` with the leading shape of ``centers``; see
        :func:`covariance_ellipsoids`.
        """
        idx, n = self._index(t, step)
        c = np.asarray(centers, dtype=np.float64)
        half_sizes, quats = covariance_ellipsoids(covariances, nsigma)
        if c.shape[-1] != 3 or c.ndim not in (2, 3) or half_sizes.shape != c.shape or c.shape[0] != n:
            raise ValueError(f"ellipsoids: centers {c.shape} / covariances {np.shape(covariances)} for {n} times")
        if c.ndim == 2:
            cols = rr.Ellipsoids3D.columns(centers=c, half_sizes=half_sizes, quaternions=quats)
        else:
            k = c.shape[1]
            cols = rr.Ellipsoids3D.columns(
                centers=c.reshape(-1, 3),
                half_sizes=half_sizes.reshape(-1, 3),
                quaternions=quats.reshape(-1, 4),
            ).partition(np.full(n, k))
        self._send(entity, idx, cols)
        self._log_static(
            entity,
            rr.Ellipsoids3D.from_fields(
                colors=_as_colors(color if color is not None else (255, 165, 0, 90)),
                fill_mode=(
                    rr.components.FillMode.TransparentFillMajorWireframe
                    if fill
                    else rr.components.FillMode.MajorWireframe
                ),
                line_radii=None if line_radius is None else [float(line_radius)],
                labels=None if label is None else [label],
                show_labels=None if label is None else True,
            ),
        )
        return half_sizes, quats

    def line_strip(
        self,
        entity: str,
        points: Any,
        *,
        color: Any = None,
        radius: float | None = None,
        static: bool = True,
        t: float | None = None,
    ) -> None:
        """One polyline ``points`` (m, 3) [m] (or several: (s, m, 3) / list of (m_i, 3)).

        Static by default (e.g. a whole trajectory); with ``static=False`` give ``t`` [s] to log it
        as one row at that time. ``radius`` in scene units [m].
        """
        strips = _strip_list(points)
        kwargs: dict[str, Any] = {"strips": strips, **_row_style(color, radius, len(strips))}
        self._log_row(entity, lambda: rr.LineStrips3D(**kwargs), lambda: rr.LineStrips3D.columns(**kwargs), static, t)

    def line_strips_series(
        self,
        entity: str,
        t: Any,
        strips: Any,
        *,
        colors: Any = None,
        radii: Any = None,
        step: Any = None,
    ) -> None:
        """Per-step sets of polylines (radar beams, stroke segments, trajectories so far).

        ``strips``: array (n, s, k, 3) [m] — s strips of k points per step (k = 2: segments) —,
        (n, k, 3) for one strip per step, or a ragged list of n per-step lists of (m, 3) arrays.
        ``colors``: one colour or (s, 3|4) per strip (static, every step), or per step
        (n, s, 3|4) / list of n (s_i, 3|4). ``radii`` [m]: scalar or (s,) static, (n, s) / list per step.
        """
        idx, n = self._index(t, step)
        flat, counts = _strips_per_step(strips, n)
        kwargs: dict[str, Any] = {"strips": flat}
        static_style = _series_style(kwargs, colors, radii, n, counts)
        self._send(entity, idx, rr.LineStrips3D.columns(**kwargs).partition(counts))
        if static_style:
            self._log_static(entity, rr.LineStrips3D.from_fields(**static_style))

    def arrows_series(
        self,
        entity: str,
        t: Any,
        vectors: Any,
        *,
        color: Any = None,
        radius: float | None = None,
        label: str | None = None,
        step: Any = None,
    ) -> None:
        """One arrow per step from the entity's origin: ``vectors`` (n, 3) [m, the entity's frame];
        ``color``, ``radius`` [m] (negative: screen points) and ``label`` static, for every step."""
        idx, n = self._index(t, step)
        v = np.asarray(vectors, dtype=np.float64)
        if v.shape != (n, 3):
            raise ValueError(f"arrows_series: need vectors ({n}, 3), got {v.shape}")
        self._send(entity, idx, rr.Arrows3D.columns(vectors=v))
        style: dict[str, Any] = {}
        if color is not None:
            c = _as_colors(color)
            style["colors"] = c.reshape(-1, c.shape[-1])[:1]
        if radius is not None:
            style["radii"] = [float(radius)]
        if label is not None:
            style["labels"] = [label]
            style["show_labels"] = True
        if style:
            self._log_static(entity, rr.Arrows3D.from_fields(**style))

    def points(
        self,
        entity: str,
        positions: Any,
        *,
        colors: Any = None,
        radii: Any = None,
        static: bool = True,
        t: float | None = None,
    ) -> None:
        """A point cloud ``positions`` (k, 3) [m]; colours one or (k, 3|4), radii [m] scalar or (k,).

        Static by default; with ``static=False`` give ``t`` [s] to log it as one row at that time.
        """
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        kwargs: dict[str, Any] = {"positions": p, **_row_style(colors, radii, len(p))}
        self._log_row(entity, lambda: rr.Points3D(**kwargs), lambda: rr.Points3D.columns(**kwargs), static, t)

    def points_series(
        self,
        entity: str,
        t: Any,
        positions: Any,
        *,
        colors: Any = None,
        radii: Any = None,
        step: Any = None,
    ) -> None:
        """Per-step point sets: ``positions`` (n, k, 3) [m] or a ragged list of n (k_i, 3) arrays.

        ``colors``: one colour or (k, 3|4) per point (static), or per step (n, k, 3|4) / list of n
        (k_i, 3|4) (e.g. accepted vs rejected Monte Carlo members). ``radii`` [m]: scalar or (k,)
        static, (n, k) / list per step.
        """
        idx, n = self._index(t, step)
        flat, counts = _points_per_step(positions, n)
        kwargs: dict[str, Any] = {"positions": flat}
        static_style = _series_style(kwargs, colors, radii, n, counts)
        self._send(entity, idx, rr.Points3D.columns(**kwargs).partition(counts))
        if static_style:
            self._log_static(entity, rr.Points3D.from_fields(**static_style))

    def text_labels_series(
        self, entity: str, t: Any, positions: Any, labels: Any, *, color: Any = None, step: Any = None
    ) -> None:
        """Labelled points per step: positions (n, 3) or (n, k, 3) [m]; labels k strings (static) or (n, k).

        The labels are drawn next to the points in the 3D view (``show_labels`` on), in ``color``
        (one RGB(A), static; None: the viewer's choice).
        """
        style: dict[str, Any] = {"show_labels": True}
        if color is not None:
            style["colors"] = _as_colors(color)
        idx, n = self._index(t, step)
        p = np.asarray(positions, dtype=np.float64)
        if p.ndim == 2:
            p = p[:, None, :]
        if p.shape[0] != n or p.shape[-1] != 3 or p.ndim != 3:
            raise ValueError(f"text_labels_series: positions {p.shape} for {n} times")
        k = p.shape[1]
        lab = np.asarray(labels, dtype=str)
        counts = np.full(n, k)
        if lab.ndim == 2:
            if lab.shape != (n, k):
                raise ValueError(f"text_labels_series: labels {lab.shape}, expected ({n}, {k})")
            cols = rr.Points3D.columns(positions=p.reshape(-1, 3), labels=lab.reshape(-1).tolist())
            self._send(entity, idx, cols.partition(counts))
            self._log_static(entity, rr.Points3D.from_fields(**style))
        else:
            self._send(entity, idx, rr.Points3D.columns(positions=p.reshape(-1, 3)).partition(counts))
            self._log_static(entity, rr.Points3D.from_fields(labels=lab.reshape(-1).tolist(), **style))

    def mesh(self, entity: str, mesh: Any, *, color: Any = (200, 200, 200, 255), static: bool = True) -> None:
        """A ``trimesh.Trimesh`` as a static ``Mesh3D`` (vertices [m] in ``entity``'s frame, vertex normals).

        ``color`` is the albedo factor (RGB/RGBA). Meshes are geometry that never changes: log them
        under an entity whose parent carries the per-step pose.
        """
        if not static:
            raise ValueError("mesh: only static meshes are supported; move them with poses() on the parent")
        self._log_static(
            entity,
            rr.Mesh3D(
                vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
                triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
                vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
                albedo_factor=_as_colors(color),
            ),
        )


def _break_gaps(t: np.ndarray, gap_s: float, v: np.ndarray, s: np.ndarray, truth: Any):
    """Insert a row at the midpoint of every step of ``t`` [s] longer than ``gap_s``: NaN in ``v`` and
    ``s`` (a break in the line), the mean of its neighbours in ``truth`` (None stays None)."""
    cut = np.flatnonzero(np.diff(t) > gap_s)
    if not cut.size:
        return t, v, s, truth
    pos = cut + 1
    t2 = np.insert(t, pos, 0.5 * (t[cut] + t[cut + 1]))
    v2 = np.insert(v, pos, np.nan, axis=0)
    s2 = np.insert(s, pos, np.nan, axis=0)
    if truth is not None:
        tr = np.asarray(truth, dtype=np.float64)
        if tr.shape == v.shape:
            truth = np.insert(tr, pos, 0.5 * (tr[cut] + tr[cut + 1]), axis=0)
    return t2, v2, s2, truth


def _tile(a: np.ndarray, count: int, item_ndim: int) -> np.ndarray:
    """One item (colour: item_ndim 1, radius: 0) repeated ``count`` times, or ``count`` items as given."""
    if a.ndim == item_ndim:
        return np.broadcast_to(a, (count,) + a.shape)
    if a.shape[0] != count:
        raise ValueError(f"expected one value or {count} values, got shape {a.shape}")
    return a


def _row_style(colors: Any, radii: Any, k: int) -> dict[str, Any]:
    """The ``colors`` / ``radii`` keyword arguments of one row of ``k`` items (each tiled to k)."""
    out: dict[str, Any] = {}
    if colors is not None:
        out["colors"] = _tile(_as_colors(colors), k, 1)
    if radii is not None:
        out["radii"] = _tile(np.asarray(radii, dtype=np.float32), k, 0)
    return out


def _series_style(kwargs: dict[str, Any], colors: Any, radii: Any, n: int, counts: np.ndarray) -> dict[str, Any]:
    """Split per-step ``colors`` / ``radii`` of a series of n steps (``counts`` items each): the
    per-step ones go into ``kwargs`` (columns), the static ones are returned (logged once)."""
    static_style: dict[str, Any] = {}
    for key, value, item_ndim in (("colors", colors, 1), ("radii", radii, 0)):
        split = _split(value, n, counts, item_ndim, key)
        if split is None:
            continue
        kind, arr = split
        arr = _as_colors(arr) if key == "colors" else np.asarray(arr, dtype=np.float32)
        (static_style if kind == "static" else kwargs)[key] = arr
    return static_style


def _series_names(names: str | Sequence[str], k: int) -> list[str]:
    if isinstance(names, str):
        return [names] if k == 1 else [f"{names}[{i}]" for i in range(k)]
    out = [str(x) for x in names]
    if len(out) != k:
        raise ValueError(f"names: expected {k} names (one per series), got {len(out)}")
    return out


def _strip_list(points: Any) -> list[np.ndarray]:
    """(m, 3) -> one strip; (s, m, 3) or a list of (m_i, 3) -> several strips."""
    try:
        a = np.asarray(points, dtype=np.float64)
    except ValueError:
        return [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in points]
    if a.ndim == 2 and a.shape[1] == 3:
        return [a]
    if a.ndim == 3 and a.shape[2] == 3:
        return list(a)
    raise ValueError(f"line strip points must be (m, 3), (s, m, 3) or a list of (m_i, 3); got {a.shape}")


def _strips_per_step(strips: Any, n: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Flatten per-step strips to a list of (m, 3) arrays plus strips-per-step counts (n,)."""
    try:
        a = np.asarray(strips, dtype=np.float64)
    except ValueError:
        a = None
    if a is not None and a.ndim in (3, 4) and a.shape[-1] == 3:
        if a.ndim == 3:
            a = a[:, None]
        if a.shape[0] != n:
            raise ValueError(f"line_strips_series: {a.shape[0]} steps of strips for {n} times")
        return list(a.reshape(-1, a.shape[2], 3)), np.full(n, a.shape[1])
    steps = list(strips)
    if len(steps) != n:
        raise ValueError(f"line_strips_series: {len(steps)} steps of strips for {n} times")
    flat = [np.asarray(s, dtype=np.float64).reshape(-1, 3) for step in steps for s in step]
    return flat, np.array([len(step) for step in steps], dtype=np.int64)


def _points_per_step(positions: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Flatten per-step points to (N, 3) plus points-per-step counts (n,)."""
    try:
        a = np.asarray(positions, dtype=np.float64)
    except ValueError:
        a = None
    if a is not None and a.ndim == 3 and a.shape[-1] == 3:
        if a.shape[0] != n:
            raise ValueError(f"points_series: {a.shape[0]} steps of points for {n} times")
        return a.reshape(-1, 3), np.full(n, a.shape[1])
    steps = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in positions]
    if len(steps) != n:
        raise ValueError(f"points_series: {len(steps)} steps of points for {n} times")
    flat = np.concatenate(steps) if steps else np.zeros((0, 3))
    return flat, np.array([len(p) for p in steps], dtype=np.int64)
