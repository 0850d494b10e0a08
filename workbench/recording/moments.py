"""Key moments in a recording: bookmarks in the events log, a machine-readable property, and a
Viewer layout (``.rbl``) per moment for ``workbench open REC.rrd --at NAME``.

A run's key moments (:class:`workbench.io.moments.KeyMoment`, named by the problem) go into its
recording twice (:func:`log_key_moments`):

* a ``TextLog`` row per moment at its time on ``/events/key_moments`` (``layout.KEY_MOMENTS``) —
  under ``/events``, so the events view lists them; clicking a row in the Viewer moves the time
  cursor there;
* the recording property ``key_moments`` (``/__properties/key_moments``): parallel lists
  ``names``, ``t_s``, ``descriptions``, ``window_start_s``, ``window_end_s`` (NaN: no window), so a
  tool finds them from the ``.rrd`` alone (:func:`read_key_moments`).

:func:`write_moment_blueprint` writes the layout that lands on one moment: the recording's own
embedded layout (the last blueprint stored in the ``.rrd``, copied chunk by chunk) with the time
panel replaced — the moment's time range as the time selection, looped, paused — and, where the
layout has no 3D view that already moves with the vehicle, the 3D views without a fixed camera
following ``/world/vehicle`` (``EyeControls3D(tracking_entity=...)``, that view made the active
tab). Rerun 0.41's blueprint has no field for the time cursor itself (the time panel holds the
timeline, play state, speed, loop mode and selection only); ``workbench open`` sets the cursor
through the Viewer's control API after loading (:func:`seek_viewer`).

Copying the embedded layout overrides ``rerun.blueprint.Blueprint._log_to_stream`` — the one hook
through which ``Blueprint.save`` writes the blueprint store — so that the saved ``.rbl`` holds the
recording's chunks plus the overrides; ``tests/recording/test_moments.py`` reads the file back.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.archetypes import ContainerBlueprint, EyeControls3D, TimePanelBlueprint
from rerun.blueprint.components import AbsoluteTimeRange

from workbench.io.moments import KeyMoment, MomentError, moments_from_dicts, ordered
from workbench.recording import layout
from workbench.recording.reader import RecordingData
from workbench.recording.writer import Recorder

__all__ = [
    "KEY_MOMENTS_PROPERTY",
    "MomentLayout",
    "UnknownMomentError",
    "ViewerCommand",
    "bookmark_text",
    "find_moment",
    "log_key_moments",
    "read_key_moments",
    "seek_viewer",
    "vehicle_eye",
    "viewer_command",
    "write_moment_blueprint",
]

#: name of the recording property holding the key moments (``/__properties/key_moments``)
KEY_MOMENTS_PROPERTY = "key_moments"

_TIME_PANEL = "/time_panel"


class UnknownMomentError(LookupError):
    """``--at NAME`` names no key moment of the recording; the message lists the valid names."""

    def __init__(self, name: str, moments: Sequence[KeyMoment], where: str = "the recording"):
        self.name = name
        self.valid = [m.name for m in moments]
        valid = ", ".join(self.valid) if self.valid else "none (it holds no key moments)"
        super().__init__(f"{where} has no key moment {name!r}; key moments: {valid}")


def bookmark_text(m: KeyMoment) -> str:
    """The events-log text of a key moment: ``★ <name> — <description>``."""
    return f"★ {m.name} — {m.description}"


def _as_moments(moments: Iterable[KeyMoment | Mapping[str, Any]]) -> list[KeyMoment]:
    return ordered(m if isinstance(m, KeyMoment) else KeyMoment.from_dict(m) for m in moments)


def log_key_moments(rec: Recorder, moments: Iterable[KeyMoment | Mapping[str, Any]]) -> list[KeyMoment]:
    """Log the key moments (objects or their summary dicts) into an open recording: one INFO
    ``TextLog`` row each on ``layout.KEY_MOMENTS`` at its time [s] (:func:`bookmark_text`) and the
    :data:`KEY_MOMENTS_PROPERTY` recording property. Returns the moments in time order; nothing is
    logged when there are none."""
    ms = _as_moments(moments)
    if not ms:
        return ms
    rec.events([(m.t_s, bookmark_text(m), "INFO") for m in ms], entity=layout.KEY_MOMENTS)
    nan = float("nan")
    rec.property(
        KEY_MOMENTS_PROPERTY,
        {
            "names": [m.name for m in ms],
            "t_s": [m.t_s for m in ms],
            "descriptions": [m.description for m in ms],
            "window_start_s": [m.window_s[0] if m.window_s else nan for m in ms],
            "window_end_s": [m.window_s[1] if m.window_s else nan for m in ms],
        },
    )
    return ms


def _listify(v: Any) -> list:
    """A property value as a list (the reader unwraps one-element lists)."""
    return list(v) if isinstance(v, list | tuple) else [v]


def read_key_moments(data: RecordingData) -> list[KeyMoment]:
    """The key moments of a recording, in time order: from its :data:`KEY_MOMENTS_PROPERTY`
    property, else from the ``key_moments`` of the run summary beside it
    (``<name>.summary.json``), else none. :class:`~workbench.io.moments.MomentError` if they are
    malformed."""
    prop = data.properties().get(KEY_MOMENTS_PROPERTY)
    if prop:
        names = _listify(prop.get("names"))
        cols = {k: _listify(prop.get(k)) for k in ("t_s", "descriptions", "window_start_s", "window_end_s")}
        if any(len(v) != len(names) for v in cols.values()):
            raise MomentError(f"{data.path}: the key_moments property has lists of different lengths")
        out = []
        for i, name in enumerate(names):
            lo, hi = cols["window_start_s"][i], cols["window_end_s"][i]
            window = None if lo is None or hi is None or math.isnan(lo) or math.isnan(hi) else (lo, hi)
            out.append(KeyMoment(str(name), float(cols["t_s"][i]), str(cols["descriptions"][i]), window))
        return ordered(out)
    summary = data.path.with_name(data.path.stem + ".summary.json")
    if summary.is_file():
        try:
            items = json.loads(summary.read_text(encoding="utf-8")).get("key_moments")
        except (OSError, ValueError):
            items = None
        return moments_from_dicts(items)
    return []


def find_moment(moments: Sequence[KeyMoment], name: str, where: str = "the recording") -> KeyMoment:
    """The moment called ``name``; :class:`UnknownMomentError` listing the valid names if none is."""
    for m in moments:
        if m.name == name:
            return m
    raise UnknownMomentError(name, moments, where)


# ----------------------------------------------------------------------------- blueprint per moment
def _ns(t_s: float) -> int:
    return int(round(float(t_s) * 1e9))


def _cells(chunk: rr.chunk.Chunk) -> dict[str, Any]:
    """The component cells of a one-row blueprint chunk, ``{"Archetype:field": python value}``
    (the last row's; timeline columns left out)."""
    rb = chunk.to_record_batch()
    out = {}
    for i, f in enumerate(rb.schema):
        if ":" not in f.name or pa.types.is_timestamp(f.type) or pa.types.is_duration(f.type):
            continue
        col = rb.column(i)
        for j in range(len(col) - 1, -1, -1):
            if col[j].is_valid:
                out[f.name] = col[j].as_py()
                break
    return out


def _first(v: Any) -> Any:
    return v[0] if isinstance(v, list) and v else v


def embedded_blueprint_chunks(path: str | os.PathLike[str]) -> list[rr.chunk.Chunk]:
    """The chunks of the layout a recording opens with: the last blueprint store in the ``.rrd``
    (a run embeds a default layout when it opens and may send the final one at the end); empty
    when the recording has no blueprint."""
    reader = rr.chunk.RrdReader(Path(path))
    stores = reader.blueprints()
    for store in reversed(stores):
        chunks = list(reader.stream(store=store))
        if chunks:
            return chunks
    return []


@dataclass
class MomentLayout:
    """What :func:`write_moment_blueprint` wrote: the ``path`` of the ``.rbl``, the ``moment``, the
    time selection ``window_s`` [s], whether the recording's own layout was ``copied`` (else the
    Viewer's automatic layout with the time panel), the names of the 3D views set to follow
    ``follow`` and of those left as they were (their own camera, or already at the vehicle)."""

    path: Path
    moment: KeyMoment
    window_s: tuple[float, float]
    copied: bool
    follow: str | None
    following_views: list[str] = field(default_factory=list)
    unchanged_views: list[str] = field(default_factory=list)


class _CopiedBlueprint(rrb.Blueprint):
    """A blueprint made of existing blueprint chunks plus overrides logged after them (at
    ``blueprint`` time 1, so they win over the copied rows at time 0)."""

    def __init__(self, chunks: list[rr.chunk.Chunk], overrides: list[tuple[str, Any]]):
        super().__init__()
        self._chunks = chunks
        self._overrides = overrides

    def _log_to_stream(self, stream: rr.RecordingStream) -> None:  # the hook Blueprint.save calls
        stream.send_chunks(self._chunks)
        stream.set_time("blueprint", sequence=1)
        for entity, archetype in self._overrides:
            stream.log(entity, archetype)


def _time_panel_fields(window_s: tuple[float, float], play: bool) -> dict[str, Any]:
    """Time panel of a moment: expanded on ``time``, the window [s] selected and looped, paused
    (or playing at 0.25×)."""
    kw: dict[str, Any] = {"play_state": "playing", "playback_speed": 0.25} if play else {"play_state": "paused"}
    return {
        "state": "expanded",
        "timeline": layout.TIME,
        "time_selection": AbsoluteTimeRange(_ns(window_s[0]), _ns(window_s[1])),
        "loop_mode": "selection",
        **kw,
    }


def _under(path: str, root: str) -> bool:
    return path == root or path.startswith(root.rstrip("/") + "/")


def vehicle_eye(data: RecordingData, follow: str, t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
    """A camera on the entity ``follow`` at ``t_s`` [s]: ``(eye position, look target)`` [m, in the
    frame of ``follow``'s parent]. The target is its ``Transform3D`` translation at the last row at
    or before ``t_s``; the eye sits 2 sizes away (size: the largest bounding-box diagonal of the
    static meshes below it, 2 m without any) back along the track it came in on (from its position
    where it was one size away), turned 30° sideways and raised, so that it looks at the vehicle
    from its free side; None if ``follow`` has no translations."""
    try:
        t, tr = data.translations(follow)
    except KeyError:
        return None
    if not len(t):
        return None
    k = int(np.clip(np.searchsorted(t, t_s, side="right") - 1, 0, len(t) - 1))
    target = tr[k]
    size = 0.0
    for e in data.entities():
        if _under(e, follow) and e != follow:
            for when, v, _f, _c in data.meshes(e):
                if when is None and len(v):
                    size = max(size, float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))))
    size = size or 2.0
    back = tr[: k + 1] - target
    far = np.flatnonzero(np.linalg.norm(back, axis=1) >= size)
    d = back[far[-1]] if far.size else np.array([1.0, -1.0, 1.0])
    d = d / np.linalg.norm(d)
    side = np.cross([0.0, 0.0, 1.0], d)
    if np.linalg.norm(side) < 1e-6:  # came straight down: look from the side
        side = np.array([1.0, 0.0, 0.0])
    d = d + 0.6 * side / np.linalg.norm(side) + np.array([0.0, 0.0, 0.3])
    return target + 2.0 * size * d / np.linalg.norm(d), target


