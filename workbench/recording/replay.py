"""Presentation video of a run, rendered from its recording: ``workbench replay REC.rrd --mp4 OUT.mp4``.

Rerun has no video export of a view, so the 3D scene is rendered here in software: the meshes,
poses, tracks, beams and the uncertainty ellipsoid are read back from the ``.rrd``
(:mod:`workbench.recording.reader`), projected with a pinhole camera in numpy and drawn with OpenCV
(flat-shaded triangles back to front, translucent meshes blended, lines clipped at the near
plane). What is drawn is what the recording holds — nothing is recomputed:

* the scene below ``/world`` without the truth meshes, the dispersion cloud, the forward-pass
  vehicle and the drop test's max-stroke ghost (:data:`HIDDEN`); the truth track is drawn thin;
* a camera that follows ``/world/vehicle``: it looks at the (smoothed) vehicle position from the
  side of the overall track, at a distance of a few vehicle sizes (problem's :class:`Presentation`);
* the 3σ position ellipsoid ``/world/vehicle/uncertainty`` as its three principal ellipses;
* a HUD of key numbers (time, and per problem e.g. stroke ± 1σ, altitude ± 1σ, speed), read from
  the bounded series under ``/plots``;
* the ``/events`` log (INFO and WARN entries) as captions, and the playback slowed around them;
* a time bar with the events and an inset of the whole track (side view) with the vehicle on it;
* a title bar: the run's name and scenario description, then the kind, seed, recording date and
  what is drawn (:func:`replay_titles`); text in DejaVu Sans (matplotlib's bundled font, through
  Pillow: σ, ±, °, Δ), captions kept left of the inset.

Frames are 1280×720 by default, 1920×1080 with ``size`` (``workbench replay --size``; the overlay
scales with the width) (``mp4v`` in an ``.mp4`` container through OpenCV's bundled FFmpeg). Frame
times follow a time warp: a base rate (recording seconds per video second) chosen so the video
lasts ``duration_s``, slowed by ``slow`` within ``± window`` of every event.
"""

from __future__ import annotations

import datetime as dt
import functools
import math
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from workbench.core.rotation import quat_to_dcm
from workbench.recording import layout
from workbench.recording.reader import RecordingData, read_recording

__all__ = [
    "HIDDEN",
    "PRESENTATIONS",
    "HudItem",
    "Presentation",
    "ReplayError",
    "ReplayStats",
    "Overlay",
    "draw_overlay",
    "draw_text",
    "replay_titles",
    "frame_times",
    "render_mp4",
]

#: scene subtrees not drawn in a replay (truth meshes, ghosts, the dispersion cloud, forward pass)
HIDDEN = (
    layout.TRUTH_VEHICLE,
    layout.DISPERSION,
    layout.DROPTEST_MAX_STROKE,
    layout.DROPTEST_MAX_STROKE_SEGMENT,
    layout.DROPTEST_MAX_STROKE_POINT,
    layout.DROPTEST_MAX_STROKE_DIMENSION,
    layout.DROPTEST_ROLL_LINE,
    layout.ENTRY_FORWARD_VEHICLE,
    layout.ESTIMATE_FORWARD,
    layout.ENTRY_NOMINAL_TRACK,
    layout.ENTRY_ONBOARD_TRACK,
)


class ReplayError(ValueError):
    """The recording cannot be replayed (no vehicle pose to follow, nothing in the time range)."""


@dataclass(frozen=True)
class HudItem:
    """One HUD line: ``label``, the bounded-series ``root`` below which the estimate (``value`` or
    ``smoothed``) and ``plus_<n>sigma`` live (or a plain ``Scalars`` entity), the component
    ``index`` (or ``"norm"`` for the norm of several series, e.g. speed from velocity components
    ``children``), ``scale`` from the recorded unit to the shown ``unit`` and the format ``fmt``."""

    label: str
    root: str
    unit: str
    scale: float = 1.0
    fmt: str = ".3f"
    children: tuple[str, ...] = ()


@dataclass(frozen=True)
class Presentation:
    """How one problem is presented: HUD lines, camera ``distance`` in vehicle sizes (the half
    diagonal of the world box around the meshes under ``/world/vehicle`` shown at the time),
    camera ``elevation_deg``, the default video length ``duration_s`` [s], the event ``slow``
    factor (< 1) and ``window_s`` [s of recording] around each event, the ``plots`` of the
    summary image [(title, root, y label, scale)] and ``zoom``: two key-moment names whose span the
    first plot is zoomed on (the drop test's stroke from first contact to rebound)."""

    hud: tuple[HudItem, ...] = ()
    distance: float = 4.0
    elevation_deg: float = 15.0
    duration_s: float = 12.0
    slow: float = 0.2
    window_s: float | None = None
    plots: tuple[tuple[str, str, str, float], ...] = ()
    zoom: tuple[str, str] | None = None


