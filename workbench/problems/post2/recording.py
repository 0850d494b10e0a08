"""The post2 recording: observations as read, residuals with ±3σ and the weight schedule, every
estimated state with ±3σ converging (and the planted truth when synthetic), the phases, the vehicle
in 3-D (capsule, parachute while open, tilt when a tilt state is estimated), the scorecard; a rocket
flight (``[launch]``) also its track in the pad's frame (altitude above the pad, speeds, east/north/up),
the views it opens on.

States are read generically by name from the state map (``Post2Result.history``), so a state another
module adds (per-regime multipliers, a drogue, a tilt, ...) is drawn without code here: scalar and
vector blocks each get a tab with one small view per component (value, ±3σ, truth: four series).
Drawn through :class:`workbench.recording.writer` and the entity paths of
:mod:`workbench.recording.layout`; a :class:`~workbench.recording.dispatch.StageDispatch` maps each
stage type to its handler (an unknown stage is a ``TypeError``).
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import trimesh

from workbench.core.rotation import dcm_to_quat, quat_to_dcm
from workbench.problems.post2.model import OBSERVATIONS, STATES
from workbench.problems.post2.pipeline import ForwardStage, ObservationData, Post2Result
from workbench.problems.post2.scoring import truth_on_grid
from workbench.recording import layout
from workbench.recording.blueprint import events_view, plot_view, report_view, tab, y_range_if_needed
from workbench.recording.dispatch import StageDispatch
from workbench.recording.meshes import mesh3d
from workbench.recording.moments import log_key_moments
from workbench.recording.writer import open_recording

__all__ = [
    "Post2Drawer",
    "open_post2_recording",
    "post2_blueprint",
    "trajectory_eye",
    "COMPONENTS",
    "vehicle_meshes",
    "local_level_in_body",
    "horizon_grid",
    "PLOT_KEY_MD",
]

#: component names of the state blocks in the plots
COMPONENTS = {
    "position": ("x", "y", "z"),
    "velocity": ("x", "y", "z"),
    "attitude": ("alpha", "beta", "bank"),
    "body_rates": ("p", "q", "r"),
    "accel_bias": ("x", "y", "z"),
    "wind": ("east", "north"),
}

#: display unit of a state or observation unit (SI values are scaled by the factor for the plots)
_DISPLAY = {"deg": ("deg", 180.0 / math.pi), "deg/s": ("deg/s", 180.0 / math.pi)}

#: the colours of every plot, once for all views (their titles are only quantity and unit), in the
#: scorecard under the verdict
PLOT_KEY_MD = (
    "*Plot key* — states: blue estimate, grey ±3σ, thin pale blue truth, purple propagation only; "
    "residuals: blue, grey ±3σ  \n\n"
)

EST = (31, 119, 180, 255)
FWD = (255, 127, 14, 255)
TRUTH = (44, 160, 44, 255)
PROP = (148, 103, 189, 255)
#: the height [CSS px] of a state or residual view (a 1400 x 900 window: about 155 to 175)
VIEW_PX = 150.0


def _display(unit: str) -> tuple[str, float]:
    return _DISPLAY.get(unit, (unit, 1.0))


def _components(name: str, size: int) -> tuple[str, ...]:
    c = COMPONENTS.get(name)
    if c is not None and len(c) == size:
        return c
    return ("value",) if size == 1 else tuple(f"c{i}" for i in range(size))


def vehicle_meshes(diameter: float, parachute_diameter: float | None, riser: float) -> dict:
    """Simple display meshes in the post2 body frame B (+X_B towards the heat shield): a 70° sphere-cone
    forebody (apex on +X_B) and a conical back shell, and, with ``parachute_diameter`` [m], a canopy
    ``riser`` [m] behind the vehicle (−X_B) with its riser end points; trimesh objects, metres."""
    r = 0.5 * diameter
    to_x = trimesh.transformations.rotation_matrix(math.pi / 2.0, [0.0, 1.0, 0.0])  # +Z -> +X
    fore = trimesh.creation.cone(radius=r, height=r / math.tan(math.radians(70.0)), sections=32)
    fore.apply_transform(to_x)
    back = trimesh.creation.cone(radius=r, height=0.75 * diameter, sections=32)
    back.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2.0, [0.0, 1.0, 0.0]))  # apex -X
    out = {"forebody": fore, "back_shell": back}
    if parachute_diameter:
        rp = 0.5 * parachute_diameter
        canopy = trimesh.creation.cone(radius=rp, height=0.5 * rp, sections=32)
        canopy.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2.0, [0.0, 1.0, 0.0]))
        canopy.apply_translation([-riser, 0.0, 0.0])
        out["canopy"] = canopy
        u = np.linspace(0.0, 2.0 * math.pi, 9)[:-1]
        out["riser_ends"] = np.column_stack([np.full(u.size, -riser), rp * np.cos(u), rp * np.sin(u)])
    return out


def trajectory_eye(track: np.ndarray) -> rrb.EyeControls3D | None:
    """A camera that frames the whole ``track`` (n, 3) [m, planet-centred frame of ``/world``]: it looks
    at the middle of the track's bounding box from the side of its overall direction, a little above
    (up = the local vertical there), at 1.6 × the box's diagonal; None for an empty or one-point track.
    The viewer's own fit of the planet-scale scene left the track half off the pane."""
    p = np.asarray(track, dtype=float)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < 2:
        return None
    lo, hi = p.min(axis=0), p.max(axis=0)
    c, size = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    if size <= 0.0:
        return None
    up = c / np.linalg.norm(c) if np.linalg.norm(c) > 0 else np.array([0.0, 0.0, 1.0])
    along = p[-1] - p[0]
    side = np.cross(along, up)
    if np.linalg.norm(side) < 1e-9 * max(np.linalg.norm(along), 1.0):  # a vertical track: any horizontal
        side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    eye = c + size * (1.5 * side + 0.5 * up)
    return rrb.EyeControls3D(position=eye, look_target=c, eye_up=up)