def write_moment_blueprint(
    data: RecordingData,
    moment: KeyMoment,
    path: str | os.PathLike[str],
    *,
    follow: str | None = layout.VEHICLE,
    play: bool = False,
) -> MomentLayout:
    """Write the ``.rbl`` that opens ``data``'s recording at ``moment`` (see the module docstring).

    ``follow``: entity the 3D views without a camera of their own track (None: leave the cameras;
    ignored when the recording has no ``Transform3D`` on it); ``play``: loop the time selection
    at 0.25× speed instead of pausing. The file is saved under the recording's application id.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        span = data.time_range(layout.TIME)
    except KeyError:
        span = None
    window = moment.window_or_default(span)
    tp = TimePanelBlueprint(**_time_panel_fields(window, play))
    chunks = embedded_blueprint_chunks(data.path)
    if follow is not None and not data.has_temporal(follow, "Transform3D:translation"):
        follow = None
    if not chunks:  # no layout of its own: the Viewer's automatic layout with the time panel set
        rrb.Blueprint(rrb.TimePanel(**_time_panel_fields(window, play)), auto_layout=True, auto_views=True).save(
            data.application_id, str(p)
        )
        return MomentLayout(p, moment, window, False, None)
    keep = [c for c in chunks if c.entity_path != _TIME_PANEL]
    cells = {c.entity_path: _cells(c) for c in keep}
    views = {
        e: (_first(d.get("ViewBlueprint:display_name")) or e, _first(d.get("ViewBlueprint:space_origin")) or "/")
        for e, d in cells.items()
        if e.startswith("/view/") and _first(d.get("ViewBlueprint:class_identifier")) == "3D"
    }
    overrides: list[tuple[str, Any]] = [(_TIME_PANEL, tp)]
    following, unchanged = [], []
    at_vehicle = follow is not None and any(_under(origin, follow) for _, origin in views.values())
    eye_kw: dict | None = None  # the camera on the vehicle at the moment: the same for every view
    for e, (name, _origin) in views.items():
        has_eye = f"{e}/EyeControls3D" in cells
        if follow is None or at_vehicle or has_eye:
            unchanged.append(name)
            continue
        if eye_kw is None:
            eye = vehicle_eye(data, follow, moment.t_s)
            eye_kw = {} if eye is None else {"position": eye[0], "look_target": eye[1], "eye_up": [0.0, 0.0, 1.0]}
        overrides.append((f"{e}/EyeControls3D", EyeControls3D(tracking_entity=follow, **eye_kw)))
        following.append(name)
        # make the following view the active tab of the tab strip holding it
        for ce, d in cells.items():
            if (
                ce.startswith("/container/")
                and e.lstrip("/") in (d.get("ContainerBlueprint:contents") or [])
                and d.get("ContainerBlueprint:active_tab") is not None
            ):
                overrides.append((ce, ContainerBlueprint.from_fields(active_tab=e.lstrip("/"))))
                break
    _CopiedBlueprint(keep, overrides).save(data.application_id, str(p))
    return MomentLayout(p, moment, window, True, follow if following else None, following, unchanged)


# ------------------------------------------------------------------------------- the running Viewer
def seek_viewer(
    url: str,
    t_s: float,
    *,
    rbl: str | os.PathLike[str] | None = None,
    timeout_s: float = 60.0,
    play: bool = False,
) -> bool:
    """Move the time cursor of the Viewer at ``url`` (``rerun+http://host:port/proxy``) to ``t_s``
    [s] on the ``time`` timeline once it shows a recording with that timeline, paused (or playing,
    ``play``); with ``rbl``, open that layout again first, so that it is the last one activated
    whatever the recording itself activates. Uses ``rerun.experimental.ViewerClient`` (Rerun 0.41,
    experimental; the native Viewer only — the web Viewer's server answers ``Unimplemented``).
    Returns False if no Viewer answered with the recording within ``timeout_s`` [s]."""
    import time

    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + timeout_s
    client = None
    while time.monotonic() < deadline:
        try:
            client = client or ViewerClient.connect(url)
            state = client.get_state()
            rec = next(
                (
                    r
                    for r in state.recordings
                    if any(tl.name == layout.TIME and tl.end is not None for tl in r.timelines)
                ),
                None,
            )
            if rec is not None and not state.loading:
                if rbl is not None:
                    client.open(str(Path(rbl).resolve()), navigate=False)
                client.set_time(
                    layout.TIME,
                    duration=np.timedelta64(_ns(t_s), "ns"),
                    play_state="playing" if play else "paused",
                    recording=rec.store_id,
                )
                return True
        except Exception:  # noqa: BLE001 - the Viewer is still starting (connection refused, timeouts)
            client = None
        time.sleep(1.0)
    return False


@dataclass(frozen=True)
class ViewerCommand:
    """How to start the Viewer on a recording: the ``argv`` and, for the native Viewer started
    with a known port, the ``control_url`` (``rerun+http://127.0.0.1:<port>/proxy``) through which
    :func:`seek_viewer` moves its time cursor (None for the web Viewer: its proxy does not relay
    the control API)."""

    argv: list[str]
    control_url: str | None


def viewer_command(
    rerun: str,
    rrd: str | os.PathLike[str],
    rbl: str | os.PathLike[str] | None = None,
    *,
    web: bool = False,
    port: int | None = None,
) -> ViewerCommand:
    """The ``rerun`` command line opening ``rrd`` (with the layout ``rbl``): the native Viewer,
    listening for control on ``port`` when given, or with ``web`` the web Viewer served locally."""
    argv = [rerun, str(rrd)] + ([str(rbl)] if rbl is not None else [])
    if web:
        return ViewerCommand(argv + ["--web-viewer"], None)
    if port is None:
        return ViewerCommand(argv, None)
    return ViewerCommand(argv + ["--port", str(port)], f"rerun+http://127.0.0.1:{port}/proxy")