PRESENTATIONS: dict[str, Presentation] = {
    "droptest": Presentation(
        hud=(
            HudItem("stroke", layout.DROPTEST_PLOT_STROKE, "m", fmt=".3f"),
            HudItem("height z", layout.join(layout.DROPTEST_PLOT_POSITION, "z"), "m", fmt=".2f"),
            HudItem("speed", layout.DROPTEST_PLOT_VELOCITY, "m/s", fmt=".2f", children=("vx", "vy", "vz")),
            HudItem("|accel|", layout.DROPTEST_PLOT_ACCEL_BODY, "g", fmt=".1f", children=("ax_B", "ay_B", "az_B")),
        ),
        distance=4.0,
        elevation_deg=12.0,
        duration_s=10.0,
        slow=0.25,
        window_s=0.06,
        zoom=("first_contact", "rebound"),
        plots=(
            ("stroke ± 3σ, the impact", layout.DROPTEST_PLOT_STROKE, "stroke [m]", 1.0),
            ("position", layout.DROPTEST_PLOT_POSITION, "position SPF [m]", 1.0),
            ("velocity", layout.DROPTEST_PLOT_VELOCITY, "velocity SPF [m/s]", 1.0),
            ("body acceleration", layout.DROPTEST_PLOT_ACCEL_BODY, "non-grav. accel. body [g]", 1.0),
            ("body rate", layout.DROPTEST_PLOT_RATE, "rate [deg/s]", 1.0),
            ("1σ of the stroke", layout.DROPTEST_PLOT_STROKE_SIGMA, "stroke 1σ [m]", 1.0),
        ),
    ),
    "entry": Presentation(
        hud=(
            HudItem("altitude AGL", layout.ENTRY_PLOT_ALTITUDE_AGL, "m", fmt=".0f"),
            HudItem("altitude AMR", layout.ENTRY_PLOT_ALTITUDE_AMR, "km", fmt=".2f"),
            HudItem("speed", layout.ENTRY_PLOT_VELOCITY_NED, "m/s", fmt=".1f", children=()),
            HudItem("tilt", layout.ENTRY_PLOT_TILT, "deg", fmt=".1f"),
        ),
        distance=5.0,
        elevation_deg=10.0,
        duration_s=25.0,
        slow=0.2,
        window_s=3.0,
        plots=(
            ("altitude AMR ± 3σ", layout.ENTRY_PLOT_ALTITUDE_AMR, "altitude AMR [km]", 1.0),
            ("altitude above ground", layout.ENTRY_PLOT_ALTITUDE_AGL, "altitude AGL [m]", 1.0),
            ("ground-relative velocity", layout.ENTRY_PLOT_VELOCITY_NED, "velocity N, E, D [m/s]", 1.0),
            ("tilt", layout.ENTRY_PLOT_TILT, "tilt [deg]", 1.0),
            ("position 1σ", layout.ENTRY_PLOT_SIGMA_POSITION, "1σ / 3σ [m]", 1.0),
            ("density vs default", layout.ENTRY_PLOT_DENSITY_RATIO, "density / default [%]", 1.0),
        ),
    ),
}
_DEFAULT = Presentation()

W, H = 1280, 720
_FOV_DEG = 50.0
_BG_TOP = np.array([40, 28, 20], np.float32)  # BGR
_BG_BOTTOM = np.array([92, 80, 70], np.float32)
_ELLIPSE = (0, 165, 255)
_TRACK = (180, 119, 31)
_TRUTH = (200, 200, 200)
_TEXT = (240, 240, 240)
#: text height [px] per unit of ``scale`` in :func:`draw_text` (cv2's Hershey scale, kept for the layout)
_FONT_PX = 30.0
_SHADES = 24  # shade levels of the flat shading
_MAX_FACES = 10000  # larger meshes are simplified by vertex clustering for drawing
_MAX_LINE_POINTS = 600
_FILE_MESSAGE = re.compile(r"\.(csv|toml|npz|json)\b")  # static tracks are thinned to this many points


@dataclass(frozen=True)
class ReplayStats:
    """What :func:`render_mp4` wrote: ``path``, ``frames``, ``fps``, ``size`` (w, h), the
    recording's time span ``t0``..``t1`` [s], the wall ``render_s`` [s] and the CPU ``cpu_s`` [s]
    (this process) it took."""

    path: Path
    frames: int
    fps: float
    size: tuple[int, int]
    t0: float
    t1: float
    render_s: float
    cpu_s: float


# --------------------------------------------------------------------------------- scene model
@dataclass
class _Xform:
    """Pose of one entity in its parent: static (t None) or latest-at rows."""

    t: np.ndarray | None
    R: np.ndarray  # (n, 3, 3)
    p: np.ndarray  # (n, 3)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        if self.t is None:
            return self.R[0], self.p[0]
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        if i < 0:
            return None
        return self.R[i], self.p[i]


def _decimate(v: np.ndarray, f: np.ndarray, max_faces: int = _MAX_FACES) -> tuple[np.ndarray, np.ndarray]:
    """Vertex-clustering simplification of a mesh (vertices (n, 3), faces (m, 3)) to at most
    ``max_faces`` faces: vertices in one grid cell merge to their mean, degenerate and repeated
    faces are dropped; the cell grows until the mesh is small enough."""
    if len(f) <= max_faces or not len(v):
        return v, f
    lo, hi = v.min(axis=0), v.max(axis=0)
    cells = 48.0
    while True:
        cell = float(np.linalg.norm(hi - lo)) / cells
        key = np.floor((v - lo) / cell).astype(np.int64)
        _, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        nv = np.zeros((inv.max() + 1, 3))
        np.add.at(nv, inv, v)
        nv /= np.bincount(inv)[:, None]
        nf = inv[f]
        ok = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
        nf = nf[ok]
        _, first = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)
        nf = nf[np.sort(first)]
        if len(nf) <= max_faces or cells < 6:
            return nv, nf
        cells *= 0.75