def local_level_in_body(p_I: np.ndarray, q_I_B: np.ndarray) -> np.ndarray:
    """q_B_L (n, 4) scalar-last: the local level frame L (east, north, up at the position ``p_I``
    (n, 3) [m, planet-centred inertial, +Z the pole]) seen from the body frame B of attitude
    ``q_I_B`` (n, 4); a child entity of the vehicle with this rotation lies in the local horizontal.
    East = unit(Ẑ × r̂), north = r̂ × east (undefined exactly at a pole)."""
    p = np.asarray(p_I, dtype=float)
    up = p / np.linalg.norm(p, axis=-1, keepdims=True)
    east = np.stack([-up[:, 1], up[:, 0], np.zeros(len(up))], axis=-1)
    east /= np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    C_I_L = np.stack([east, north, up], axis=-1)  # columns: L's axes in I
    C_B_L = np.einsum("nji,njk->nik", quat_to_dcm(q_I_B), C_I_L)  # C_I_B^T C_I_L
    return dcm_to_quat(C_B_L)


def horizon_grid(extent: float, below: float, n: int = 8) -> list[np.ndarray]:
    """Lines of a square grid in the local horizontal plane z = −``below`` [m] of frame L, ``extent``
    [m] from the centre each way, ``n`` cells across: the horizon drawn under the vehicle."""
    u = np.linspace(-extent, extent, n + 1)
    z = -float(below)
    lines = [np.array([[x, -extent, z], [x, extent, z]]) for x in u]
    return lines + [np.array([[-extent, y, z], [extent, y, z]]) for y in u]


