"""Draw the drop-test reconstruction stages into a Rerun recording (layout in docs/RECORDING.md).

The pipeline (:mod:`workbench.problems.droptest.pipeline`) yields stages; :class:`DropTestRecorder`
draws each one as it arrives and, for synthetic scenarios, the truth beside the estimate under
``/world/truth`` and ``.../truth`` series. Every entity path comes from
:mod:`workbench.recording.layout`; a stage type the recorder does not know is a ``TypeError``. All
geometry is in the SPF chamber frame (origin at the trigger nail, Z up, metres), which is local and
float32-safe.

What a reviewer scrubs through: the ramp and chamber axes; the lander body and airbag lobes moving
with the smoothed pose (truth pose beside it, translucent green); forward, smoothed and truth CM
tracks; the roll line; the stroke segment from the closest body point to the ramp with its value;
the 3σ position ellipsoid; triad measured vs predicted specific force; rates, quaternion and
1-2-3 Euler angles; stroke with ±1σ/±3σ; 1σ of every state; residuals with ±3σ bounds; events;
the scorecard.
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.core.bodies import G0
from workbench.core.rotation import euler123_from_quat, quat_conjugate, quat_rotate, quat_to_dcm
from workbench.estimation.consistency import chi2_ppf
from workbench.problems.droptest import model as rl
from workbench.problems.droptest.lander import airbag_mesh
from workbench.problems.droptest.pipeline import DropResult, DropTelemetry, FilterStage, InitialState, StrokeStage
from workbench.problems.droptest.stroke import contact_end
from workbench.problems.droptest.surface import ramp_mesh, rock_meshes
from workbench.recording import layout
from workbench.recording.blueprint import events_view, legible_range, plot_view, report_view, tab, y_range_if_needed
from workbench.recording.dispatch import StageDispatch
from workbench.recording.writer import PALETTE, Recorder

__all__ = [
    "DropTestRecorder",
    "airbags_at",
    "bounded_y_ranges",
    "droptest_blueprint",
    "impact_view",
    "max_stroke_dimension",
]

EST = (31, 119, 180, 255)
FWD = (255, 127, 14, 255)
TRUTH = (44, 160, 44, 255)
XYZ = [(214, 39, 40, 255), (44, 160, 44, 255), (31, 119, 180, 255)]
XYZW = XYZ + [(120, 120, 120, 255)]
#: the lander at the max-stroke pose (body, bags): grey, so it cannot be taken for the estimate
GHOST, GHOST_BAGS = (150, 150, 150, 110), (170, 170, 170, 25)
#: the stroke segment's colour at the closest approach and at the largest stroke
STROKE_NEAR, STROKE_FAR = (230, 0, 230, 255), (0, 200, 230, 255)
#: the stroke segments' line widths [screen points, as Rerun's negative radii]: the same at the
#: Impact view's metres and the Chamber view's whole drop
STROKE_WIDTH = -3.0
#: the max stroke's dimension line (and its extension lines) [screen points]
DIMENSION_WIDTH, EXTENSION_WIDTH = -5.0, -1.5
#: the dimension line's clearance outside the airbag lobes [m]
DIMENSION_CLEARANCE_M = 0.25
#: the Impact view's camera: distance [m] beyond the dimension line, elevation [deg] above the ramp
IMPACT_EYE_DISTANCE_M = 1.6
IMPACT_EYE_ELEVATION_DEG = 12.0

#: what the 3D scene shows (``layout.SCENE_KEY``, beside the 3D views)
SCENE_KEY_MD = (
    "**3D key** — lander (light grey) and airbags (orange, translucent): smoothed estimate · "
    "blue line: smoothed CM track · orange line: forward-pass track · magenta dots: accelerometer "
    "triads · magenta → cyan segment: stroke (closest body point to the ramp; magenta = closest) · "
    "grey ghost: lander at max stroke; thick magenta bar: its stroke in cm, in front of the airbags · "
    "purple line: roll line (CM path of a perfectly inelastic impact) · blue wireframe: 3σ position "
    "ellipsoid (inside the body while the pose is known to centimetres)"
)
SCENE_KEY_TRUTH_MD = " · green wireframe and line: truth body and CM track"


#: key of the red/green/blue (x/y/z) colours, for view names (legends off: they covered the data)
XYZ_KEY = "RGB = xyz"
BOUNDS_KEY = "±3σ grey, truth pale"
#: room right of the data in the NIS view for its legend, as a fraction of the run's span (the
#: legend, up to about 120 px wide, in a plot about 510 px wide in a 1400 x 900 window)
NIS_LEGEND_ROOM = 0.35
#: the height [CSS px] the zoomed stroke view is given at least (1400 x 900 window: about 190)
STROKE_VIEW_PX = 150.0

#: bounded per-axis series under a plot root: (root, tab title, unit, axis leaf names). The leaf is the
#: first word of each series name the recorder gives (``layout.join(root, leaf)``).
_BOUNDED = [
    (layout.DROPTEST_PLOT_POSITION, "position", "m", ("x", "y", "z")),
    (layout.DROPTEST_PLOT_VELOCITY, "velocity", "m/s", ("vx", "vy", "vz")),
    (layout.DROPTEST_PLOT_ACCEL_BODY, "accel body", "g", ("ax_B", "ay_B", "az_B")),
    (layout.DROPTEST_PLOT_RATE, "rate", "deg/s", ("p", "q", "r")),
    (layout.DROPTEST_PLOT_ANGULAR_ACCEL, "ang. accel", "rad/s²", ("αx", "αy", "αz")),
    (layout.DROPTEST_PLOT_GYRO_SCALE, "gyro scale", "%", ("sx", "sy", "sz")),
]
#: 1σ groups under ``/plots/sigma``: (leaf, title with unit); the labels the recorder gives
SIGMA_GROUPS = [
    ("position", "position [m]"),
    ("velocity", "velocity [m/s]"),
    ("accel", "accel [m/s²]"),
    ("attitude", "attitude [deg]"),
    ("rate", "rate [deg/s]"),
    ("ang", "ang. accel [rad/s²]"),
]


def _residual_unit(name: str, triads) -> str:
    """Unit of the innovation of measurement group ``name`` (SI, as the filter forms it)."""
    if name in triads:
        return "m/s²"
    if name == "gyro":
        return "rad/s"
    if name == "zupt" or name.endswith(".rate"):
        return "m/s"
    return "m"  # odometer, <gun>.range


def droptest_blueprint(
    residual_names: list[str],
    impact: dict | None = None,
    triads: tuple[str, ...] | list[str] = (),
    y_ranges: dict[str, tuple[float, float]] | None = None,
    zoom_y_ranges: dict[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """Default layout for stroke inspection.

    Left: the 3D scene as two tabs — "Impact", a camera beside the impact point that follows the
    lander, and "Chamber", the whole drop. Right: the stroke zoomed on the impact first, then the
    other plots; residual tabs; the scorecard and the events log. Every plot names its unit and
    explains its colours in its name (legends off: they covered a third of the data); bounded
    quantities are split per axis, each with the impact window beside the whole drop so the ±3σ
    band is visible.
    ``impact`` (known only after the reconstruction, :func:`impact_view`): ``eye``, ``look`` (3,)
    [m, SPF] the Impact view's camera position and look target and ``up`` (3,) its up axis,
    ``t0``/``t1`` [s] window of the impact, ``stroke_lo``/``stroke_hi`` [m] y-range of the zoomed
    stroke plot, ``span`` (t0, t1) [s] the filter grid's (the NIS view opens on it with
    :data:`NIS_LEGEND_ROOM` of it added right of the data, where its legend stands). Without it a
    generic layout is returned.
    ``triads``: accelerometer triad names (one measured-vs-predicted plot each).
    A bounded quantity's tab holds a tab per axis, the whole drop beside the impact zoom at full
    height (three axes stacked, each view was too low for more than one y label); without a zoom
    (the gyro scale factors) the axes stand side by side;
    ``y_ranges`` / ``zoom_y_ranges`` {view origin: (lo, hi)} fix the y axes of the whole-drop /
    impact views (:func:`bounded_y_ranges`).
    """
    yr, zyr = y_ranges or {}, zoom_y_ranges or {}
    scene_kw = {}
    stroke_kw = {}
    win = None
    if impact is not None:
        scene_kw["eye_controls"] = rrb.EyeControls3D(
            position=np.asarray(impact["eye"], float),
            look_target=np.asarray(impact["look"], float),
            eye_up=np.asarray(impact["up"], float),
        )
        win = (float(impact["t0"]), float(impact["t1"]))
        stroke_kw = {"y_range": (impact["stroke_lo"], impact["stroke_hi"]), "window": win}
    scenes = rrb.Vertical(
        rrb.Tabs(
            rrb.Spatial3DView(name="Impact", origin=layout.WORLD, **scene_kw),
            rrb.Spatial3DView(name="Chamber", origin=layout.WORLD),
            active_tab=0,
        ),
        rrb.TextDocumentView(name="3D key", origin=layout.SCENE_KEY, contents="$origin"),
        row_shares=[5, 1],
    )
    stroke_key = "blue smoothed, grey ±1σ ±3σ, orange fwd, green truth"
    plots: list = [
        tab("stroke at impact [m]", plot_view(f"stroke [m] — {stroke_key}", layout.DROPTEST_PLOT_STROKE, **stroke_kw)),
        tab("stroke [m]", plot_view(f"stroke, whole drop [m] — {stroke_key}", layout.DROPTEST_PLOT_STROKE)),
        tab("stroke 1σ [m]", plot_view("stroke 1σ [m] — blue smoothed, orange fwd", layout.DROPTEST_PLOT_STROKE_SIGMA)),
    ]
    for root, title, unit, leaves in _BOUNDED:
        axes = []
        for leaf in leaves:
            path = layout.join(root, leaf)
            full = plot_view(f"{leaf} [{unit}] — {BOUNDS_KEY}", path, y_range=yr.get(path))
            if win is None or root == layout.DROPTEST_PLOT_GYRO_SCALE:
                axes.append(full)
            else:
                zoom = plot_view(f"{leaf} at impact [{unit}]", path, window=win, y_range=zyr.get(path))
                axes.append(rrb.Horizontal(full, zoom, column_shares=[3, 2], name=leaf))
        if win is None or root == layout.DROPTEST_PLOT_GYRO_SCALE:
            plots.append(rrb.Horizontal(*axes, name=f"{title} [{unit}]"))
        else:
            plots.append(rrb.Tabs(*axes, active_tab=0, name=f"{title} [{unit}]"))
    plots += [
        tab("accel SPF [g]", plot_view(f"accel SPF [g] — {XYZ_KEY}; thin truth", layout.DROPTEST_PLOT_ACCEL_SPF)),
        tab(
            "quaternion [-]",
            plot_view(f"quaternion [-] — {XYZ_KEY}, grey w; thin truth", layout.DROPTEST_PLOT_QUATERNION),
        ),
        tab(
            "Euler 1-2-3 [deg]",
            plot_view("Euler 1-2-3 [deg] — red φ, green θ, blue ψ; thin truth", layout.DROPTEST_PLOT_EULER123),
        ),
        rrb.Grid(
            *[
                plot_view(f"1σ {title} — {XYZ_KEY}; thin fwd", layout.join(layout.DROPTEST_PLOT_SIGMA, leaf))
                for leaf, title in SIGMA_GROUPS
            ],
            grid_columns=2,
            name="1σ states",
        ),
    ]
    if triads:
        plots.append(
            rrb.Grid(
                *[
                    plot_view(
                        f"{tr} [g] — {XYZ_KEY} measured, black predicted",
                        layout.join(layout.DROPTEST_PLOT_TRIADS, tr),
                    )
                    for tr in triads
                ],
                grid_columns=2,
                name="triads [g]",
            )
        )
    else:
        key = "triads [g] — measured, black predicted"
        plots.append(tab("triads [g]", plot_view(key, layout.DROPTEST_PLOT_TRIADS, legend="LeftBottom")))
    # the NIS legend names one colour per sensor; over the data it hid the right end of the spikes,
    # so the x axis opens with room for it right of the data
    nis_span = None
    if impact is not None:
        t0, t1 = (float(v) for v in impact["span"])
        nis_span = (t0, t1 + NIS_LEGEND_ROOM * (t1 - t0))
    plots += [
        tab(
            "NIS [-]",
            plot_view(
                "NIS [-] — one series per sensor, grey χ² 99 % bound per dimension",
                layout.DROPTEST_PLOT_NIS,
                legend="RightTop",
                span=nis_span,
            ),
        ),
        tab(
            "process noise",
            plot_view(
                "process noise — blue q_accel [m²/s⁵], orange q_angular [rad²/s⁵]", layout.DROPTEST_PLOT_PROCESS_NOISE
            ),
        ),
    ]
    residuals = []
    for nm in residual_names:
        unit = _residual_unit(nm, triads)
        key = f"{XYZ_KEY}, grey ±3σ" if nm in triads or nm in ("gyro", "zupt") else "grey ±3σ"
        full = plot_view(f"{nm} [{unit}] — {key}", layout.residual_path(nm))
        if win is None or nm in ("zupt", "odometer"):  # measured only before the drop / until the cut
            residuals.append(tab(nm, full))
        else:
            zoom = plot_view(f"{nm} at impact [{unit}]", layout.residual_path(nm), window=win)
            residuals.append(rrb.Horizontal(full, zoom, column_shares=[3, 2], name=nm))
    right = rrb.Vertical(
        rrb.Tabs(*plots, active_tab=0),
        rrb.Tabs(*residuals, active_tab=0),
        report_view("Scorecard", extra=[events_view()]),
        # residuals tall enough for two or three y labels (the axis labels decades: at 2 of 7 a
        # 1400 x 900 window showed only "0"); the scorecard keeps its verdict lines
        row_shares=[3, 2.8, 1.7],
    )
    return rrb.Blueprint(
        rrb.Horizontal(scenes, right, column_shares=[3, 2]),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
    )


#: the height [CSS px] of a bounded quantity's view (a 1400 x 900 window: about 220)
BOUNDED_VIEW_PX = 200.0


def bounded_y_ranges(rec, impact: dict | None) -> tuple[dict, dict]:
    """The y ranges of the bounded quantities' views of :func:`droptest_blueprint` whose data (what
    ``rec``, the run's :class:`~workbench.recording.writer.Recorder`, drew: the whole drop, and
    between ``impact["t0"]`` and ``impact["t1"]`` [s] for the zoom) the viewer would label at fewer
    than three ticks (``blueprint.y_range_if_needed``): ``({origin: (lo, hi)}, {origin: (lo, hi)})``
    for the whole-drop and the impact views."""
    whole, zoom = {}, {}
    for root, _, _, leaves in _BOUNDED:
        for leaf in leaves:
            path = layout.join(root, leaf)
            windows = [(whole, None, None)]
            if impact is not None and root != layout.DROPTEST_PLOT_GYRO_SCALE:
                windows.append((zoom, float(impact["t0"]), float(impact["t1"])))
            for out, t0, t1 in windows:
                r = rec.value_range(path, t0, t1)
                if r is not None and r[1] > r[0] and (y := y_range_if_needed(r[0], r[1], BOUNDED_VIEW_PX)):
                    out[path] = y
    return whole, zoom


def max_stroke_dimension(
    closest: np.ndarray, foot: np.ndarray, normal: np.ndarray, bags: np.ndarray, cm: np.ndarray
) -> dict[str, np.ndarray]:
    """Where the max stroke is drawn in front of the airbags, and the Impact view's camera that reads it.

    The stroke segment runs from the body's ``closest`` point to its ``foot`` on the ramp (both (3,)
    [m, SPF]) inside the airbag lobes, whose translucent layers hid it. The camera looks at it across
    the ramp (normal to the segment and to the chamber's x axis, from the side where the lobes end
    sooner; the lander slides along the ramp, past the camera's side rather than through it),
    :data:`IMPACT_EYE_ELEVATION_DEG` above the ramp (``normal`` (3,), towards the free side), with the
    ramp normal ``up`` on screen, so the ramp reads as the ground and the stroke as a vertical bar.
    Its copy, the dimension line ``a`` → ``b``, is moved towards the camera along the view direction
    ``side`` (unit) by ``offset`` [m], to :data:`DIMENSION_CLEARANCE_M` beyond every point of ``bags``
    ((k, 3) [m, SPF], the lobes at the max-stroke pose): on screen it covers the segment, in front of
    the lobes; extension lines join its ends to the real ones. ``eye`` is
    :data:`IMPACT_EYE_DISTANCE_M` beyond it, ``look`` halfway from the segment to the CM ``cm`` (3,)
    [m, SPF]; ``label`` (3,) [m] beside the line's middle, on the side away from the CM.
    """
    c, f = np.asarray(closest, float), np.asarray(foot, float)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    seg = f - c
    u = seg / np.linalg.norm(seg) if np.linalg.norm(seg) > 1e-9 else -n
    # across the ramp: the chamber's x axis made normal to the segment (the y axis if x is along it)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    across = ref - (ref @ u) * u
    across /= np.linalg.norm(across)
    e = np.radians(IMPACT_EYE_ELEVATION_DEG)
    reach = np.asarray(bags, float).reshape(-1, 3) - c
    views = [np.cos(e) * sgn * across + np.sin(e) * n for sgn in (1.0, -1.0)]
    ends = [float(np.max(reach @ d)) for d in views]
    k = int(np.argmin(ends))
    d = views[k] / np.linalg.norm(views[k])
    offset = max(ends[k], 0.0) + DIMENSION_CLEARANCE_M
    a, b = c + offset * d, f + offset * d
    mid = 0.5 * (c + f)
    v = np.cross(u, d)
    v /= np.linalg.norm(v)
    v = v if v @ (np.asarray(cm, float) - c) <= 0.0 else -v
    return {
        "a": a,
        "b": b,
        "side": d,
        "offset": np.float64(offset),
        "label": 0.5 * (a + b) + 0.45 * v,
        "eye": mid + (offset + IMPACT_EYE_DISTANCE_M) * d,
        "look": mid + 0.5 * (np.asarray(cm, float) - mid),
        "up": n,
    }


def airbags_at(lander, x: np.ndarray) -> np.ndarray:
    """The airbag lobes' mesh vertices (k, 3) [m, SPF] of the ``lander`` model at the pose of the
    filter state ``x`` (N_X,) (CM position [m, SPF] and attitude q_I_B, xyzw)."""
    v = np.asarray(airbag_mesh(lander, subdivisions=1).vertices, float)
    return x[rl.SP] + quat_rotate(x[rl.SQ], v)


def impact_view(result) -> dict:
    """Camera and zoom settings of :func:`droptest_blueprint` from a ``DropResult``: the Impact
    view's ``eye``, ``look`` and ``up`` (:func:`max_stroke_dimension`), the filter grid's ``span``
    and the impact window ``t0``/``t1`` [s], the stroke zoom's ``stroke_lo``/``stroke_hi`` [m]."""
    st = result.stroke
    smo = result.smoothed
    i0, i1 = st.contact
    if i0 < 0:
        i0 = i1 = int(st.max.index)
    h = st.smoothed
    # the max stroke with its ±3σ band and 0.1 m above, down to the ramp (0), widened to labelled
    # ticks (a span a little above 1 m is labelled at 0 and 1 only in a short view)
    lo, hi = legible_range(
        min(0.0, st.max.distance - 3.5 * st.max.sigma),
        st.max.distance + 4.0 * st.max.sigma + 0.1,
        min_px=STROKE_VIEW_PX,
    )
    k = int(st.max.index)
    dim = max_stroke_dimension(
        h.closest_point_I[k], h.surface_point_I[k], st.surface.normal, airbags_at(st.lander, smo.x[k]), smo.x[k, rl.SP]
    )
    return {
        "eye": dim["eye"],
        "look": dim["look"],
        "up": dim["up"],
        "span": (float(smo.t[0]), float(smo.t[-1])),
        "t0": float(smo.t[i0]) - 0.15,
        "t1": contact_end(smo.t, (i0, i1), st.restitution_index[1]) + 0.25,  # past the restitution's leaving
        "stroke_lo": lo,
        "stroke_hi": hi,
    }


def _stroke_text(d: float, s: float) -> str:
    """The stroke label: ``d`` ± ``s`` [m] (1σ) in cm below 1 m (the impact), else in m."""
    if abs(d) < 1.0:
        return f"stroke {100 * d:.1f} ± {100 * s:.1f} cm (1σ)"
    return f"stroke {d:.3f} ± {s:.3f} m (1σ)"


def _wrap_pi(a: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped into [−π, π)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


class DropTestRecorder:
    """Observer of the drop-test stages; ``truth`` is the dict of ``load_truth`` or None."""

    def __init__(self, rec: Recorder, truth: dict | None = None):
        self.rec = rec
        self.truth = truth
        self.tel = None
        self._fwd_t = None  # the forward pass's times and 1σ (n, n_e): what later stages draw of it
        self._fwd_sd = None
        self._smoothed_x = None
        self.dispatch = StageDispatch(
            {
                DropTelemetry: self._on_telemetry,
                InitialState: self._on_initial_state,
                FilterStage: self._on_filter,
                StrokeStage: self._on_stroke,
            },
            ignored=(DropResult,),  # the final bundle: everything in it was drawn stage by stage
        )

    # ---------------------------------------------------------------- dispatch
    def handle(self, stage) -> None:
        """Draw one stage of ``workbench.problems.droptest.pipeline.reconstruct``; a stage of a type
        the recorder does not know is a ``TypeError`` (see :class:`~workbench.recording.dispatch.StageDispatch`)."""
        self.dispatch(stage)

    # ---------------------------------------------------------------- stages
    def _on_telemetry(self, tel) -> None:
        self.tel = tel
        r = self.rec
        r.view_coordinates(layout.WORLD)
        r.axes(layout.DROPTEST_CHAMBER_AXES, 1.0)
        t = tel.imu.time
        for name in tel.triads:
            r.scalars(
                layout.sensor_path(name),
                t,
                tel.imu.stack([f"{name}.{a}" for a in "xyz"]) / G0,
                names=[f"{name}.{a} [g]" for a in "xyz"],
                colors=XYZ,
            )
        r.scalars(
            layout.DROPTEST_SENSOR_GYRO,
            t,
            np.degrees(tel.imu.stack(["gyro.x", "gyro.y", "gyro.z"])),
            names=[f"gyro.{a} [deg/s]" for a in "xyz"],
            colors=XYZ,
        )
        if tel.ranging is not None:
            for ch in tel.ranging.names:
                tt, vv = tel.ranging.samples(ch)
                if tt.size:
                    r.scatter(
                        layout.droptest_ranging_sensor_path(ch),
                        tt,
                        vv,
                        names=ch,
                        colors=[(148, 103, 189, 255)],
                        size=1.5,
                    )
        entries = [(t_e, f"{name} (from the events file)", "INFO") for name, t_e in tel.events.items()]
        entries += [(t_d, txt, lvl) for t_d, lvl, txt in tel.degradations]
        r.events(sorted(entries))

    def _on_initial_state(self, init) -> None:
        r = self.rec
        s = np.degrees(np.sqrt(np.diag(init.P_theta)))
        r.events(
            [
                (
                    float(self.tel.t[0]),
                    f"3DM TRIAD attitude: 1σ body x/y/z = {s[0]:.2f}/{s[1]:.2f}/{s[2]:.2f} deg",
                    "INFO",
                )
            ]
        )

    def _on_filter(self, st) -> None:
        if st.name == "forward":
            self._fwd_t, self._fwd_sd = st.t, np.sqrt(np.einsum("nii->ni", st.P))  # not the stage: its histories
            self._forward(st)
        else:
            self._smoothed(st)

    def _forward(self, st) -> None:
        r = self.rec
        t = st.t
        step = np.arange(t.size)
        r.line_strip(layout.ESTIMATE_FORWARD, st.x[:, rl.SP], color=FWD, radius=0.01)
        fp = st.forward
        dofs: set[int] = set()
        for k, (name, ih) in enumerate(fp.innovations.items()):
            m = ih.step  # grid steps of the samples
            if not m.size:
                continue
            y = ih.y
            sig = np.sqrt(np.einsum("nii->ni", ih.S))
            labels = ("x", "y", "z") if y.shape[1] == 3 else ("value",)
            for i, lab in enumerate(labels):
                root = layout.residual_path(name, lab) if y.shape[1] > 1 else layout.residual_path(name)
                # innovation with its ±3√S bounds about zero (children value, plus_3sigma, minus_3sigma)
                r.scalars(
                    layout.join(root, layout.VALUE),
                    t[m],
                    y[:, i],
                    step=step[m],
                    names=f"{name}.{lab} innovation",
                    colors=[XYZ[i % 3]],
                    widths=1.0,
                )
                for sign, bname in zip((1.0, -1.0), layout.bound_names(3.0), strict=True):
                    r.scalars(
                        layout.join(root, bname),
                        t[m],
                        sign * 3.0 * sig[:, i],
                        step=step[m],
                        names=f"{'+' if sign > 0 else '−'}3σ",
                        colors=[(150, 150, 150, 255)],
                        widths=0.8,
                    )
            # one palette colour per sensor (the viewer's own, by path, gave gyro, PXBP and PYBP one magenta)
            r.scalars(
                layout.droptest_nis_path(name),
                t[m],
                ih.nis,
                step=step[m],
                names=f"NIS {name}",
                colors=[PALETTE[k % len(PALETTE)]],
            )
            dofs.add(int(ih.y.shape[1]))
        # the χ² 99 % bound of each innovation dimension: a NIS above it is a 1 % event per sample
        for dof in sorted(dofs):
            r.scalars(
                layout.droptest_nis_path(f"chi2_{dof}dof_99"),
                t[[0, -1]],
                np.full(2, chi2_ppf(0.99, dof)),
                step=step[[0, -1]],
                names=f"χ²({dof}) 99 %",
                colors=[(90, 90, 90, 255)],
                widths=1.5,
            )
        # measured vs predicted specific force at each triad (prediction from the prior state)
        tel = self.tel
        for j, name in enumerate(tel.triads):
            ok = tel.f_valid[:, j]
            if not ok.any():  # a triad excluded from the reconstruction (dead): nothing to draw
                continue
            pred = rl.triad_specific_force(fp.x_prior[ok], tel.lever_arms_B[j], j)
            r.scalars(
                layout.droptest_triad_plot_path(name, layout.MEASURED_SERIES),
                t[ok],
                tel.f_B[ok, j] / G0,
                names=[f"{name}.{a} measured [g]" for a in "xyz"],
                colors=XYZ,
                widths=1.0,
            )
            r.scalars(
                layout.droptest_triad_plot_path(name, layout.PREDICTED_SERIES),
                t[ok],
                pred / G0,
                names=[f"{name}.{a} predicted [g]" for a in "xyz"],
                colors=[(0, 0, 0, 255)] * 3,
                widths=0.8,
            )
        r.scalars(
            layout.DROPTEST_PLOT_PROCESS_NOISE,
            t,
            np.stack([st.q_accel, st.q_angular], 1),
            step=step,
            names=["q_accel [m²/s⁵]", "q_angular [rad²/s⁵]"],
            colors=[EST, FWD],
        )

    def _smoothed(self, st) -> None:
        r = self.rec
        t = st.t
        step = np.arange(t.size)
        x, P = st.x, st.P
        self._smoothed_x = x
        tg = None
        if self.truth is not None:
            from workbench.problems.droptest.pipeline import truth_on_grid

            tg = truth_on_grid(self.truth, t)
        sd = np.sqrt(np.einsum("nii->ni", P))
        p, q = x[:, rl.SP], x[:, rl.SQ]
        r.poses(layout.VEHICLE, t, p, q, step=step)
        r.line_strip(layout.ESTIMATE_SMOOTHED, p, color=EST, radius=0.012)
        # 3σ position ellipsoid, expressed in the body frame so it can live under the vehicle
        C = quat_to_dcm(q)
        P_B = np.swapaxes(C, 1, 2) @ P[:, rl.EP, rl.EP] @ C
        r.ellipsoids(layout.UNCERTAINTY, t, np.zeros((t.size, 3)), P_B, nsigma=3.0, color=(31, 119, 180, 90), step=step)
        aI = rl.accel_inertial(x)
        series = [
            (layout.DROPTEST_PLOT_POSITION, p, sd[:, rl.EP], None if tg is None else tg["p_I"], ["x", "y", "z"], 1.0),
            (
                layout.DROPTEST_PLOT_VELOCITY,
                x[:, rl.SV],
                sd[:, rl.EV],
                None if tg is None else tg["v_I"],
                ["vx", "vy", "vz"],
                1.0,
            ),
            (
                layout.DROPTEST_PLOT_ACCEL_BODY,
                x[:, rl.SA] / G0,
                sd[:, rl.EA] / G0,
                None if tg is None else quat_rotate(quat_conjugate(tg["q_I_B"]), tg["a_ng_I"]) / G0,
                ["ax_B [g]", "ay_B [g]", "az_B [g]"],
                1.0,
            ),
            (
                layout.DROPTEST_PLOT_RATE,
                np.degrees(x[:, rl.SW]),
                np.degrees(sd[:, rl.EW]),
                None if tg is None else np.degrees(tg["w_B"]),
                ["p [deg/s]", "q [deg/s]", "r [deg/s]"],
                1.0,
            ),
            (layout.DROPTEST_PLOT_ANGULAR_ACCEL, x[:, rl.SAL], sd[:, rl.EAL], None, ["αx", "αy", "αz"], 1.0),
            (
                layout.DROPTEST_PLOT_GYRO_SCALE,
                100 * x[:, rl.GYRO_SCALE_X],
                100 * sd[:, rl.GYRO_SCALE_E],
                None if self.truth is None else np.broadcast_to(100 * self.truth["gyro_scale"], (t.size, 3)),
                ["sx [%]", "sy [%]", "sz [%]"],
                1.0,
            ),
        ]
        for root, v, s, tr, names, _ in series:
            for i, nm in enumerate(names):
                r.series_with_bounds(
                    layout.join(root, nm.split(" ")[0]),
                    t,
                    v[:, i],
                    s[:, i],
                    truth=None if tr is None else tr[:, i],
                    names=nm,
                    step=step,
                    color=[XYZ[i]],
                )
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_ACCEL_SPF, layout.VALUE),
            t,
            aI / G0,
            step=step,
            names=["ax [g]", "ay [g]", "az [g]"],
            colors=XYZ,
        )
        if tg is not None:
            r.scalars(
                layout.join(layout.DROPTEST_PLOT_ACCEL_SPF, layout.TRUTH_SERIES),
                t,
                tg["a_ng_I"] / G0,
                step=step,
                names=["ax truth [g]", "ay truth [g]", "az truth [g]"],
                colors=XYZ,
                widths=0.6,
            )
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_QUATERNION, layout.VALUE),
            t,
            q,
            step=step,
            names=["qx", "qy", "qz", "qw"],
            colors=XYZW,
        )
        eul = np.degrees(np.unwrap(euler123_from_quat(q), axis=0))
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_EULER123, layout.VALUE),
            t,
            eul,
            step=step,
            names=["φ [deg]", "θ [deg]", "ψ [deg]"],
            colors=XYZ,
        )
        if tg is not None:
            qt = tg["q_I_B"] * np.sign(np.sum(tg["q_I_B"] * q, axis=1))[:, None]
            r.scalars(
                layout.join(layout.DROPTEST_PLOT_QUATERNION, layout.TRUTH_SERIES),
                t,
                qt,
                step=step,
                names=["qx truth", "qy truth", "qz truth", "qw truth"],
                colors=XYZW,
                widths=0.6,
            )
            r.scalars(
                layout.join(layout.DROPTEST_PLOT_EULER123, layout.TRUTH_SERIES),
                t,
                # on the estimate's branch: each angle within ±180° of the estimate's (unwrapped
                # separately, −180° and +180° of one attitude looked like a 360° error)
                eul + np.degrees(_wrap_pi(euler123_from_quat(tg["q_I_B"]) - np.radians(eul))),
                step=step,
                names=["φ truth", "θ truth", "ψ truth"],
                colors=XYZ,
                widths=0.6,
            )
        # 1σ of every state (REDLand Fig. 14), forward and smoothed
        groups = [
            ("position [m]", rl.EP, 1.0),
            ("velocity [m/s]", rl.EV, 1.0),
            ("accel [m/s²]", rl.EA, 1.0),
            ("attitude [deg]", rl.ETH, np.degrees(1.0)),
            ("rate [deg/s]", rl.EW, np.degrees(1.0)),
            ("ang. accel [rad/s²]", rl.EAL, 1.0),
        ]
        sdf = self._fwd_sd
        for label, sl, k in groups:
            key = label.split(" ")[0].replace(".", "")
            for series, sigma, tag, style in (
                (layout.SMOOTHED_SERIES, sd, "", {}),
                (layout.FORWARD_SERIES, sdf, " (forward)", {"widths": 0.6}),
            ):
                if sigma is not None:
                    r.scalars(
                        layout.droptest_sigma_path(key, series),
                        t,
                        sigma[:, sl] * k,
                        step=step,
                        names=[f"σ{a} {label}{tag}" for a in "xyz"],
                        colors=XYZ,
                        **style,
                    )

    def _on_stroke(self, st) -> None:
        r = self.rec
        lander, surf = st.lander, st.surface
        t = self._fwd_t
        step = np.arange(t.size)
        h = st.smoothed
        r.mesh(
            layout.SURFACE,
            ramp_mesh(surf, width=12.0, length_down=8.0, length_up=10.0),
            color=(170, 150, 130, 255),
        )
        if surf.n_rocks:
            r.mesh(layout.DROPTEST_ROCKS, rock_meshes(surf), color=(90, 80, 75, 255))
        r.mesh(layout.VEHICLE_BODY, lander.body, color=(200, 200, 210, 255))
        r.mesh(layout.AIRBAGS, airbag_mesh(lander, subdivisions=2), color=(255, 200, 60, 30))
        r.points(
            layout.DROPTEST_TRIADS,
            np.array([lander.instruments[n] for n in self.tel.triads]),
            colors=(255, 0, 255, 255),
            radii=0.03,
        )
        # stroke segment: closest body point -> its foot on the ramp, magenta near to cyan far (neither
        # is a colour of the bags, the ramp or the tracks), thick enough to read through the lobes
        seg = np.stack([h.closest_point_I, h.surface_point_I], axis=1)[:, None]
        frac = np.clip(h.distance / max(1e-3, float(np.max(h.distance[t >= 0]))), 0.0, 1.0)[:, None]
        cols = (1.0 - frac) * np.array(STROKE_NEAR, float) + frac * np.array(STROKE_FAR, float)
        r.line_strips_series(
            layout.STROKE, t, seg, colors=cols.astype(np.uint8)[:, None], radii=STROKE_WIDTH, step=step
        )
        r.report(SCENE_KEY_MD + ("" if self.truth is None else SCENE_KEY_TRUTH_MD), entity=layout.SCENE_KEY)
        # the label 0.6 m off the closest point, along the ramp normal: on the point it hid the segment
        r.text_labels_series(
            layout.DROPTEST_STROKE_LABEL,
            t,
            (h.closest_point_I + 0.6 * np.asarray(surf.normal, float))[:, None],
            [[_stroke_text(d, s)] for d, s in zip(h.distance, h.sigma, strict=True)],
            step=step,
        )
        # stroke plot with ±1σ and ±3σ, forward pass and truth
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_STROKE, layout.VALUE),
            t,
            h.distance,
            step=step,
            names="stroke (smoothed) [m]",
            colors=[EST],
            widths=2.0,
        )
        for k, w in ((1, 1.0), (3, 0.6)):
            plus, minus = layout.bound_names(k)
            r.scalars(
                layout.join(layout.DROPTEST_PLOT_STROKE, plus),
                t,
                h.distance + k * h.sigma,
                step=step,
                names=f"+{k}σ",
                colors=[(150, 150, 150, 255)],
                widths=w,
            )
            r.scalars(
                layout.join(layout.DROPTEST_PLOT_STROKE, minus),
                t,
                h.distance - k * h.sigma,
                step=step,
                names=f"−{k}σ",
                colors=[(150, 150, 150, 255)],
                widths=w,
            )
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_STROKE, layout.FORWARD_SERIES),
            t,
            st.forward.distance,
            step=step,
            names="stroke (forward) [m]",
            colors=[FWD],
            widths=1.0,
        )
        r.scalars(
            layout.DROPTEST_PLOT_STROKE_SIGMA,
            t,
            np.stack([h.sigma, st.forward.sigma], 1),
            step=step,
            names=["1σ smoothed [m]", "1σ forward [m]"],
            colors=[EST, FWD],
        )
        # roll line: would-be CM path in a perfectly inelastic collision (normal velocity removed)
        i0, i1 = st.contact
        if i0 >= 0 and self._smoothed_x is not None:
            from workbench.problems.droptest.pipeline import GRAVITY

            n = surf.normal
            p0, v0 = self._smoothed_x[i0, rl.SP], self._smoothed_x[i0, rl.SV]
            vt = v0 - (v0 @ n) * n
            gt = GRAVITY - (GRAVITY @ n) * n
            tau = np.linspace(0.0, 0.8, 40)
            r.line_strip(
                layout.DROPTEST_ROLL_LINE,
                p0 + vt * tau[:, None] + 0.5 * gt * tau[:, None] ** 2,
                color=(148, 103, 189, 255),
                radius=0.01,
            )
        ms = st.max
        # static snapshot of the lander at the max-stroke pose (visible whatever the time cursor)
        k = int(ms.index)
        r.static_transform(
            layout.DROPTEST_MAX_STROKE,
            translation=self._smoothed_x[k, rl.SP],
            quaternion_xyzw=self._smoothed_x[k, rl.SQ],
        )
        r.mesh(layout.DROPTEST_MAX_STROKE_BODY, lander.body, color=GHOST)
        r.mesh(layout.DROPTEST_MAX_STROKE_AIRBAGS, airbag_mesh(lander, subdivisions=2), color=GHOST_BAGS)
        r.line_strip(
            layout.DROPTEST_MAX_STROKE_SEGMENT,
            np.stack([h.closest_point_I[k], h.surface_point_I[k]]),
            color=STROKE_NEAR,
            radius=STROKE_WIDTH,
        )
        r.points(layout.DROPTEST_MAX_STROKE_POINT, ms.point_I[None], colors=STROKE_NEAR, radii=0.06)
        # the same segment beside the airbags (inside them it was hidden), labelled in cm
        dim = max_stroke_dimension(
            h.closest_point_I[k],
            h.surface_point_I[k],
            surf.normal,
            airbags_at(lander, self._smoothed_x[k]),
            self._smoothed_x[k, rl.SP],
        )
        r.line_strip(
            layout.DROPTEST_MAX_STROKE_DIMENSION,
            [
                np.stack([dim["a"], dim["b"]]),
                np.stack([h.closest_point_I[k], dim["a"]]),
                np.stack([h.surface_point_I[k], dim["b"]]),
            ],
            color=STROKE_NEAR,
            radius=[DIMENSION_WIDTH, EXTENSION_WIDTH, EXTENSION_WIDTH],
        )
        r.stream.log(
            layout.DROPTEST_MAX_STROKE_DIMENSION_LABEL,
            rr.Points3D(
                dim["label"][None],
                labels=[f"max stroke {100 * ms.distance:.1f} ± {100 * ms.sigma:.1f} cm (1σ)"],
                colors=[STROKE_NEAR],
                radii=[0.001],
                show_labels=True,
            ),
            static=True,
        )
        ev = [
            (
                float(ms.time),
                f"max stroke {ms.distance:.3f} m ± {ms.sigma:.3f} m (1σ; sampled {st.sampled_sigma:.3f}) at vertex "
                f"{ms.vertex}"
                + (
                    " — FULL STROKE"
                    if ms.full_stroke
                    else " — full stroke within 3σ"
                    if ms.possible_full_stroke
                    else ""
                ),
                "WARN" if ms.possible_full_stroke else "INFO",
            )
        ]
        kb, ka = st.restitution_index
        if ka >= 0:
            vn = self._smoothed_x[:, rl.SV] @ surf.normal
            # the contact's start and the rebound are key moments (★ rows); this is the instant the
            # restitution's leaving velocity is read: the lander's last push off the ramp
            ev.append(
                (
                    float(t[ka]),
                    f"the lander leaves the ramp (largest v_n before the rebound's apex, {vn[ka]:+.2f} m/s; "
                    f"approaching {vn[kb]:+.2f} m/s at t = {t[kb]:.3f} s): restitution "
                    f"e = {st.restitution[0]:.3f} ± {st.restitution[1]:.3f}",
                    "INFO",
                )
            )
        r.events(ev)
        if self.truth is not None:
            self._truth(st)

    def _truth(self, st) -> None:
        from workbench.problems.droptest.pipeline import truth_on_grid, truth_stroke

        r = self.rec
        t = self._fwd_t
        tg = truth_on_grid(self.truth, t)
        r.poses(layout.TRUTH_VEHICLE, t, tg["p_I"], tg["q_I_B"], step=np.arange(t.size))
        edges = np.asarray(st.lander.body.vertices, float)[np.asarray(st.lander.body.edges_unique)]
        r.line_strip(layout.DROPTEST_TRUTH_BODY, edges, color=TRUTH, radius=0.008)  # wireframe
        r.line_strip(layout.DROPTEST_TRUTH_TRAJECTORY, self.truth["p_I"][::20], color=TRUTH, radius=0.008)
        d, _, _ = truth_stroke(self.truth, st.lander, st.surface)
        r.scalars(
            layout.join(layout.DROPTEST_PLOT_STROKE, layout.TRUTH_SERIES),
            self.truth["t"][::5],
            d[::5],
            names="stroke truth [m]",
            colors=[TRUTH],
            widths=1.0,
        )
        r.events([(float(v), f"truth: {k}", "DEBUG") for k, v in self.truth["events"].items()])