@dataclass
class _Mesh:
    entity: str
    rows: list[tuple[float | None, np.ndarray, np.ndarray, int]]
    clears: np.ndarray

    def __post_init__(self) -> None:
        self.rows = [(t, *_decimate(v, f), c) for t, v, f, c in self.rows]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]] | None:
        best = None
        for tm, v, f, c in self.rows:
            if tm is None or tm <= t:
                if best is None or (tm is not None and (best[0] is None or tm >= best[0])):
                    best = (tm, v, f, c)
        if best is None:
            return None
        t_mesh = -np.inf if best[0] is None else best[0]
        if np.any((self.clears <= t) & (self.clears >= t_mesh)):
            return None
        c = best[3]
        return best[1], best[2], ((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255, c & 255)


def _hidden(entity: str) -> bool:
    return any(entity == h or entity.startswith(h + "/") for h in HIDDEN)


class _Scene:
    """Meshes, transforms, lines and the ellipsoid of a recording, posed at any time."""

    def __init__(self, data: RecordingData) -> None:
        self.data = data
        self._cache: dict[tuple[str, float], tuple[np.ndarray, np.ndarray] | None] = {}
        self.xforms: dict[str, _Xform] = {}
        self.meshes: list[_Mesh] = []
        self.static_lines: list[tuple[str, list[np.ndarray], tuple[int, int, int], int]] = []
        self.temporal_lines: list[tuple[str, np.ndarray, list[list[np.ndarray]], tuple[int, int, int]]] = []
        for e in data.entities():
            if not e.startswith(layout.WORLD):
                continue
            comps = set(data.components(e))
            if comps & {"Transform3D:translation", "Transform3D:quaternion", "Transform3D:mat3x3"}:
                x = self._xform(e, comps)
                if x is not None:
                    self.xforms[e] = x
            if _hidden(e):
                continue
            if "Mesh3D:vertex_positions" in comps:
                self.meshes.append(_Mesh(e, data.meshes(e), data.clear_times(e)))
            if "LineStrips3D:strips" in comps:
                self._lines(e)
        if layout.VEHICLE not in self.xforms:
            raise ReplayError(f"{data.path}: no {layout.VEHICLE} pose in this recording: nothing to follow")

    def _xform(self, e: str, comps: set[str]) -> _Xform | None:
        d = self.data
        if d.has_temporal(e, "Transform3D:translation"):
            t, p = d.translations(e)
            R = np.tile(np.eye(3), (len(t), 1, 1))
            if d.has_temporal(e, "Transform3D:quaternion"):
                tq, _, q = d.transforms(e)
                if np.array_equal(tq, t):
                    R = quat_to_dcm(q)
            return _Xform(t, R, p)
        R, p = np.eye(3), np.zeros(3)
        try:
            p = np.asarray(d.static_component(e, "Transform3D:translation")[0], float)
        except KeyError:
            pass
        try:
            R = quat_to_dcm(np.asarray(d.static_component(e, "Transform3D:quaternion")[0], float))
        except KeyError:
            try:  # Rerun stores a 3x3 matrix column-major
                R = np.asarray(d.static_component(e, "Transform3D:mat3x3")[0], float).reshape(3, 3).T
            except KeyError:
                pass
        return _Xform(None, R[None], p[None])

    def _lines(self, e: str) -> None:
        d = self.data
        colour = _TRUTH if e.startswith(layout.TRUTH) else _TRACK
        try:
            c = d.static_component(e, "LineStrips3D:colors")
            if c:
                v = int(c[0])
                colour = ((v >> 8) & 255, (v >> 16) & 255, (v >> 24) & 255)  # BGR
        except KeyError:
            pass
        width = 1 if e.startswith(layout.TRUTH) else 2
        if d.has_temporal(e, "LineStrips3D:strips"):
            t, rows = d.line_strips(e)
            self.temporal_lines.append((e, t, rows, colour))
        else:
            try:
                strips = d.static_component(e, "LineStrips3D:strips")
            except KeyError:
                return
            thin = []
            for st in strips:
                a = np.asarray(st, float).reshape(-1, 3)
                if len(a) > _MAX_LINE_POINTS:
                    a = a[np.unique(np.linspace(0, len(a) - 1, _MAX_LINE_POINTS).astype(int))]
                thin.append(a)
            self.static_lines.append((e, thin, colour, width))

    def pose(self, entity: str, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """World pose (R (3, 3), p (3,)) of ``entity`` at ``t``; None if an ancestor has no pose yet."""
        key = (entity, t)
        if key in self._cache:
            return self._cache[key]
        if len(self._cache) > 4096:
            self._cache.clear()
        self._cache[key] = out = self._pose(entity, t)
        return out

    def _pose(self, entity: str, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        parts = entity.strip("/").split("/")
        R, p = np.eye(3), np.zeros(3)
        for i in range(1, len(parts) + 1):
            x = self.xforms.get("/" + "/".join(parts[:i]))
            if x is None:
                continue
            rp = x.at(t)
            if rp is None:
                return None
            p = p + R @ rp[1]
            R = R @ rp[0]
        return R, p

    def vehicle_box(self, t: float) -> tuple[np.ndarray, float]:
        """Centre (3,) [m] and half-diagonal [m] of the world box around the vehicle meshes shown
        at ``t`` (the vehicle position and 1 m if none is shown)."""
        pts = []
        for m in self.meshes:
            if not m.entity.startswith(layout.VEHICLE + "/"):
                continue
            geo, pose = m.at(t), self.pose(m.entity, t)
            if geo is None or pose is None or not len(geo[0]):
                continue
            lo, hi = geo[0].min(axis=0), geo[0].max(axis=0)
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            pts.append(corners @ pose[0].T + pose[1])
        if not pts:
            pose = self.pose(layout.VEHICLE, t)
            return (pose[1] if pose is not None else np.zeros(3)), 1.0
        a = np.concatenate(pts)
        lo, hi = a.min(axis=0), a.max(axis=0)
        return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)


# ----------------------------------------------------------------------------------- camera
@dataclass
class _Camera:
    eye: np.ndarray
    R_cw: np.ndarray  # rows: right, down, forward (OpenCV camera axes) in world
    f: float
    near: float
    size: tuple[int, int] = (W, H)  # frame (width, height) [px]

    def to_cam(self, pts: np.ndarray) -> np.ndarray:
        return (pts - self.eye) @ self.R_cw.T

    def project(self, pc: np.ndarray) -> np.ndarray:
        z = np.maximum(pc[..., 2], 1e-9)
        w, h = self.size
        return np.stack([w / 2 + self.f * pc[..., 0] / z, h / 2 + self.f * pc[..., 1] / z], axis=-1)


def _look_at(eye: np.ndarray, target: np.ndarray, near: float, size: tuple[int, int] = (W, H)) -> _Camera:
    fwd = target - eye
    fwd = fwd / np.linalg.norm(fwd)
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(fwd, up)
    if np.linalg.norm(right) < 1e-6:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    f = 0.5 * size[0] / math.tan(math.radians(_FOV_DEG) / 2)
    return _Camera(eye, np.stack([right, down, fwd]), f, near, size)


def _clip_poly(poly: np.ndarray, near: float) -> np.ndarray:
    """Sutherland–Hodgman clip of a camera-frame polygon (k, 3) against z >= near."""
    out = []
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            s = (near - a[2]) / (b[2] - a[2])
            out.append(a + s * (b - a))
    return np.array(out) if out else np.zeros((0, 3))


def _draw_mesh(img: np.ndarray, cam: _Camera, verts_w: np.ndarray, faces: np.ndarray, colour, light: np.ndarray):
    """Flat-shaded, back-face culled triangles, far to near; translucent meshes blended."""
    if len(faces) == 0:
        return
    pc = cam.to_cam(verts_w)
    tri = pc[faces]  # (f, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nn = np.linalg.norm(n, axis=1)
    ok = nn > 0
    n[ok] /= nn[ok, None]
    centre = tri.mean(axis=1)
    facing = np.einsum("ij,ij->i", n, centre) < 0  # the camera sits at the origin of pc
    # both sides of thin surfaces (ramp, terrain patch) and of translucent meshes (whose winding
    # the recording does not promise); back faces culled only on large opaque meshes
    two_sided = len(faces) <= 64 or (len(colour) > 3 and colour[3] < 250)
    if two_sided:
        n = np.where(facing[:, None], n, -n)
        facing[:] = True
    zmin = tri[:, :, 2].min(axis=1)
    zmax = tri[:, :, 2].max(axis=1)
    keep = facing & ok & (zmax > cam.near)
    if not keep.any():
        return
    idx = np.nonzero(keep)[0]
    light_c = cam.R_cw @ light
    shade = 0.45 + 0.55 * np.clip(-(n[idx] @ light_c), 0.0, 1.0)
    order = np.argsort(-centre[idx, 2])
    idx, shade = idx[order], shade[order]
    bgr = np.array([colour[2], colour[1], colour[0]], float)
    alpha = colour[3] / 255.0 if len(colour) > 3 else 1.0
    pts2 = cam.project(tri[idx])
    front = zmin[idx] >= cam.near
    fw, fh = img.shape[1], img.shape[0]
    off_screen = front & (
        np.all(pts2[:, :, 0] < 0, axis=1)
        | np.all(pts2[:, :, 0] > fw, axis=1)
        | np.all(pts2[:, :, 1] < 0, axis=1)
        | np.all(pts2[:, :, 1] > fh, axis=1)
    )
    if off_screen.any():
        idx, shade, pts2, front = idx[~off_screen], shade[~off_screen], pts2[~off_screen], front[~off_screen]
        if not len(idx):
            return
    big = 30000.0  # OpenCV's drawing works in 16.16 fixed point
    partial = ~front | (np.abs(pts2).max(axis=(1, 2)) > big)
    whole = ~partial
    lo = (
        np.floor(np.clip(pts2[whole].reshape(-1, 2).min(axis=0), 0, [fw - 1, fh - 1])).astype(int)
        if whole.any()
        else None
    )
    hi = (
        np.ceil(np.clip(pts2[whole].reshape(-1, 2).max(axis=0), 0, [fw - 1, fh - 1])).astype(int)
        if whole.any()
        else None
    )
    if partial.any() or lo is None:
        lo, hi = np.array([0, 0]), np.array([fw - 1, fh - 1])
    target = img if alpha >= 0.99 else img[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1].copy()
    off = np.array([0, 0]) if target is img else lo
    # painter's order, one triangle at a time: OpenCV fills several polygons of one call with
    # the even-odd rule, so overlapping triangles may not share a call
    cols = ((np.minimum((shade * _SHADES).astype(int), _SHADES - 1) + 0.5) / _SHADES)[:, None] * bgr[None, :]
    cols = cols.astype(int).tolist()
    pts_i = np.round(np.clip(pts2, -big, big) - off).astype(np.int32)
    for j in range(len(idx)):
        if partial[j]:
            poly = _clip_poly(tri[idx[j]], cam.near)
            if len(poly) >= 3:
                q = np.clip(cam.project(poly), -big, big) - off
                cv2.fillPoly(target, [np.round(q).astype(np.int32)], cols[j])
        else:
            cv2.fillConvexPoly(target, pts_i[j], cols[j])
    if target is not img:
        a = max(alpha, 0.45)  # very faint albedo (airbags) is raised so it reads on video
        roi = img[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
        cv2.addWeighted(target, a, roi, 1.0 - a, 0.0, dst=roi)


def _draw_polyline(img: np.ndarray, cam: _Camera, pts_w: np.ndarray, colour, width: int = 1) -> None:
    """World polyline (m, 3), clipped at the near plane, as one anti-aliased polyline call."""
    if len(pts_w) < 2:
        return
    pc = cam.to_cam(pts_w)
    if np.all(pc[:, 2] >= cam.near):
        q = np.round(np.clip(cam.project(pc), -1e5, 1e5)).astype(np.int32)
        cv2.polylines(img, [q], False, colour, width, cv2.LINE_AA)
        return
    a, b = pc[:-1], pc[1:]
    ina, inb = a[:, 2] >= cam.near, b[:, 2] >= cam.near
    use = ina | inb
    if not use.any():
        return
    a, b, ina, inb = a[use], b[use], ina[use], inb[use]
    s = np.where(ina == inb, 0.0, (cam.near - a[:, 2]) / np.where(b[:, 2] == a[:, 2], 1.0, b[:, 2] - a[:, 2]))
    cut = a + s[:, None] * (b - a)
    a = np.where(ina[:, None], a, cut)
    b = np.where(inb[:, None], b, cut)
    big = 1e5
    pa = np.clip(cam.project(a), -big, big)
    pb = np.clip(cam.project(b), -big, big)
    segs = np.round(np.stack([pa, pb], axis=1)).astype(np.int32)
    cv2.polylines(img, list(segs), False, colour, width, cv2.LINE_AA)


def _ellipse_rings(centre: np.ndarray, R: np.ndarray, half: np.ndarray, k: int = 48) -> list[np.ndarray]:
    u = np.linspace(0, 2 * np.pi, k)
    c, s = np.cos(u), np.sin(u)
    rings = []
    for i, j in ((0, 1), (1, 2), (0, 2)):
        loc = np.zeros((k, 3))
        loc[:, i] = half[i] * c
        loc[:, j] = half[j] * s
        rings.append(centre + loc @ R.T)
    return rings


# ----------------------------------------------------------------------------------- HUD data
@dataclass
class _Series:
    t: np.ndarray
    v: np.ndarray
    s: np.ndarray | None


def _hud_series(data: RecordingData, item: HudItem) -> _Series | None:
    """Estimate (and 1σ if bounded) of one HUD item, or None if the recording lacks it."""
    ents = set(data.entities())

    def bounded(root: str) -> _Series | None:
        est = next(
            (layout.join(root, x) for x in (layout.VALUE, layout.SMOOTHED_SERIES) if layout.join(root, x) in ents),
            root if root in ents else None,
        )
        if est is None:
            return None
        try:
            t, v = data.scalars(est)
        except KeyError:
            return None
        sig = None
        for n in (1.0, 3.0):
            plus = layout.join(root, layout.bound_names(n)[0])
            if plus in ents:
                tp, p = data.scalars(plus)
                if np.array_equal(tp, t) and p.shape == v.shape:
                    sig = np.abs(p - v) / n
                    break
        return _Series(t, v, sig)

    if item.children:
        parts = [bounded(layout.join(item.root, c)) for c in item.children]
        if any(p is None for p in parts) or len({len(p.t) for p in parts}) != 1:
            return None
        v = np.linalg.norm(np.concatenate([p.v[:, :1] for p in parts], axis=1), axis=1)[:, None]
        return _Series(parts[0].t, v, None)
    s = bounded(item.root)
    if s is not None and s.v.shape[1] > 1 and item.label == "speed":
        return _Series(s.t, np.linalg.norm(s.v, axis=1)[:, None], None)
    return s


def _value_at(s: _Series, t: float) -> tuple[float, float | None] | None:
    i = int(np.searchsorted(s.t, t, side="right")) - 1
    if i < 0 or not len(s.t):
        return None
    return float(s.v[i, 0]), (float(s.s[i, 0]) if s.s is not None else None)


# ---------------------------------------------------------------------------------- time warp
def frame_times(
    t0: float, t1: float, events: list[float], *, duration_s: float, fps: float, slow: float, window_s: float
) -> np.ndarray:
    """Recording times [s] of the video frames: a base rate chosen so the video lasts about
    ``duration_s`` [s] at ``fps``, multiplied by ``slow`` (< 1) within ``± window_s`` of each event
    (smoothly, a Gaussian bump); strictly increasing, first ``t0``, last ≤ ``t1``."""
    if not t1 > t0:
        raise ReplayError(f"empty time range {t0}..{t1}")
    ev = np.array([e for e in events if t0 <= e <= t1], float)

    def factor(t: np.ndarray) -> np.ndarray:
        if not len(ev):
            return np.ones_like(t)
        bump = np.max(np.exp(-0.5 * ((t[:, None] - ev[None, :]) / window_s) ** 2), axis=1)
        return 1.0 - (1.0 - slow) * bump

    grid = np.linspace(t0, t1, 4001)
    # video seconds per recording second ∝ 1 / factor; scale so the total is duration_s
    inv = 1.0 / factor(grid)
    video = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(grid))])
    video *= duration_s / video[-1]
    n = max(2, int(round(duration_s * fps)))
    return np.interp(np.arange(n) / fps, video, grid)