class Post2Drawer:
    """Draws the post2 stages; ``truth`` (the loaded truth.npz dict) or None; ``geometry`` {"diameter_m",
    "parachute_diameter_m" (or None), "riser_m", "planet_rate_rad_s" (planet-relative velocity of the
    velocity arrow and of the 3-DOF drawn attitude; 0 when missing)} and ``parachute_events`` {event
    name: True opens /
    False releases} for the 3-D vehicle; ``layout`` an optional ``(eye, span=, spans=, y_ranges=) ->
    blueprint``, the one layout of the recording, sent by :meth:`finish` with the trajectory camera
    fitted to the smoothed track and the plots' axes on what they draw (:meth:`view_range`)."""

    def __init__(self, rec, truth, scorecard, geometry=None, parachute_events=None, layout=None):
        self.rec, self.truth, self.scorecard = rec, truth, scorecard
        self.geometry = geometry or {}
        self.parachute_events = dict(parachute_events or {})
        self.events: tuple[tuple[float, str], ...] = ()
        self.layout = layout
        self.track: np.ndarray | None = None
        self.span: tuple[float, float] | None = None
        self.spans: dict[str, tuple[float, float]] = {}
        self.y_ranges: dict[str, tuple[float, float]] = {}
        self.handle = StageDispatch(
            {ObservationData: self._data, ForwardStage: self._forward, Post2Result: self._result}
        )

    def view_range(self, origin: str, t: np.ndarray, *series: np.ndarray | None) -> None:
        """Note the x span (first, last ``t`` [s]) and a y range holding every finite value of
        ``series`` (the view's unit; :meth:`finish` fixes it, widened, where the viewer's own fit
        would label fewer than three ticks in a view :data:`VIEW_PX` high:
        ``blueprint.y_range_if_needed``) of the plot view at ``origin``; several notes of one
        origin are merged."""
        t = np.asarray(t, dtype=float)
        t = t[np.isfinite(t)]
        if t.size > 1 and t.max() > t.min():
            a, b = self.spans.get(origin, (np.inf, -np.inf))
            self.spans[origin] = (min(a, float(t.min())), max(b, float(t.max())))
        vals = np.concatenate([np.ravel(np.asarray(x, dtype=float)) for x in series if x is not None] or [[]])
        vals = vals[np.isfinite(vals)]
        if vals.size:
            a, b = self.y_ranges.get(origin, (np.inf, -np.inf))
            lo, hi = min(a, float(vals.min())), max(b, float(vals.max()))
            self.y_ranges[origin] = (lo, hi)

    def _data(self, stage: ObservationData) -> None:
        for name, ch in stage.channels.items():
            d = OBSERVATIONS[ch.spec.quantity]
            unit, k = _display(d.file_unit or d.unit) if ch.spec.quantity != "quaternion" else ("1", 1.0)
            for i, c in enumerate(d.components):
                self.rec.scalars(
                    layout.join(layout.sensor_path(name, c), layout.MEASURED_SERIES),
                    ch.t,
                    ch.z[:, i] * k,
                    names=f"{name}.{c} measured [{unit}]",
                )

    def _forward(self, stage: ForwardStage) -> None:
        fp = stage.forward
        for name, ih in fp.innovations.items():
            d = OBSERVATIONS[stage.quantities[name]]
            unit, k = _display(d.unit)
            sd = stage.residual_sigma(name)
            for i, c in enumerate(d.residual_names):
                path, label = layout.residual_path(name, c), f"{name}.{c} residual [{unit}]"
                y, b = ih.y[:, i] * k, 3.0 * sd[:, i] * k
                self.rec.series_with_bounds(path, ih.t, y, sd[:, i] * k, names=label)
                for origin in (path, layout.residual_path(name)):  # a component's view, or all in one
                    self.view_range(origin, ih.t, y + b, y - b)
        for name, (t, f) in stage.weight_factors.items():  # the weight schedule as applied
            self.rec.scalars(
                layout.plot_path(f"schedule/{name}_weight_factor"),
                t,
                f,
                names=f"{name} weight factor (W × f, R / f) [1]",
                colors=[FWD],
            )
        self.events = tuple(stage.events)
        if stage.events:
            self.rec.events([(t, f"event {name}", "INFO") for t, name in stage.events])

    def _phase_series(self, res: Post2Result) -> None:
        """Phase index vs time (:meth:`Post2Result.phase_index`), named after the events."""
        if not res.events:
            return
        label = "phase index [1] (" + ", ".join(f"{n} at {a:.1f} s" for a, n in res.events) + ")"
        self.rec.scalars(layout.POST2_PHASE, res.t, res.phase_index(), names=label, colors=[EST])

    def _result(self, res: Post2Result) -> None:
        tg = truth_on_grid(self.truth, res.t) if self.truth is not None else {}
        prop = res.history.get("propagated")
        for name, h in res.history["smoothed"].items():
            unit, k = _display(STATES[name].unit)
            size = h["value"].shape[1]
            comps = _components(name, size)
            v, s = h["value"] * k, h["sigma"] * k
            truth = None
            if name in tg:
                truth = tg[name] * k
            elif self.truth is not None and f"param_{name}" in self.truth:
                truth = np.broadcast_to(np.atleast_1d(self.truth[f"param_{name}"]) * k, v.shape)
            shown = name
            pv = prop[name]["value"] * k if prop is not None and name in prop else None
            if name in ("position", "velocity") and truth is not None:  # errors: values are too large to read
                v, pv, truth = v - truth, None if pv is None else pv - truth, np.zeros_like(v)
                shown = f"{name}_error"
            for i, c in enumerate(comps):
                root = layout.plot_path(f"{shown}/{c}")
                self.view_range(
                    root,
                    res.t,
                    v[:, i] + 3.0 * s[:, i],
                    v[:, i] - 3.0 * s[:, i],
                    None if truth is None else truth[:, i],
                    None if pv is None else pv[:, i],
                )
                self.rec.series_with_bounds(
                    root,
                    res.t,
                    v[:, i],
                    s[:, i],
                    truth=None if truth is None else truth[:, i],
                    names=f"{shown}.{c} [{unit}]",
                )
                if pv is not None:
                    self.rec.scalars(
                        layout.join(root, "propagation_only"),
                        res.t,
                        pv[:, i],
                        names=f"{shown}.{c} propagation only [{unit}]",
                        colors=[PROP],
                    )
        self._phase_series(res)
        if res.rocket is not None:
            self._rocket(res)
        p = res.smap.raw(res.x, "position")
        self.track = np.asarray(p, dtype=float)
        if len(res.t) > 1 and res.t[-1] > res.t[0]:
            self.span = (float(res.t[0]), float(res.t[-1]))
        # tracks and the vehicle marker in screen units: at the trajectory's hundreds of km a line in
        # metres is invisible, and so is the capsule
        self.rec.line_strip(layout.join(layout.ESTIMATE_SMOOTHED, "track"), p, color=EST, radius=-1.2)
        pf = res.smap.raw(res.forward.x_post, "position")
        self.rec.line_strip(layout.join(layout.ESTIMATE_FORWARD, "track"), pf, color=FWD, radius=-0.8)
        if self.truth is not None and "position" in self.truth:
            self.rec.line_strip(layout.truth_path("track"), self.truth["position"], color=TRUTH, radius=-0.8)
        self._vehicle(res)

    def _rocket(self, res: Post2Result) -> None:
        """A rocket flight's track in the pad's frame (:class:`~.rocket_results.LocalTrack`), each
        series with ±3σ: altitude above the pad, vertical speed, speed, downrange, east, north, up."""
        tr = res.rocket
        series = (
            (layout.POST2_ROCKET_ALTITUDE, tr.altitude, tr.sigma_altitude, "altitude above the pad [m]"),
            (layout.POST2_ROCKET_VERTICAL_SPEED, tr.vertical_speed, tr.sigma_vertical_speed, "vertical speed [m/s]"),
            (layout.POST2_ROCKET_SPEED, tr.speed, tr.sigma_speed, "speed (planet-relative) [m/s]"),
            (layout.POST2_ROCKET_DOWNRANGE, tr.downrange, tr.sigma_downrange, "downrange from the pad [m]"),
            (layout.POST2_ROCKET_EAST, tr.enu[:, 0], tr.sigma_enu[:, 0], "east of the pad [m]"),
            (layout.POST2_ROCKET_NORTH, tr.enu[:, 1], tr.sigma_enu[:, 1], "north of the pad [m]"),
            (layout.POST2_ROCKET_UP, tr.enu[:, 2], tr.sigma_enu[:, 2], "up from the pad (pad's axes) [m]"),
        )
        for root, v, sd, label in series:
            self.rec.series_with_bounds(root, res.t, v, sd, names=label, color=[EST])

    def _vehicle(self, res: Post2Result) -> None:
        """The vehicle at its smoothed pose (decimated to ≤ 2000 rows), with tilt and parachute."""
        g = self.geometry
        if not g.get("diameter_m"):
            return
        n = res.t.size
        sel = np.unique(np.linspace(0, n - 1, min(n, 2000)).astype(int))
        t = res.t[sel]
        rate = float(g.get("planet_rate_rad_s") or 0.0)
        self.rec.poses(layout.VEHICLE, t, res.smap.raw(res.x[sel], "position"), res.body_attitude(sel, rate))
        self.rec.points(layout.VEHICLE_MARKER, np.zeros((1, 3)), colors=(230, 60, 30, 255), radii=-5.0)
        q_tilt = res.tilt_rotation(sel)
        if q_tilt is not None:  # body drawn tilted by the estimated tilt
            self.rec.poses(layout.VEHICLE_BODY, t, np.zeros((t.size, 3)), q_tilt)
        m = vehicle_meshes(g["diameter_m"], g.get("parachute_diameter_m"), g.get("riser_m", 0.0))
        self._horizon(res, sel, m)
        self.rec.mesh(layout.POST2_FOREBODY, m["forebody"], color=(200, 120, 60, 255))
        self.rec.mesh(layout.POST2_BACK_SHELL, m["back_shell"], color=(220, 220, 225, 255))
        if "canopy" not in m:
            return
        s = self.rec.stream
        for te, name in self.events:
            opens = self.parachute_events.get(name)
            if opens is None:
                continue
            rr.set_time(layout.TIME, duration=float(te), recording=s)
            if opens:
                s.log(layout.POST2_PARACHUTE, mesh3d(m["canopy"], [230, 120, 40, 255]))
                s.log(
                    layout.POST2_RISERS,
                    rr.LineStrips3D([[[0.0, 0.0, 0.0], e] for e in m["riser_ends"]], colors=[[120, 120, 120]]),
                )
            else:
                s.log(layout.POST2_PARACHUTE, rr.Clear(recursive=False))
                s.log(layout.POST2_RISERS, rr.Clear(recursive=False))

    def _horizon(self, res: Post2Result, sel: np.ndarray, meshes: dict) -> None:
        """The references that make the attitude readable in the Vehicle view (origin at the vehicle,
        so its axes are the body's): the local horizontal as a grid under the vehicle with its north
        and east edges labelled, and the planet-relative velocity v − ω × r (ω about +Z,
        ``geometry["planet_rate_rad_s"]``) as an arrow of fixed length, both rotated into the body
        frame at each of the grid rows ``sel``; sized on the vehicle and its parachute."""
        g = self.geometry
        d = float(g["diameter_m"])
        reach = max(2.0 * d, float(g.get("riser_m") or 0.0) + 0.5 * float(g.get("parachute_diameter_m") or 0.0))
        t = res.t[sel]
        p = np.asarray(res.smap.raw(res.x[sel], "position"), dtype=float)
        v = np.asarray(res.smap.raw(res.x[sel], "velocity"), dtype=float)
        w = float(g.get("planet_rate_rad_s") or 0.0)
        q_I_B = res.body_attitude(sel, w)
        self.rec.poses(layout.POST2_HORIZON, t, np.zeros((t.size, 3)), local_level_in_body(p, q_I_B))
        below = 0.6 * reach
        self.rec.line_strip(
            layout.join(layout.POST2_HORIZON, layout.GRID),
            horizon_grid(reach, below),
            color=(110, 140, 110, 150),
            radius=-0.6,
        )
        self.rec.stream.log(
            layout.join(layout.POST2_HORIZON, layout.LABELS),
            rr.Points3D(
                [[0.0, reach, -below], [reach, 0.0, -below]],
                labels=["N (local horizontal)", "E"],
                colors=[[70, 110, 70]],
                radii=[-3.0],
                show_labels=True,
            ),
            static=True,
        )
        v_rel = v - np.stack([-w * p[:, 1], w * p[:, 0], np.zeros(len(p))], axis=-1)
        speed = np.linalg.norm(v_rel, axis=1, keepdims=True)
        v_B = np.einsum("nji,nj->ni", quat_to_dcm(q_I_B), v_rel / np.where(speed > 0.0, speed, 1.0))
        self.rec.arrows_series(
            layout.POST2_VELOCITY_ARROW,
            t,
            1.5 * reach * v_B,  # long: its label (at the middle) clear of the capsule
            color=(20, 90, 200, 255),
            radius=-2.5,
            label="velocity (planet-relative)",
        )

    def finish(self, result: object, summary: dict) -> None:
        """Write the scorecard (headed by the verdict block), the health verdict and the key moments,
        then the recording's one layout (default and active), its trajectory camera on the track."""
        from workbench.problems.drawer import verdict_block

        self.rec.report(verdict_block(summary) + PLOT_KEY_MD + self.scorecard(summary))
        if "health" in summary:
            self.rec.health(summary["health"])
        log_key_moments(self.rec, summary.get("key_moments", []))
        if self.layout is not None:
            eye = None if self.track is None else trajectory_eye(self.track)
            y_ranges = {
                o: y for o, (lo, hi) in self.y_ranges.items() if (y := y_range_if_needed(lo, hi, VIEW_PX)) is not None
            }
            bp = self.layout(eye, span=self.span, spans=self.spans, y_ranges=y_ranges)
            self.rec.stream.send_blueprint(bp, make_active=True, make_default=True)


