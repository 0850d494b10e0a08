"""Look at recordings the way a reviewer does: in Rerun's web viewer, inside headless Chromium.

:class:`WebViewer` serves Rerun's web viewer with the ``rerun`` command line of the environment
(``rerun --serve-web``, bound to 127.0.0.1 on free ports), opens each recording in a headless
Chromium driven by ``playwright`` (the system's browser, nothing is downloaded), waits until the
viewer has loaded it and painted a settled frame, and returns a :class:`ViewerCheck`: the PNG of the
window, the viewer's errors and warnings, and whether the 3D view shows anything.

How a recording is shown (one browser for all of them; one page per recording):

1. the page ``http://127.0.0.1:<web>/?url=<rrd>[&url=<rbl>]&renderer=webgl`` loads the viewer, which
   fetches the recording (and the blueprint) over HTTP from the same origin (playwright answers
   those requests from the local files; every request to another host is blocked, so the viewer's
   update check, fonts and telemetry neither leak nor wait for a network);
2. the viewer's own state (``WebHandle.viewer_state()``, the ``GetViewerStateResponse`` of Rerun's
   viewer-control API, protobuf) is polled until the recording is open and nothing is loading;
3. the time cursor is put where asked (``"end"`` of the ``time`` timeline by default) and playback
   paused (viewer-control ``SetTimeCursor``), the left panel hidden;
4. screenshots are taken about once a second until two in a row are the same (software rendering
   takes a while to draw a frame); the last one is saved: the recording's own layout;
5. each 3D view of the layout is then maximised in turn (viewer-control ``GetBlueprint`` /
   ``SetBlueprint`` with the viewport's ``maximized`` view), its settled frame saved beside the first
   and judged (below);
6. problems are collected: uncaught page errors, console errors, the viewer's log entries of level
   ``ERROR`` (viewer-control ``GetViewerLogs``), ``error`` reports of any view, a crash of the viewer
   (``has_panicked``), a load that never finishes. ``WARN`` entries and view warnings are kept as
   warnings. Console errors caused by the blocked requests to other hosts are not problems.

The empty-3D-view judgement is :func:`judge_scene` (content pixels against the region's most common
colour, in :data:`SCENE_REGION`).

Needs ``playwright`` (``[browser]`` extra), a Chromium (or ``WORKBENCH_CHROMIUM``) and the ``rerun``
command line; :func:`unavailable_reason` says what is missing. The viewer renders
with the software rasterizer (SwiftShader). The protobuf field numbers are Rerun 0.41's
``viewer_control.proto`` (an experimental API); the viewer's reported version is checked against them.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import time
import urllib.request
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote, urlsplit

import numpy as np

from workbench.recording import layout
from workbench.recording.reader import read_recording, rerun_executable

__all__ = [
    "DIFF_THRESHOLD",
    "MIN_CONTENT_FRACTION",
    "SCENE_REGION",
    "VIEWER_VERSION",
    "SceneJudgement",
    "ViewerCheck",
    "ViewerState",
    "ViewerUnavailable",
    "WebViewer",
    "decode_message",
    "encode_field",
    "find_chromium",
    "free_port",
    "judge_scene",
    "parse_viewer_logs",
    "parse_viewer_state",
    "server_command",
    "unavailable_reason",
    "check_recordings",
    "viewer_url",
    "write_empty_scene_recording",
]

VIEWER_VERSION = "0.41."
"""Version prefix of the viewer whose viewer-control field numbers this module uses."""

SCENE_REGION = (0.02, 0.10, 0.98, 0.70)
"""Part of the window judged for an empty 3D view, as fractions ``(left, top, right, bottom)`` of its
width and height: inside a maximised view (under the top bar and the view's tab strip, above the
expanded time panel) with the left and right panels hidden."""

DIFF_THRESHOLD = 48
"""A pixel is content when a channel differs from the region's background by more than this (0-255)."""

MIN_CONTENT_FRACTION = 0.001
"""Below this share of content pixels in :data:`SCENE_REGION` the 3D view counts as empty."""

_CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
_CHROMIUM_ARGS = (
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--ignore-gpu-blocklist",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)
_DATA_PREFIX = "/__workbench_data/"


class ViewerUnavailable(RuntimeError):
    """The web viewer cannot be driven here; the message says what is missing."""


# ---------------------------------------------------------------------------------------------------
# What is needed, and where it is


def find_chromium() -> str | None:
    """Path of a Chromium executable: ``$WORKBENCH_CHROMIUM`` if set, else the first of chromium,
    chromium-browser, google-chrome on ``PATH``; None if there is none."""
    env = os.environ.get("WORKBENCH_CHROMIUM")
    if env:
        return env if Path(env).is_file() else None
    for name in _CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def unavailable_reason() -> str | None:
    """Why the web viewer cannot be driven on this machine (what to install), or None if it can."""
    missing = []
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("the Python package 'playwright' (pip install 'edl-workbench[browser]')")
    if find_chromium() is None:
        missing.append("a Chromium browser (Debian: apt-get install chromium; or set WORKBENCH_CHROMIUM)")
    if rerun_executable() is None:
        missing.append("the 'rerun' command line (installed with rerun-sdk)")
    return "missing " + " and ".join(missing) if missing else None


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free on ``host`` (the system picks it; 127.0.0.1 only by default)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def server_command(rerun: str, web_port: int, grpc_port: int, host: str = "127.0.0.1") -> list[str]:
    """The command line that serves the web viewer on ``host:web_port`` (and the gRPC proxy it
    starts anyway on ``host:grpc_port``), without opening a browser."""
    return [
        rerun,
        "--serve-web",
        "--bind",
        host,
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
    ]


def viewer_url(base: str, data_urls: Sequence[str], renderer: str = "webgl") -> str:
    """The viewer page at ``base`` (``http://host:port``) opening ``data_urls`` (recordings, blueprints)."""
    query = "&".join(f"url={quote(u, safe='')}" for u in data_urls)
    return f"{base.rstrip('/')}/?{query}&renderer={renderer}"


# ---------------------------------------------------------------------------------------------------
# Protobuf wire format: just enough of it for three viewer-control messages


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if i >= len(buf):
            raise ValueError("truncated varint")
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return value, i


def decode_message(buf: bytes) -> dict[int, list[int | bytes]]:
    """Decode one protobuf message into ``{field number: [values]}`` without a schema: varints as
    (unsigned) ints, length-delimited fields as bytes (strings and nested messages alike), fixed
    32/64-bit fields as their raw bytes. ``ValueError`` on malformed input."""
    out: dict[int, list[int | bytes]] = {}
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        num, wire = key >> 3, key & 7
        value: int | bytes
        if wire == 0:
            value, i = _varint(buf, i)
        elif wire == 2:
            n, i = _varint(buf, i)
            if i + n > len(buf):
                raise ValueError("truncated length-delimited field")
            value, i = bytes(buf[i : i + n]), i + n
        elif wire in (1, 5):
            n = 8 if wire == 1 else 4
            value, i = bytes(buf[i : i + n]), i + n
        else:
            raise ValueError(f"unsupported wire type {wire}")
        out.setdefault(num, []).append(value)
    return out


def _enc_varint(n: int) -> bytes:
    n &= (1 << 64) - 1  # negative int64 as two's complement
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def encode_field(num: int, value: bool | int | str | bytes) -> bytes:
    """One protobuf field: bool/int as a varint (negative ints as int64), str/bytes (or an encoded
    nested message) length-delimited."""
    if isinstance(value, bool | int):
        return _enc_varint(num << 3) + _enc_varint(int(value))
    data = value.encode() if isinstance(value, str) else bytes(value)
    return _enc_varint(num << 3 | 2) + _enc_varint(len(data)) + data


def _int64(v: int) -> int:
    return v - (1 << 64) if v >= 1 << 63 else v


def _str(msg: dict, num: int, default: str = "") -> str:
    vals = msg.get(num)
    return vals[0].decode("utf-8", "replace") if vals else default


def _sub(msg: dict, num: int) -> dict:
    vals = msg.get(num)
    return decode_message(vals[0]) if vals else {}


@dataclass(frozen=True)
class ViewerState:
    """What the viewer shows (from its ``GetViewerStateResponse``).

    ``timelines`` maps each timeline of the active recording to its ``(start, end)`` in the
    timeline's unit (nanoseconds for ``time``; ticks for sequences), ``cursor`` the current time on
    ``cursor_timeline``; ``views`` are ``(view id, class, name, origin)``; ``reports`` are
    ``(severity, "view name: summary")``; ``loading`` the status lines of sources still loading.
    """

    version: str
    active: str | None
    recordings: tuple[str, ...]
    timelines: dict[str, tuple[int, int]]
    cursor_timeline: str | None
    cursor: int | None
    views: tuple[tuple[str, str, str, str], ...]
    reports: tuple[tuple[str, str], ...]
    loading: tuple[str, ...]


def parse_viewer_state(buf: bytes) -> ViewerState:
    """Read the fields this module needs from an encoded ``GetViewerStateResponse`` (Rerun 0.41:
    1 url, 2 active store id, 3 recordings {1 store id, 2 timelines {1 {1 name}, 3 range {1 start,
    2 end}}, 3 cursor {1 {1 name}, 3 {1 time}}}, 5 views {2 class, 3 name, 4 origin, 6 reports
    {1 severity, 2 summary, 3 details}}, 6 version, 7 loading {1 name, 2 status})."""
    msg = decode_message(buf)
    active = _str(msg, 2) or None
    recordings, timelines = [], {}
    cursor_timeline = cursor = None
    for raw in msg.get(3, []):
        rec = decode_message(raw)  # type: ignore[arg-type]
        store_id = _str(rec, 1)
        recordings.append(store_id)
        if active is not None and store_id != active:
            continue
        for tl_raw in rec.get(2, []):
            tl = decode_message(tl_raw)  # type: ignore[arg-type]
            rng = _sub(tl, 3)
            if not rng and 3 not in tl:
                continue  # no data on it yet
            start = _int64(int(rng.get(1, [0])[0]))
            end = _int64(int(rng.get(2, [0])[0]))
            timelines[_str(_sub(tl, 1), 1)] = (start, end)
        cur = _sub(rec, 3)
        if cur:
            cursor_timeline = _str(_sub(cur, 1), 1) or None
            t = _sub(cur, 3)
            cursor = _int64(int(t.get(1, [0])[0])) if 3 in cur else None
    views, reports = [], []
    for raw in msg.get(5, []):
        v = decode_message(raw)  # type: ignore[arg-type]
        views.append((_str(v, 1), _str(v, 2), _str(v, 3), _str(v, 4)))
        for rep_raw in v.get(6, []):
            rep = decode_message(rep_raw)  # type: ignore[arg-type]
            text = f"view {_str(v, 3)!r}: {_str(rep, 2)}"
            if rep.get(3):
                text += f" ({_str(rep, 3)})"
            reports.append((_str(rep, 1), text))
    loading = tuple(_str(decode_message(raw), 2) or _str(decode_message(raw), 1) for raw in msg.get(7, []))  # type: ignore[arg-type]
    return ViewerState(
        version=_str(msg, 6),
        active=active,
        recordings=tuple(recordings),
        timelines=timelines,
        cursor_timeline=cursor_timeline,
        cursor=cursor,
        views=tuple(views),
        reports=tuple(reports),
        loading=loading,
    )


def parse_viewer_logs(buf: bytes) -> list[tuple[int, str, str]]:
    """``(sequence, level, "target: message")`` of an encoded ``ViewerControlResponse`` holding a
    ``GetViewerLogsResponse`` (field 2: entries 1 {1 sequence, 2 level, 3 target, 4 message})."""
    resp = _sub(decode_message(buf), 2)
    out = []
    for raw in resp.get(1, []):
        e = decode_message(raw)  # type: ignore[arg-type]
        out.append((int(e.get(1, [0])[0]), _str(e, 2), f"{_str(e, 3)}: {_str(e, 4)}"))
    return out


# ---------------------------------------------------------------------------------------------------
# The empty-3D-view judgement


@dataclass(frozen=True)
class SceneJudgement:
    """Pixels of the 3D view's region: share of content pixels, the background colour (RGB), the
    region in pixels ``(x0, y0, x1, y1)``, and the verdict ``empty``."""

    content_fraction: float
    background: tuple[int, int, int]
    region_px: tuple[int, int, int, int]
    empty: bool


def judge_scene(
    image: np.ndarray,
    region: tuple[float, float, float, float] = SCENE_REGION,
    diff_threshold: int = DIFF_THRESHOLD,
    min_fraction: float = MIN_CONTENT_FRACTION,
) -> SceneJudgement:
    """Whether the 3D view in a screenshot shows anything.

    ``image`` is ``(H, W, 3)`` or ``(H, W, 4)`` uint8 (RGB[A]); ``region`` the judged part as
    fractions ``(left, top, right, bottom)`` of ``W`` and ``H``. The background is the region's most
    common colour; content is every pixel with a channel more than ``diff_threshold`` away from it;
    the view is empty when content covers less than ``min_fraction`` of the region.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"expected an (H, W, 3|4) image, got shape {img.shape}")
    h, w = img.shape[:2]
    left, top, right, bottom = region
    x0, x1 = int(round(left * w)), int(round(right * w))
    y0, y1 = int(round(top * h)), int(round(bottom * h))
    if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
        raise ValueError(f"region {region} is empty or outside a {w}x{h} image")
    crop = img[y0:y1, x0:x1, :3].astype(np.int32)
    packed = (crop[..., 0] << 16) | (crop[..., 1] << 8) | crop[..., 2]
    values, counts = np.unique(packed.ravel(), return_counts=True)
    bg_packed = int(values[np.argmax(counts)])
    bg = np.array([(bg_packed >> 16) & 255, (bg_packed >> 8) & 255, bg_packed & 255])
    content = np.abs(crop - bg).max(axis=2) > diff_threshold
    frac = float(content.mean())
    return SceneJudgement(
        content_fraction=frac,
        background=(int(bg[0]), int(bg[1]), int(bg[2])),
        region_px=(x0, y0, x1, y1),
        empty=frac < min_fraction,
    )


# ---------------------------------------------------------------------------------------------------
# Driving the viewer


def has_3d_content(path: str | os.PathLike[str]) -> bool:
    """Whether the recording at ``path`` logs any 3D archetype (``Transform3D``, ``Mesh3D``,
    ``Points3D``, ``LineStrips3D``, ...).  True when it cannot be read (the check then asks for
    a 3D view, as before)."""
    try:
        rec = read_recording(path)
        return any(c.split(":")[0].endswith("3D") for e in rec.entities() for c in rec.components(e))
    except Exception:  # an unreadable recording is judged by the viewer, not here
        return True


@dataclass
class ViewerCheck:
    """What the viewer showed for one recording.

    ``png`` the saved screenshot of the layout; ``load_s`` seconds from opening the page until the recording was
    loaded, ``settle_s`` from then until the frame settled; ``errors`` problems (any one fails the
    check), ``warnings`` the rest worth reading; ``views`` ``(view id, class, name, origin)`` of the
    blueprint; ``scenes`` the empty-view judgement of each 3D view, by view name, and ``scene_pngs``
    the screenshots of them maximised; ``time_s`` where the time cursor was put on the ``time``
    timeline [s]; ``needs_3d`` whether the recording logs any 3D archetype (:func:`has_3d_content`):
    a recording of plots and tables only (a Monte Carlo summary) needs no 3D view.
    """

    recording: Path
    png: Path | None = None
    load_s: float = float("nan")
    settle_s: float = float("nan")
    time_s: float | None = None
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    views: tuple[tuple[str, str, str, str], ...] = ()
    scenes: dict[str, SceneJudgement] = field(default_factory=dict)
    scene_pngs: list[Path] = field(default_factory=list)
    needs_3d: bool = True

    @property
    def ok(self) -> bool:
        """No errors, at least one 3D view when the recording has 3D content, and none of them empty."""
        return (
            not self.errors
            and (bool(self.scenes) or not self.needs_3d)
            and not any(j.empty for j in self.scenes.values())
        )

    def summary(self) -> str:
        """One line: verdict, timings, content share of each 3D view, first error."""
        verdict = "OK" if self.ok else "FAIL"
        scene = ", ".join(
            f"3D view {name!r} {'EMPTY' if j.empty else 'drawn'} ({j.content_fraction:.1%} content)"
            for name, j in self.scenes.items()
        ) or ("no 3D view judged" if self.needs_3d else "plots only (no 3D content, no 3D view needed)")
        first = f"; {len(self.errors)} error(s), first: {self.errors[0]}" if self.errors else ""
        return (
            f"{verdict} {self.recording.name}: loaded in {self.load_s:.1f} s, settled in {self.settle_s:.1f} s, "
            f"{scene}, {len(self.warnings)} warning(s){first}"
        )


_JS_CONTROL = """async (req) => {
  try { return {ok: Array.from(await window._handle.viewer_control(new Uint8Array(req)))}; }
  catch (e) { return {err: String(e)}; }
}"""
_JS_STATE = "() => Array.from(window._handle.viewer_state())"
_JS_PANIC = "() => window._handle.has_panicked() ? String(window._handle.panic_message()) : null"
_NOISE = ("Failed to fetch", "ERR_NAME_NOT_RESOLVED", "ERR_FAILED", "ERR_INTERNET_DISCONNECTED")


def _png_array(png: bytes) -> np.ndarray:
    """RGB array of PNG bytes (OpenCV decodes BGR)."""
    import cv2

    arr = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if arr is None:
        raise ValueError("could not decode the screenshot")
    return arr[..., ::-1]


class WebViewer:
    """Rerun's web viewer in headless Chromium, for several recordings in one browser session.

    ::

        with WebViewer() as viewer:
            check = viewer.check("recordings/droptest.rrd", "shots/droptest.png")
            print(check.summary())

    ``size`` is the window in CSS pixels; ``load_timeout_s`` bounds opening one recording,
    ``settle_timeout_s`` the wait for a settled frame. Leaving the ``with`` block closes the browser
    and stops the server (its whole process group), also after an error or Ctrl-C.
    Raises :class:`ViewerUnavailable` (with what is missing) on entry when it cannot run.
    """

    def __init__(
        self,
        size: tuple[int, int] = (1400, 900),
        load_timeout_s: float = 240.0,
        settle_timeout_s: float = 60.0,
        host: str = "127.0.0.1",
    ) -> None:
        self.size = size
        self.load_timeout_s = load_timeout_s
        self.settle_timeout_s = settle_timeout_s
        self.host = host
        self._server: subprocess.Popen | None = None
        self._pw = None
        self._browser = None
        self._context = None
        self._files: dict[str, Path] = {}
        self._blocked: list[str] = []
        self.base = ""

    # -- lifetime -----------------------------------------------------------------------------------
    def __enter__(self) -> WebViewer:
        reason = unavailable_reason()
        if reason:
            raise ViewerUnavailable(reason)
        try:
            self._start_server()
            self._start_browser()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _start_server(self) -> None:
        rerun = rerun_executable()
        assert rerun is not None
        web, grpc = free_port(self.host), free_port(self.host)
        env = dict(os.environ, RERUN_ANALYTICS="off")
        self._server = subprocess.Popen(
            server_command(rerun, web, grpc, self.host),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,  # its own process group: stopped as a whole in close()
        )
        self.base = f"http://{self.host}:{web}"
        deadline = time.monotonic() + 30.0
        while True:
            if self._server.poll() is not None:
                raise ViewerUnavailable(f"'{rerun} --serve-web' exited with code {self._server.returncode}")
            try:
                with urllib.request.urlopen(self.base + "/", timeout=2):
                    return
            except OSError:
                if time.monotonic() > deadline:
                    raise ViewerUnavailable(f"the web viewer did not answer on {self.base} within 30 s") from None
                time.sleep(0.3)

    def _start_browser(self) -> None:
        from playwright.sync_api import sync_playwright

        self._pw = sync_playwright().start()
        self._browser = self._pw.chromium.launch(
            executable_path=find_chromium(), headless=True, args=list(_CHROMIUM_ARGS)
        )
        w, h = self.size
        self._context = self._browser.new_context(viewport={"width": w, "height": h})
        self._context.route(lambda url: True, self._route)

    def _route(self, route) -> None:
        url = route.request.url
        parts = urlsplit(url)
        if f"{parts.scheme}://{parts.netloc}" != self.base:
            self._blocked.append(url)
            route.abort()
        elif parts.path.startswith(_DATA_PREFIX) and parts.path in self._files:
            route.fulfill(path=str(self._files[parts.path]), headers={"content-type": "application/octet-stream"})
        else:
            route.continue_()

    def close(self) -> None:
        """Close the browser and stop the server (SIGTERM to its process group, SIGKILL after 10 s)."""
        for step in (
            lambda: self._context and self._context.close(),
            lambda: self._browser and self._browser.close(),
            lambda: self._pw and self._pw.stop(),
        ):
            with contextlib.suppress(Exception):
                step()
        self._context = self._browser = self._pw = None
        if self._server is not None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self._server.pid, signal.SIGTERM)
            try:
                self._server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self._server.pid, signal.SIGKILL)
                self._server.wait(timeout=10)
            self._server = None

    # -- one recording ------------------------------------------------------------------------------
    def _serve(self, path: Path) -> str:
        key = f"{_DATA_PREFIX}{len(self._files)}/{quote(path.name)}"
        self._files[key] = path
        return self.base + key

    def check(
        self,
        recording: str | os.PathLike[str],
        png: str | os.PathLike[str],
        blueprint: str | os.PathLike[str] | None = None,
        at: str | float = "end",
        region: tuple[float, float, float, float] = SCENE_REGION,
        judge_views: bool = True,
    ) -> ViewerCheck:
        """Open ``recording`` (with the ``.rbl`` ``blueprint`` if given) in a new page, wait for it to
        load and settle, save the window as ``png`` and judge it (module docstring).

        ``at``: where to put the time cursor on the ``time`` timeline and pause: ``"end"``,
        ``"start"``, ``"keep"`` (where the viewer / blueprint put it, paused) or seconds (float).
        With ``judge_views`` each 3D view is then maximised, saved as ``<png stem>.3d<k>.png`` and
        judged in ``region``. Never raises for what the viewer does; problems are in the returned
        check's ``errors``.
        """
        if self._context is None:
            raise RuntimeError("WebViewer.check outside its with-block")
        rec_path = Path(recording).resolve()
        result = ViewerCheck(recording=rec_path)
        if not rec_path.is_file():
            result.errors.append(f"no such recording: {rec_path}")
            return result
        result.needs_3d = has_3d_content(rec_path)
        urls = [self._serve(rec_path)]
        if blueprint is not None:
            bp = Path(blueprint).resolve()
            if not bp.is_file():
                result.errors.append(f"no such blueprint: {bp}")
                return result
            urls.append(self._serve(bp))
        page = self._context.new_page()
        blocked_before = len(self._blocked)
        console: list[tuple[str, str, str]] = []
        page.on("console", lambda m: console.append((m.type, m.text, (m.location or {}).get("url", ""))))
        page.on("pageerror", lambda e: result.errors.append(f"page error: {str(e)[:500]}"))
        out = Path(png)
        try:
            shot = self._show(page, urls, at, result)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(shot)
            result.png = out
            if judge_views:
                self._judge_views(page, result, out, region)
        except Exception as err:  # a timeout or a browser failure is a failed check, not a crash
            result.errors.append(f"{type(err).__name__}: {str(err).splitlines()[0][:300]}")
            if result.png is None:
                with contextlib.suppress(Exception):
                    out.parent.mkdir(parents=True, exist_ok=True)
                    out.write_bytes(page.screenshot())
                    result.png = out
        finally:
            with contextlib.suppress(Exception):
                panic = page.evaluate(_JS_PANIC)
                if panic:
                    result.errors.append(f"the viewer crashed: {panic[:500]}")
            with contextlib.suppress(Exception):
                for _, level, text in self._logs(page):
                    if level == "ERROR":
                        result.errors.append(f"viewer log: {text[:500]}")
                    elif level == "WARN":
                        result.warnings.append(f"viewer log: {text[:300]}")
            external = len(self._blocked) > blocked_before
            for kind, text, where in console:
                if kind != "error":
                    continue
                if external and (any(n in text for n in _NOISE)) and not where.startswith(self.base + _DATA_PREFIX):
                    continue  # a blocked request to another host (update check, fonts, telemetry)
                msg = f"console: {text.strip()[:500]}"
                if msg not in result.errors:
                    result.errors.append(msg)
            with contextlib.suppress(Exception):
                page.close()
        return result

    def _state(self, page) -> ViewerState:
        return parse_viewer_state(bytes(page.evaluate(_JS_STATE)))

    def _control(self, page, request: bytes) -> bytes:
        r = page.evaluate(_JS_CONTROL, list(request))
        if "err" in r:
            raise RuntimeError(f"viewer control refused: {r['err']}")
        return bytes(r["ok"])

    def _logs(self, page) -> list[tuple[int, str, str]]:
        return parse_viewer_logs(self._control(page, encode_field(2, b"")))

    def _settle(self, page, result: ViewerCheck, what: str) -> bytes:
        """Screenshots about once a second until two in a row agree (all but 0.01 % of the pixels);
        returns the last one (PNG bytes), with a warning if it never settled."""
        t1 = time.monotonic()
        previous = None
        while True:
            time.sleep(1.0)
            shot = page.screenshot()
            arr = _png_array(shot)
            if previous is not None and previous.shape == arr.shape and np.mean(previous != arr) < 1e-4:
                return shot
            previous = arr
            if time.monotonic() - t1 > self.settle_timeout_s:
                result.warnings.append(f"{what}: the picture was still changing after {self.settle_timeout_s:.0f} s")
                return shot

    def _judge_views(self, page, result: ViewerCheck, png: Path, region: tuple[float, float, float, float]) -> None:
        """Maximise each 3D view in turn (the viewport's ``maximized`` view, set through the blueprint
        JSON of viewer-control ``GetBlueprint``/``SetBlueprint``), save and judge its settled frame."""
        views3d = [(vid, name) for vid, cls, name, _ in result.views if cls == "3D"]
        if not views3d:
            return
        # GetBlueprintRequest {2 recording target {}} -> GetBlueprintResponse {2 json}
        got = _sub(decode_message(self._control(page, encode_field(12, encode_field(2, b"")))), 12)
        blueprint = json.loads(_str(got, 2) or "{}")
        viewport = dict(blueprint.get("/viewport", {}).get("ViewportBlueprint", {}))
        with contextlib.suppress(Exception):
            page.evaluate("() => window._handle.override_panel_state('selection', 'hidden')")
        for k, (vid, name) in enumerate(views3d):
            viewport["maximized"] = vid
            # SetBlueprintRequest {2 json, 3 recording target {}, 5 mode (2 = partial: only what is given)}
            update = json.dumps({"/viewport": {"ViewportBlueprint": viewport}})
            request = encode_field(2, update) + encode_field(3, b"") + encode_field(5, 2)
            self._control(page, encode_field(14, request))
            shot = self._settle(page, result, f"3D view {name!r}")
            path = png.with_name(f"{png.stem}.3d{k}{png.suffix}")
            path.write_bytes(shot)
            result.scene_pngs.append(path)
            result.scenes[name if name not in result.scenes else f"{name} ({k})"] = judge_scene(
                _png_array(shot), region
            )

    def _show(self, page, urls: list[str], at: str | float, result: ViewerCheck) -> bytes:
        """Load ``urls[0]`` (the recording), then each further URL (a layout) once it has loaded —
        the last layout activated wins, and a recording activates its own at its end — then seek
        (``at``) and settle; returns the screenshot (PNG bytes)."""
        t0 = time.monotonic()
        page.goto(viewer_url(self.base, urls[:1]), wait_until="load", timeout=self.load_timeout_s * 1000)
        page.wait_for_function("() => window._handle !== undefined", timeout=self.load_timeout_s * 1000)
        deadline = t0 + self.load_timeout_s
        pending = list(urls[1:])
        while True:
            st = self._state(page)
            if st.recordings and not st.loading and st.timelines:
                if not pending:
                    break
                page.evaluate("(u) => window._handle.add_receiver(u)", pending.pop(0))
                time.sleep(1.0)
                continue
            if page.evaluate(_JS_PANIC):
                return page.screenshot()
            if time.monotonic() > deadline:
                status = "; ".join(st.loading) or ("no recording opened" if not st.recordings else "no timeline")
                raise TimeoutError(f"not loaded after {self.load_timeout_s:.0f} s ({status})")
            time.sleep(1.0)
        result.load_s = time.monotonic() - t0
        if not st.version.startswith(VIEWER_VERSION):
            result.warnings.append(f"viewer {st.version}: viewer-control fields are those of {VIEWER_VERSION}x")
        result.views = st.views
        if result.needs_3d and not any(cls == "3D" for _, cls, _, _ in st.views):
            result.errors.append("the blueprint has no 3D view")
        with contextlib.suppress(Exception):
            page.evaluate("() => window._handle.override_panel_state('blueprint', 'hidden')")
        result.time_s = self._seek(page, st, at)
        t1 = time.monotonic()
        shot = self._settle(page, result, "layout")
        result.settle_s = time.monotonic() - t1
        st = self._state(page)
        for severity, text in st.reports:
            (result.errors if severity == "error" else result.warnings).append(text)
        return shot

    def _seek(self, page, st: ViewerState, at: str | float) -> float | None:
        """Put the cursor on the ``time`` timeline (``at``, see :meth:`check`) and pause; returns the
        time [s] or None when the recording has no ``time`` timeline or ``at`` is ``"keep"`` and the
        layout opened another timeline (a Monte Carlo's ``sample``: switching would empty its plots)."""
        tl = layout.TIME
        if tl not in st.timelines or (at == "keep" and st.cursor_timeline not in (None, tl)):
            return None
        start, end = st.timelines[tl]
        if at == "end":
            t_ns = end
        elif at == "start":
            t_ns = start
        elif at == "keep":
            t_ns = st.cursor if st.cursor is not None and st.cursor_timeline == tl else end
        else:
            t_ns = int(round(float(at) * 1e9))
        # SetTimeCursorRequest: 2 timeline {1 name}, 3 time {1 ns}, 5 play_state (1 = paused)
        request = encode_field(2, encode_field(1, tl)) + encode_field(3, encode_field(1, t_ns)) + encode_field(5, 1)
        self._control(page, encode_field(6, request))
        return t_ns / 1e9


def check_recordings(
    recordings: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    blueprint: str | os.PathLike[str] | None = None,
    at: str | float = "end",
    progress=None,
    **viewer_kwargs,
) -> Iterator[ViewerCheck]:
    """Check each recording in one :class:`WebViewer` session, writing ``<out_dir>/<stem>.png``;
    yields the checks in order (``progress(str)`` gets a line per recording when given)."""
    out = Path(out_dir)
    with WebViewer(**viewer_kwargs) as viewer:
        for rec in recordings:
            stem = Path(rec).stem + (f".{Path(blueprint).stem}" if blueprint else "")
            check = viewer.check(rec, out / f"{stem}.png", blueprint=blueprint, at=at)
            if progress:
                progress(check.summary())
            yield check


def write_empty_scene_recording(path: str | os.PathLike[str]) -> Path:
    """Write a small recording in the standard layout whose 3D view has nothing to show (a plot, a
    report and an event, nothing under ``/world``): the negative control of :func:`judge_scene` in a
    real viewer. Returns the path."""
    from workbench.recording.blueprint import standard_blueprint
    from workbench.recording.writer import open_recording

    t = np.linspace(0.0, 10.0, 101)
    bp = standard_blueprint(plots=[("signal [1]", layout.plot_path("signal"))])
    with open_recording(path, "empty_scene", blueprint=bp) as rec:
        rec.scalars(layout.plot_path("signal"), t, np.sin(t), names="signal [1]")
        rec.events([(0.0, "start", "INFO")])
        rec.report("# empty scene\n\nNothing is drawn in the 3D view of this recording.")
    return Path(path)