# ------------------------------------------------------------------------------------ drawing
def _smooth(x: np.ndarray, k: int) -> np.ndarray:
    """Moving average over ``2k + 1`` rows of (n, m) ``x`` (edges padded with the end values)."""
    ker = np.ones(2 * k + 1) / (2 * k + 1)
    padded = np.pad(x, ((k, k), (0, 0)), mode="edge")
    return np.stack([np.convolve(padded[:, i], ker, mode="valid") for i in range(x.shape[1])], axis=1)


def _background(size: tuple[int, int] = (W, H)) -> np.ndarray:
    w = np.linspace(0, 1, size[1], dtype=np.float32)[:, None]
    col = (1 - w) * _BG_TOP[None, :] + w * _BG_BOTTOM[None, :]
    return np.repeat(col[:, None, :], size[0], axis=1).astype(np.uint8)


@functools.lru_cache(maxsize=16)
def _font(px: int, bold: bool):
    """DejaVu Sans (matplotlib's bundled font: σ, ±, °, Greek, arrows) at ``px`` pixels, as a PIL font."""
    from matplotlib import font_manager
    from PIL import ImageFont

    props = font_manager.FontProperties(family="DejaVu Sans", weight="bold" if bold else "normal")
    return ImageFont.truetype(font_manager.findfont(props), px)