def post2_blueprint(
    state_names: list[str],
    observation_names: list[str],
    has_truth: bool,
    *,
    sizes: dict[str, int] | None = None,
    residual_components: dict[str, tuple[str, ...]] | None = None,
    schedules: list[str] | None = None,
    has_events: bool = False,
    observation_units: dict[str, str] | None = None,
    vehicle: bool = True,
    rocket_span: tuple[float, float] | None = None,
    trajectory_eye: rrb.EyeControls3D | None = None,
    span: tuple[float, float] | None = None,
    spans: dict[str, tuple[float, float]] | None = None,
    y_ranges: dict[str, tuple[float, float]] | None = None,
):
    """The default layout: left, 3D tabs "Trajectory" (the tracks, `/world`) and, when ``vehicle`` (a
    vehicle is drawn: the problem file gives its diameter), "Vehicle" (origin the local level frame
    at the vehicle, `/world/vehicle/horizon`, showing `/world/vehicle`:
    capsule, parachute, tilt; without a vehicle that view would be empty); right, one tab per
    estimated state with a grid of one view per component (value, ±3σ, truth; position and velocity
    as errors against the truth when it is known), the phases and the weight schedule, one residual
    tab per observation (a view per component: residual with ±3σ), the scorecard; the event log under
    the 3D views.
    Every plot's name states its quantity and unit (the display unit of the state;
    ``observation_units`` {observation: SI unit} for the residuals) and nothing more, so that it
    shows whole in a grid cell (three cells across the right column of a 1400 px window leave each
    title about 22 characters); the colours are named once, in the scorecard's plot key
    (:data:`PLOT_KEY_MD`; legends off: they covered the data).

    A rocket flight (``[launch]``; ``rocket_span`` (t0, t1) [s] its reconstructed span, the x range
    of its views) opens on its results in the pad's frame instead: left, the tab "Rocket (pad frame)"
    (altitude above the pad, with vertical speed and speed below) before the 3D tabs; right, "pad ENU
    position" (east, north, up, downrange) before the state tabs. ``trajectory_eye``: the Trajectory
    view's camera (:func:`trajectory_eye`; None: the viewer's own); its grid (at the planet's
    centre, far from the track) is off. ``span`` (t0, t1) [s]: the run's grid, on which the state,
    phase, schedule and residual views open their x axis (else the viewer opens a run of hours on a
    minute around the time cursor); ``spans`` {view origin: (t0, t1)} [s] a view's own span (an
    observation's residuals: the phase it is measured in), ``y_ranges`` {view origin: (lo, hi)} a
    view's y range (:meth:`Post2Drawer.view_range`; else the viewer's fit, which labels a short view
    at one or two ticks)."""
    spans, y_ranges = spans or {}, y_ranges or {}

    def view(name: str, origin: str):
        return plot_view(name, origin, span=spans.get(origin, span), y_range=y_ranges.get(origin))

    sizes = sizes or {}
    rc = residual_components or {}
    ou = observation_units or {}
    tabs = []
    for n in state_names:
        shown = f"{n}_error" if has_truth and n in ("position", "velocity") else n
        unit = _display(STATES[n].unit)[0] if n in STATES else "-"
        comps = _components(n, sizes.get(n, STATES[n].size if n in STATES else 1))
        views = [view(f"{shown}.{c} [{unit or '-'}]", layout.plot_path(f"{shown}/{c}")) for c in comps]
        tabs.append(tab(f"{shown} [{unit or '-'}]", views[0]) if len(views) == 1 else rrb.Grid(*views, name=shown))
    if has_events:
        tabs.append(tab("phases", plot_view("phase index [-]", layout.POST2_PHASE, span=span)))
    for n in schedules or []:
        tabs.append(
            tab(
                f"{n} schedule",
                plot_view(f"{n} weight factor [-]", layout.plot_path(f"schedule/{n}_weight_factor"), span=span),
            )
        )
    res = []
    for n in observation_names:
        comps = rc.get(n)
        unit = _display(ou[n])[0] if n in ou else "as logged"
        if not comps:
            res.append(tab(n, view(f"{n} [{unit}] residual", layout.residual_path(n))))
            continue
        # component and unit first: a grid cell shows ~22 characters, the tab names the observation
        views = [view(f"{c} [{unit}] — {n} residual", layout.residual_path(n, c)) for c in comps]
        res.append(tab(n, views[0]) if len(views) == 1 else rrb.Grid(*views, name=f"{n} residuals"))
    # the horizon and the velocity arrow (metres, with labels) belong to the Vehicle view: at trajectory
    # scale their labels sat on the vehicle marker
    at_vehicle = [f"- {layout.POST2_HORIZON}/**", f"- {layout.POST2_VELOCITY_ARROW}"]
    scene_views = [
        rrb.Spatial3DView(
            name="Trajectory",
            origin=layout.WORLD,
            contents=["+ $origin/**", *at_vehicle],
            eye_controls=trajectory_eye,
            line_grid=False,
        )
    ]
    if vehicle:
        scene_views.append(
            rrb.Spatial3DView(
                name="Vehicle",
                # the local level frame at the vehicle (east, north, up): the horizon grid lies flat,
                # the viewer's up is the local vertical, and the body turns against them
                origin=layout.POST2_HORIZON,
                contents=[f"+ {layout.VEHICLE}/**", "- " + layout.VEHICLE_MARKER],
                line_grid=False,  # the horizon grid (under the vehicle, north and east labelled) instead
            )
        )
    if rocket_span is not None:
        band, w = "blue estimate, grey ±3σ", rocket_span
        local = rrb.Vertical(
            plot_view(f"altitude above the pad [m] — {band}", layout.POST2_ROCKET_ALTITUDE, window=w),
            rrb.Horizontal(
                plot_view(f"vertical speed, up + [m/s] — {band}", layout.POST2_ROCKET_VERTICAL_SPEED, window=w),
                plot_view(f"speed, planet-relative [m/s] — {band}", layout.POST2_ROCKET_SPEED, window=w),
            ),
            name="Rocket (pad frame)",
            row_shares=[3.0, 2.0],
        )
        scene_views.insert(0, local)
        enu = [
            plot_view(f"{what} [m] — {band}", root, window=w)
            for what, root in (
                ("east of the pad", layout.POST2_ROCKET_EAST),
                ("north of the pad", layout.POST2_ROCKET_NORTH),
                ("up, the pad's axes", layout.POST2_ROCKET_UP),
                ("downrange from the pad", layout.POST2_ROCKET_DOWNRANGE),
            )
        ]
        tabs.insert(0, rrb.Grid(*enu, grid_columns=2, name="pad ENU position [m]"))
    scenes = rrb.Tabs(*scene_views, active_tab=0)
    right = [rrb.Tabs(*tabs, active_tab=0)]
    if res:
        right.append(rrb.Tabs(*res, active_tab=0))
    right.append(report_view("Report"))
    # the state and residual views tall enough for two or three y labels (the axis labels decades: a
    # residual view a fifth of the column high showed one in a 1400 x 900 window), so the event log
    # sits under the 3D views, tall enough for a few rows (at a seventh of the column it showed one)
    shares = [2.6] + ([2.4] if res else []) + [1.6]
    left = rrb.Vertical(scenes, events_view(), row_shares=[3.0, 1.0])
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*right, row_shares=shares), column_shares=[2, 3]),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
    )