@functools.lru_cache(maxsize=4096)
def _text_size(s: str, scale: float = 0.6, thick: int = 1) -> tuple[int, int]:
    """(width, height) [px] of ``s`` drawn by :func:`draw_text` with ``scale`` and ``thick``."""
    font = _font(max(6, round(scale * _FONT_PX)), thick > 1)
    x0, y0, x1, y1 = font.getbbox(s, anchor="ls")
    return int(x1 - x0), int(y1 - y0)


@functools.lru_cache(maxsize=1024)
def _fit(s: str, width: int, scale: float = 0.6, thick: int = 1) -> str:
    """``s`` cut (with "…") to fit ``width`` [px] at ``scale``."""
    if _text_size(s, scale, thick)[0] <= width:
        return s
    while s and _text_size(s + "…", scale, thick)[0] > width:
        s = s[:-1]
    return s.rstrip() + "…"


def draw_text(img, s: str, org, scale=0.6, colour=_TEXT, thick=1):
    """Draw ``s`` on the BGR frame ``img`` with its baseline starting at ``org`` (x, y) [px], at
    ``scale`` × 30 px, bold when ``thick`` > 1, in DejaVu Sans (any Unicode the font has: σ, ±, °),
    anti-aliased; only the text's box is converted through PIL."""
    from PIL import Image, ImageDraw

    font = _font(max(6, round(scale * _FONT_PX)), thick > 1)
    x, y = int(org[0]), int(org[1])
    bx0, by0, bx1, by1 = font.getbbox(s, anchor="ls")
    x0, y0 = max(0, x + bx0 - 2), max(0, y + by0 - 2)
    x1, y1 = min(img.shape[1], x + bx1 + 2), min(img.shape[0], y + by1 + 2)
    if x1 <= x0 or y1 <= y0:
        return
    roi = Image.fromarray(np.ascontiguousarray(img[y0:y1, x0:x1, ::-1]))
    ImageDraw.Draw(roi).text((x - x0, y - y0), s, font=font, fill=tuple(int(c) for c in colour[::-1]), anchor="ls")
    img[y0:y1, x0:x1] = np.asarray(roi)[:, :, ::-1]


def _panel(img, x0, y0, x1, y1, alpha=0.55):
    roi = img[y0:y1, x0:x1]
    roi[:] = (roi.astype(np.float32) * (1 - alpha)).astype(np.uint8)


@dataclass
class Overlay:
    """Everything drawn on top of the 3D scene that does not depend on the camera (pixels of the
    1280×720 layout, scaled with the frame by :func:`draw_overlay`; times [s]): ``title``/``subtitle``
    (:func:`replay_titles`), ``events`` (t, text)
    captioned for ``caption_s`` after t, the HUD's ``hud`` series, the time bar's ``t0``..``t1``,
    the inset's ``track_2d`` (n, 2) at ``track_t`` (n,) in its box ``inset`` (x0, y0, x1, y1), and
    per-frame ``extra`` values (``ellipsoid_3sigma_axes_m``: the 3σ ellipsoid's semi-axes [m])."""

    title: str
    subtitle: str
    events: list[tuple[float, str]]
    hud: list[tuple[HudItem, _Series]]
    t0: float
    t1: float
    track_2d: np.ndarray  # (n, 2) inset coordinates
    track_t: np.ndarray
    inset: tuple[int, int, int, int] = (W - 330, H - 215, W - 10, H - 55)
    caption_s: float = 0.0
    extra: dict = field(default_factory=dict)


#: what a replay shows, per problem kind (the subtitle's end)
_SHOWN = {
    "droptest": "smoothed lander and airbags, 3σ position ellipsoid, truth track thin",
    "entry": "smoothed vehicle, 3σ position ellipsoid, truth track thin",
}


def replay_titles(data: RecordingData, kind: str | None) -> tuple[str, str]:
    """(title, subtitle) of a replay: the run's name and scenario description; the kind, seed,
    synthetic or user data, the recording's date (UTC) and what is drawn."""
    props = data.properties()
    run = props.get("run", {})
    name = data.recording_name or data.path.stem
    desc = str(run.get("description") or "").strip()
    title = f"{name} — {desc}" if desc else name
    parts = [f"{kind or run.get('kind') or 'run'} reconstruction"]
    if run.get("seed") is not None and run.get("synthetic", True):
        parts.append(f"synthetic, seed {run['seed']}")
    start = props.get("RecordingInfo", {}).get("start_time")
    if start is not None:
        when = dt.datetime.fromtimestamp(int(start) / 1e9, dt.UTC)
        parts.append(f"recorded {when:%Y-%m-%d %H:%M} UTC")
    parts.append(_SHOWN.get(kind or "", "smoothed vehicle and 3σ position ellipsoid"))
    return title, " · ".join(parts)


def _lengths(xs) -> str:
    """Lengths [m], largest first, "a × b × c unit" in the unit of the largest (mm, m or km: the one
    a reader takes in at a glance), three figures."""
    xs = sorted((float(x) for x in xs), reverse=True)
    scale, unit = (1e3, "mm") if xs[0] < 0.1 else (1.0, "m") if xs[0] < 1e3 else (1e-3, "km")
    return " × ".join(f"{x * scale:.3g}" for x in xs) + f" {unit}"