@contextlib.contextmanager
def open_post2_recording(
    path: Path,
    name: str,
    truth,
    properties: dict,
    scorecard,
    *,
    states=(),
    observations=(),
    sizes=None,
    residual_components=None,
    observation_units=None,
    schedules=(),
    geometry=None,
    parachute_events=None,
    has_events: bool = False,
    rocket_span: tuple[float, float] | None = None,
):
    """Open the recording (published atomically) and yield its :class:`Post2Drawer`.

    ``states`` / ``observations``: the problem file's estimated-state and observation names, for the
    default layout (:func:`post2_blueprint`, with ``sizes`` {state: size}, ``residual_components``
    {observation: names}, ``observation_units`` {observation: SI unit}, the observations a weight
    ``schedules`` touches, ``has_events``);
    ``geometry``, ``parachute_events``: see :class:`Post2Drawer`; ``rocket_span``: (t0, t1) [s]
    of a flight with a ``[launch]`` pad (its pad-frame views first, on that span). The layout is sent
    once, by :meth:`Post2Drawer.finish`."""

    def blueprint(eye, **views):
        return post2_blueprint(
            list(states),
            list(observations),
            truth is not None,
            sizes=sizes,
            residual_components=residual_components,
            observation_units=observation_units,
            schedules=list(schedules),
            has_events=has_events,
            vehicle=bool((geometry or {}).get("diameter_m")),  # as Post2Drawer._vehicle draws it
            rocket_span=rocket_span,
            trajectory_eye=eye,
            **views,
        )

    # opened without a layout: the one layout, with the camera fitted to the track, comes at the end
    with open_recording(path, name, properties=properties) as rec:
        yield Post2Drawer(rec, truth, scorecard, geometry, parachute_events, layout=blueprint)