def draw_overlay(img: np.ndarray, ov: Overlay, t: float) -> None:
    """The title bar, the HUD (top left), the latest event's caption (bottom, left of the inset),
    the time bar with the events and the inset track, at time ``t`` [s]. Laid out in the 1280×720
    frame's pixels and scaled by the frame's width over 1280 (text, lines and boxes: a 1920×1080
    frame is the same picture, sharper)."""
    h, w = img.shape[:2]
    k = w / W

    def px(v: float) -> int:
        return int(round(k * v))

    a, b, c, d = (px(v) for v in ov.inset)
    # title bar: the run and what it is, then what is shown
    _panel(img, 0, 0, w, px(58), 0.6)
    draw_text(img, _fit(ov.title, w - px(40), 0.62 * k, 2), (px(20), px(26)), 0.62 * k, (120, 200, 255), 2)
    draw_text(img, _fit(ov.subtitle, w - px(40), 0.45 * k), (px(20), px(48)), 0.45 * k, (210, 210, 210))
    # HUD, top left
    lines = [f"t = {t:8.3f} s"]
    for item, sr in ov.hud:
        va = _value_at(sr, t)
        if va is None:
            continue
        v, sg = va[0] * item.scale, va[1]
        txt = f"{item.label} {v:{item.fmt}}"
        if sg is not None:
            txt += f" ± {sg * item.scale:{item.fmt}}"
        lines.append(txt + f" {item.unit}")
    axes = ov.extra.get("ellipsoid_3sigma_axes_m")
    if axes is not None:
        lines.append("3σ ellipsoid " + _lengths(axes))
    y0 = px(66)
    _panel(img, px(10), y0, px(470), y0 + px(14 + 30 * len(lines)))
    for i, line in enumerate(lines):
        bold = 2 if i == 0 else 1
        draw_text(img, _fit(line, px(440), 0.7 * k, bold), (px(22), y0 + px(34 + 30 * i)), 0.7 * k, _TEXT, bold)
    # caption: the latest event within caption_s before t, centred left of the inset
    recent = [(te, e) for te, e in ov.events if te <= t <= te + ov.caption_s]
    if recent:
        _, cap = recent[-1]
        room = a - px(40)
        cap = _fit(cap, room - px(28), 0.8 * k, 2)
        tw, _ = _text_size(cap, 0.8 * k, 2)
        x = px(10) + max(0, (room - tw) // 2)
        _panel(img, x - px(14), h - px(112), min(a - px(10), x + tw + px(14)), h - px(74), 0.6)
        draw_text(img, cap, (x, h - px(85)), 0.8 * k, (80, 230, 255), 2)
    # time bar with the events
    x0, x1, y = px(20), w - px(350), h - px(30)
    cv2.line(img, (x0, y), (x1, y), (200, 200, 200), max(1, px(2)), cv2.LINE_AA)

    def xt(tt):
        return int(x0 + (x1 - x0) * (tt - ov.t0) / (ov.t1 - ov.t0))

    for te, _ in ov.events:
        cv2.line(img, (xt(te), y - px(8)), (xt(te), y + px(8)), (80, 230, 255), max(1, px(2)))
    cv2.circle(img, (xt(t), y), px(7), (255, 255, 255), -1, cv2.LINE_AA)
    # inset: the whole track, side view, with the vehicle on it
    _panel(img, a, b, c, d, 0.6)
    pts = np.round(k * ov.track_2d).astype(np.int32)
    cv2.polylines(img, [pts], False, _TRACK, max(1, px(1)), cv2.LINE_AA)
    i = int(np.clip(np.searchsorted(ov.track_t, t), 0, len(pts) - 1))
    cv2.circle(img, tuple(int(x) for x in pts[i]), px(5), (80, 230, 255), -1, cv2.LINE_AA)
    draw_text(img, "track (side view)", (a + px(8), b + px(18)), 0.45 * k)


def _inset_track(p: np.ndarray, right: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """Track (n, 3) [m] -> inset pixel coordinates (n, 2): horizontal along ``right``, vertical z,
    equal scales, fitted into ``box``."""
    u = p @ right
    v = p[:, 2]
    a, b, c, d = box
    pad = 24
    su = (c - a - 2 * pad) / max(np.ptp(u), 1e-9)
    sv = (d - b - 2 * pad) / max(np.ptp(v), 1e-9)
    s = min(su, sv)
    cu, cv_ = 0.5 * (u.max() + u.min()), 0.5 * (v.max() + v.min())
    return np.stack([(a + c) / 2 + s * (u - cu), (b + d) / 2 + 8 - s * (v - cv_)], axis=1)


# ------------------------------------------------------------------------------------- driver
def render_mp4(
    recording: str | os.PathLike[str] | RecordingData,
    out: str | os.PathLike[str],
    *,
    kind: str | None = None,
    fps: float = 25.0,
    duration_s: float | None = None,
    progress: Callable[[str], None] | None = None,
    size: tuple[int, int] = (W, H),
) -> ReplayStats:
    """Render the presentation video of a run recording to ``out`` (``.mp4``, ``size`` (width,
    height) [px], 16:9: 1280×720 by default, 1920×1080 for a full-HD presentation; ``fps``).

    ``kind``: the problem kind whose :class:`Presentation` to use (default: the recording's
    ``run`` property; unknown kinds get a generic one); ``duration_s``: video length [s] (default:
    the presentation's). Raises :class:`ReplayError` if there is no ``/world/vehicle`` pose, and
    ``OSError`` if OpenCV cannot open an MP4 writer. The file is written to ``<out>.partial.mp4``
    and renamed when complete.
    """
    t_start, c_start = time.perf_counter(), time.process_time()
    size = (int(size[0]), int(size[1]))
    if size[0] < 320 or abs(size[0] * H - size[1] * W) > W:
        raise ValueError(f"replay size {size[0]}x{size[1]}: give a 16:9 frame at least 320 wide (e.g. 1920x1080)")
    widen = size[0] / W  # line widths scale with the frame; the overlay scales itself
    data = recording if isinstance(recording, RecordingData) else read_recording(recording)
    kind = kind or str(data.properties().get("run", {}).get("kind", ""))
    pres = PRESENTATIONS.get(kind, _DEFAULT)
    scene = _Scene(data)
    xv = scene.xforms[layout.VEHICLE]
    if xv.t is None or len(xv.t) < 2:
        raise ReplayError(f"{data.path}: {layout.VEHICLE} has no pose history to follow")
    t0, t1 = float(xv.t[0]), float(xv.t[-1])
    try:
        log = [(float(te), s) for te, s, lv in data.text_log() if (lv or "INFO") in ("INFO", "WARN")]
    except KeyError:
        log = []
    # telemetry diagnostics (messages naming a file) are not captioned
    events = [(te, s) for te, s in log if t0 <= te <= t1 and not _FILE_MESSAGE.search(s)]
    window = pres.window_s if pres.window_s is not None else 0.02 * (t1 - t0)
    dur = float(duration_s if duration_s is not None else pres.duration_s)
    times = frame_times(t0, t1, [te for te, _ in events], duration_s=dur, fps=fps, slow=pres.slow, window_s=window)
    # camera target: centre of the visible vehicle meshes' world box; distance from its size
    centre, radius = np.zeros((len(times), 3)), np.zeros(len(times))
    for n, t in enumerate(times):
        centre[n], radius[n] = scene.vehicle_box(t)
    k = max(1, int(fps * 0.4))
    veh = np.array([scene.pose(layout.VEHICLE, t)[1] for t in times])
    target = veh + _smooth(centre - veh, k)  # the vehicle moves fast: smooth only the offset
    dist = pres.distance * _smooth(radius[:, None], k)[:, 0]
    span = veh[-1] - veh[0]
    horiz = np.array([span[0], span[1], 0.0])
    if np.linalg.norm(horiz) < 1e-6:
        horiz = np.array([1.0, 0.0, 0.0])
    horiz /= np.linalg.norm(horiz)
    side = np.cross(np.array([0.0, 0.0, 1.0]), horiz)  # the camera looks across the track
    el = math.radians(pres.elevation_deg)
    offset_dir = math.cos(el) * -side + math.sin(el) * np.array([0.0, 0.0, 1.0])
    light = np.array([0.3, -0.5, -0.8])
    light /= np.linalg.norm(light)
    # inset track: the full smoothed vehicle path
    full_t = xv.t
    full_p = np.array([scene.pose(layout.VEHICLE, t)[1] for t in full_t[:: max(1, len(full_t) // 2000)]])
    full_t = full_t[:: max(1, len(xv.t) // 2000)]
    right_dir = np.cross(-side, np.array([0.0, 0.0, 1.0]))
    title, subtitle = replay_titles(data, kind)
    ov = Overlay(
        title=title,
        subtitle=subtitle,
        events=events,
        hud=[(it, s) for it in pres.hud if (s := _hud_series(data, it)) is not None],
        t0=t0,
        t1=t1,
        track_2d=_inset_track(full_p, right_dir / np.linalg.norm(right_dir), (W - 330, H - 215, W - 10, H - 55)),
        track_t=full_t,
        caption_s=max(3.0 * window, 0.08 * (t1 - t0)),
    )
    ell = None
    if layout.UNCERTAINTY in data.entities():
        try:
            ell = data.ellipsoids(layout.UNCERTAINTY)
        except KeyError:
            ell = None
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + ".partial.mp4")
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    if not writer.isOpened():
        raise OSError(f"OpenCV cannot write an MP4 to {tmp} (no mp4v encoder?)")
    bg = _background(size)
    try:
        for n, t in enumerate(times):
            # aim a little below the box centre: the vehicle sits above the captions and the inset
            aim = target[n] - np.array([0.0, 0.0, 0.25 * dist[n] / pres.distance])
            cam = _look_at(aim + dist[n] * offset_dir, aim, near=0.02 * dist[n], size=size)
            img = bg.copy()
            for e, strips, colour, width in scene.static_lines:
                pose = scene.pose(e, t)
                if pose is None:
                    continue
                for s in strips:
                    _draw_polyline(img, cam, s @ pose[0].T + pose[1], colour, max(1, round(widen * width)))
            # opaque meshes first (far entity first), translucent after
            items = []
            for m in scene.meshes:
                geo = m.at(t)
                pose = scene.pose(m.entity, t)
                if geo is None or pose is None:
                    continue
                vw = geo[0] @ pose[0].T + pose[1]
                depth = float(np.linalg.norm(vw.mean(axis=0) - cam.eye))
                items.append((geo[2][3] < 250, -depth, vw, geo[1], geo[2]))
            for _, _, vw, faces, colour in sorted(items, key=lambda x: (x[0], x[1])):
                _draw_mesh(img, cam, vw, faces, colour, light)
            for e, tl, rows, colour in scene.temporal_lines:
                i = int(np.searchsorted(tl, t, side="right")) - 1
                pose = scene.pose(e, t)
                if i < 0 or pose is None:
                    continue
                for s in rows[i]:
                    _draw_polyline(img, cam, s @ pose[0].T + pose[1], colour, max(1, round(2 * widen)))
            if ell is not None:
                te, c, hs, q = ell
                i = int(np.searchsorted(te, t, side="right")) - 1
                pose = scene.pose(layout.UNCERTAINTY, t)
                ov.extra["ellipsoid_3sigma_axes_m"] = hs[i, 0] if i >= 0 else None
                if i >= 0 and pose is not None and hs[i, 0].max() <= 1.5 * dist[n]:
                    Rw = pose[0] @ quat_to_dcm(q[i, 0])
                    centre = pose[0] @ c[i, 0] + pose[1]
                    for ring in _ellipse_rings(centre, Rw, hs[i, 0]):
                        _draw_polyline(img, cam, ring, _ELLIPSE, max(1, round(2 * widen)))
            draw_overlay(img, ov, float(t))
            writer.write(img)
            if progress is not None and n % 100 == 0:
                progress(f"replay: frame {n + 1}/{len(times)} (t = {t:.3f} s)")
    except BaseException:
        writer.release()
        tmp.unlink(missing_ok=True)
        raise
    writer.release()
    os.replace(tmp, out)
    return ReplayStats(out, len(times), fps, size, t0, t1, time.perf_counter() - t_start, time.process_time() - c_start)
