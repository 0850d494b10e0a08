"""Draw the entry and descent reconstruction stages into a Rerun recording (layout in docs/RECORDING.md).

The pipeline (:mod:`workbench.problems.entry.pipeline`) yields stages; :class:`EntryRecorder` draws each
one as it arrives and, for synthetic scenarios, the truth beside the estimate (``/world/truth``,
``.../truth``). Every entity path comes from :mod:`workbench.recording.layout`; a stage type the
recorder does not know is a ``TypeError``.

Geometry is in the landing-site frame L (East-North-Up on the terrain sphere below the site,
:class:`~workbench.problems.entry.scene.LandingSiteFrame`): float32-safe from the entry interface
(~600 km up-range, 120 km up) down to the end of the descent.  The vehicle entity carries the
smoothed position (``/world/vehicle``, translation only, so the 3σ ellipsoid and the radar beams are
drawn in site axes) and ``/world/vehicle/body`` the smoothed attitude, with the 70° capsule, the
front shield until FSR and the parachute from PDD (drawn along +Z_G at the riser length, i.e. aligned
with the module as AMELIA assumes).  A second 3D view has its origin on the vehicle, so the descent is
legible at metre scale while the first shows the whole entry at km scale.

Atmosphere and wind profiles are drawn with altitude on the vertical axis in 2D views: x is the
quantity (density and pressure as the percentage difference from the default model, temperature in K,
wind in m/s), y is altitude above the MOLA radius in km times a per-view scale stated in the view name,
with labelled grid lines.
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.core.frames import ned_from_enu
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import quat_to_dcm
from workbench.problems.entry.atmosphere import AtmosphereResult
from workbench.problems.entry.dispersion import DispersionResult
from workbench.problems.entry.filter import EntryFilterResult, radial_sigma
from workbench.problems.entry.initial import SmootherStart
from workbench.problems.entry.pipeline import EntryResult, NominalIntegration
from workbench.problems.entry.preprocess import PreprocessedIMU
from workbench.problems.entry.scene import (
    LandingSiteFrame,
    capsule_meshes,
    parachute_mesh,
    site_frame_below,
    terrain_patch,
)
from workbench.problems.entry.site import R_MOLA
from workbench.problems.entry.state import DP, DV
from workbench.problems.entry.telemetry import EntryTelemetry
from workbench.problems.entry.winds import WindResult
from workbench.recording import layout
from workbench.recording.blueprint import events_view, legible_range, plot_view, report_view, tab
from workbench.recording.dispatch import StageDispatch
from workbench.recording.meshes import mesh3d
from workbench.recording.writer import Recorder

__all__ = [
    "EntryRecorder",
    "descent_window",
    "entry_blueprint",
    "residual_ranges",
    "residual_spans",
    "run_span",
    "sigma_label",
    "sigma_name_positions",
]

EST = (31, 119, 180, 255)
FWD = (255, 127, 14, 255)
TRUTH = (44, 160, 44, 255)
NOMINAL = (148, 103, 189, 255)
ONBOARD = (214, 39, 40, 255)
GREY = (150, 150, 150, 255)

#: what the 3D scenes show (``layout.SCENE_KEY``, under the 3D views)
SCENE_KEY_MD = (
    "**3D key** — black dot (Entry view): the vehicle; blue line: smoothed track, blue ellipsoid its 3σ; orange "
    "line: forward (filter) pass, orange ellipsoid its 3σ (the ellipsoids in the Entry view; kilometres wide, "
    "they would enclose the Descent view's camera, which names their semi-axes beside the vehicle instead); red: "
    "on-board navigation; purple: nominal trajectory; radar beams coloured by their normalised residual, green "
    "≤ 1σ → red ≥ 3σ (grey: no return); dispersion cloud hidden (tick `/world/dispersion` in the blueprint "
    "panel: green / grey, members accepted / rejected, tracks and positions at PDD)"
)
SCENE_KEY_TRUTH_MD = " · green line: truth track"
RAW = (120, 160, 220, 255)
ITER = (255, 200, 0, 255)
TRUTH_EAST = (120, 200, 120, 255)
XYZ = [(214, 39, 40, 255), (44, 160, 44, 255), (31, 119, 180, 255)]
BEAMS = ["B0", "B1", "B2", "B3"]

#: line widths of the 3D scenes, in screen points (negative radii: the same at the descent's metres
#: and the entry's hundreds of km): the tracks thin, so that the vehicle, its 3σ ellipsoid and the
#: radar beams (wider) read in front of them; the smoothed track a little wider than the others
TRACK_MAIN = -0.9
TRACK_THIN = -0.6
BEAM_WIDTH = -2.0
#: the 3σ ellipsoids' wireframe, drawn in the Entry view only (at the Descent view's metres the
#: camera sits inside them: there :data:`SIGMA_LABEL_OFFSET` names their size instead)
ELLIPSOID_LINE = -1.0
#: the gap [m] between the Entry view's 3σ ellipsoids and their names, the smoothed one's above its
#: top, the forward one's below its bottom (at the view's hundreds of km about 20 px): at their
#: centres the two names stood on each other once the ellipsoids coincide, at the end of the run
SIGMA_NAME_GAP_M = 8.0e3
#: the Descent view's camera, in the site axes at the vehicle [m]
DESCENT_EYE = (-30.0, -48.0, 14.0)
DESCENT_LOOK = (0.0, 0.0, 8.0)
#: where the smoothed 3σ ellipsoid's size is written in the Descent view [m, site axes from the
#: vehicle]: right of the capsule and below it, seen from :data:`DESCENT_EYE`
SIGMA_LABEL_OFFSET = (22.0, -14.0, -8.0)
#: the height [CSS px] a residual view is given at least (1400 x 900 window: about 150)
RESIDUAL_VIEW_PX = 130.0

MAX_DISPERSION_TRACKS = 12
"""Tracks drawn per status (accepted / rejected) of the dispersion cloud; the points at PDD are all drawn."""
BOUNDS_KEY = "blue estimate, grey ±3σ, pale truth"
XYZ_KEY = "RGB = xyz"

#: (tab name with unit and colour key, plot root); legends are off (they covered the data), so each
#: name says what its colours are
_PLOTS = [
    ("altitude AMR [km]", "altitude AMR [km] — " + BOUNDS_KEY, layout.ENTRY_PLOT_ALTITUDE_AMR),
    ("velocity NED [m/s]", "velocity NED [m/s] — RGB = NED, grey ±3σ, pale truth", layout.ENTRY_PLOT_VELOCITY_NED),
    ("tilt [deg]", "tilt off-vertical [deg] — " + BOUNDS_KEY, layout.ENTRY_PLOT_TILT),
    (
        "σ position [m]",
        "σ position [m] — purple |σ_p|; 3σ altitude: blue smoothed, orange fwd",
        layout.ENTRY_PLOT_SIGMA_POSITION,
    ),
    ("σ velocity [m/s]", "σ velocity [m/s] — |σ_v|", layout.ENTRY_PLOT_SIGMA_VELOCITY),
    ("σ attitude [deg]", "σ attitude [deg] — |σ_θ|", layout.ENTRY_PLOT_SIGMA_ATTITUDE),
    ("error vs truth [m]", "altitude error vs truth [m] — blue error, grey ±3σ", layout.ENTRY_PLOT_ERROR),
    ("strapdown [km]", "strapdown h AMR (nominal) [km] — purple, grey ±3σ", layout.ENTRY_PLOT_STRAPDOWN),
    ("on-board vs recon", "on-board vs recon — red |Δp| [m], blue Δθ [deg]", layout.ENTRY_PLOT_ONBOARD),
    ("body accel [m/s²]", "body accel f_G [m/s²] — " + XYZ_KEY + "; grey 100 Hz z", layout.ENTRY_PLOT_IMU_F),
    ("body rate [deg/s]", "body rate w_G [deg/s] — " + XYZ_KEY + "; rebuilt x", layout.ENTRY_PLOT_IMU_W),
    ("density (time) [%]", "density vs default [%] — blue reconstructed, green truth", layout.ENTRY_PLOT_ATMOSPHERE),
]
_RESIDUALS = [  # (channel, tab name, view name, origin)
    ("slant_out", "slant-out [m]", "slant-out residual [m] — blue, grey ±3σ", layout.ENTRY_RESIDUAL_SLANT_OUT),
    (
        "velocity_out",
        "velocity-out [m/s]",
        "velocity-out residual [m/s] — " + XYZ_KEY + ", grey ±3σ",
        layout.ENTRY_RESIDUAL_VELOCITY_OUT,
    ),
    (
        "slant_range",
        "slant range [m]",
        "slant-range residual [m] — per beam, grey ±3σ",
        layout.ENTRY_RESIDUAL_SLANT_RANGE,
    ),
]
#: dispersion event quantities (``dispersion.EVENT_NAMES``) with their unit, on the ``sample`` timeline
DISPERSION_UNITS = {"mach_pdd": "-", "h_pdd": "m", "h_fsr": "m", "h_end": "m", "time_to_impact": "s"}
PROFILE_SCALE = {"density": 0.3, "pressure": 0.3, "temperature": 1.0, "wind": 4.0}
"""y = altitude_km × scale in each 2D profile view. A 2D view keeps the aspect of its content, and
its pane is wide and low: density and pressure (±60 % against 0-110 km) are drawn flat, so that
they fill the pane's width instead of a square in its middle."""


def entry_blueprint(
    scene_tab: int = 0,
    profile_tab: int = 0,
    plot_tab: int = 0,
    residual_tab: int = 0,
    descent: tuple[float, float] | None = None,
    residual_y: dict[str, tuple[float, float]] | None = None,
    span: tuple[float, float] | None = None,
    residual_span: dict[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """Default layout: 3D (descent at the vehicle, whole entry), plots, residuals, profiles, report.

    The ``*_tab`` arguments pick the initially active tab of each group (0 = first), e.g. for a
    presentation or a screenshot of another view. ``descent`` (t_start, t_end) [s]: the window of the
    altitude-AGL data (PDD − 5 s to the end, known after the run); the AGL views are fixed on it (the
    AGL plot is empty before it) with the last 20 s zoomed beside, where ±3σ is legible. Every plot's
    name states its unit and colours (legends off: they covered the data). ``residual_y`` {radar
    channel: (lo, hi)} [m or m/s]: the residual views' y ranges (:func:`residual_ranges`; else the
    viewer's own fit, which in a short view can label only "0"). ``span`` (t0, t1) [s]: the run
    (:func:`run_span`), on which the time plots open their x axis, ``residual_span`` {radar channel:
    (t0, t1)} [s] the residual and radar views' own (:func:`residual_spans`); without them the
    viewer opens a plot on about a minute around the time cursor.
    The Descent view leaves out the 3σ ellipsoids (kilometres wide, they enclose its camera) and
    shows their size as text (``layout.ENTRY_UNCERTAINTY_LABEL``); the Entry view draws them.
    """
    scenes = rrb.Tabs(
        rrb.Spatial3DView(
            name="Descent (at the vehicle)",
            origin=layout.VEHICLE,
            contents=[
                layout.subtree(layout.WORLD),
                "- " + layout.subtree(layout.DISPERSION),
                "- " + layout.subtree(layout.ENTRY_FORWARD_VEHICLE),
                "- " + layout.subtree(layout.UNCERTAINTY),
                "- " + layout.VEHICLE_MARKER,
            ],
            eye_controls=rrb.EyeControls3D(position=list(DESCENT_EYE), look_target=list(DESCENT_LOOK)),
        ),
        rrb.Spatial3DView(
            name="Entry (site frame, km scale)",
            origin=layout.WORLD,
            # the dispersion cloud (sample tracks, members at PDD) hidden by default: a clutter over
            # the end of the track and its ellipsoids; tick it in the blueprint panel
            contents=[
                layout.subtree(layout.WORLD),
                "- " + layout.subtree(layout.DISPERSION),
                "- " + layout.ENTRY_UNCERTAINTY_LABEL,
            ],
            eye_controls=rrb.EyeControls3D(
                position=[-200e3, -330e3, 160e3], look_target=[-280e3, 0.0, 20e3], eye_up=[0.0, 0.0, 1.0]
            ),
        ),
        active_tab=scene_tab,
    )
    sc = PROFILE_SCALE
    # the ±60 % grid with its altitude labels left and its colour key right (the viewer fits the
    # points, not their label text, and cut the key), 0-125 km at the density/pressure scale
    pct_bounds = rrb.VisualBounds2D(x_range=[-85.0, 125.0], y_range=[-125.0 * sc["density"], 5.0])
    profiles = rrb.Tabs(
        rrb.Spatial2DView(
            name=f"density Δ% vs default (y = {sc['density']:g}·km)",
            origin=layout.ENTRY_PROFILE_DENSITY,
            visual_bounds=pct_bounds,
        ),
        rrb.Spatial2DView(
            name=f"temperature K (y = {sc['temperature']:g}·km)", origin=layout.ENTRY_PROFILE_TEMPERATURE
        ),
        rrb.Spatial2DView(
            name=f"pressure Δ% vs default (y = {sc['pressure']:g}·km)",
            origin=layout.ENTRY_PROFILE_PRESSURE,
            visual_bounds=pct_bounds,
        ),
        rrb.Spatial2DView(name=f"wind m/s (y = {sc['wind']:g}·km)", origin=layout.ENTRY_PROFILE_WIND),
        active_tab=profile_tab,
    )
    agl_key = "blue smoothed, grey ±3σ, pale truth, orange fwd, red ◆ plane fit"
    if descent is None:
        agl: object = tab(
            "altitude AGL [m]",
            plot_view(f"altitude AGL [m] (from PDD − 5 s) — {agl_key}", layout.ENTRY_PLOT_ALTITUDE_AGL),
        )
    else:
        t0, t1 = descent
        agl = rrb.Horizontal(
            plot_view(
                f"altitude AGL [m] (from PDD − 5 s) — {agl_key}",
                layout.ENTRY_PLOT_ALTITUDE_AGL,
                window=(t0, t1),
            ),
            plot_view(
                "altitude AGL, last 20 s [m]",
                layout.ENTRY_PLOT_ALTITUDE_AGL,
                window=(max(t0, t1 - 20.0), t1),
            ),
            column_shares=[3, 2],
            name="altitude AGL [m]",
        )
    plot_tabs = [agl, *[tab(short, plot_view(n, o, span=span)) for short, n, o in _PLOTS]]
    plot_tabs.append(
        rrb.Horizontal(
            *[
                plot_view(
                    f"wind {c} [m/s] — " + ("red" if c == "north" else "blue") + ", grey ±3σ, pale truth",
                    layout.entry_wind_plot_path(c),
                    span=span,
                )
                for c in ("north", "east")
            ],
            name="wind (time) [m/s]",
        )
    )
    plot_tabs.append(
        rrb.Grid(
            *[
                plot_view(
                    f"{q} [{u}] per member: set the time panel to 'sample' — green accepted, grey rejected",
                    layout.join(layout.ENTRY_PLOT_DISPERSION, q),
                )
                for q, u in DISPERSION_UNITS.items()
            ],
            grid_columns=2,
            name="dispersion (timeline sample)",
        )
    )
    plots = rrb.Tabs(*plot_tabs, active_tab=plot_tab)
    ry, rs = residual_y or {}, residual_span or {}
    res_tabs = [
        tab(short, plot_view(n, o, y_range=ry.get(ch), span=rs.get(ch, span))) for ch, short, n, o in _RESIDUALS
    ]
    radar_span = (min(a for a, _ in rs.values()), max(b for _, b in rs.values())) if rs else span
    radar = (  # channel, view name (unit and colours)
        ("slant_out", "slant-out [m] — grey measured, blue smoothed prediction"),
        ("velocity_out", "velocity-out [m/s] — grey measured, " + XYZ_KEY + " smoothed prediction"),
        ("slant_range", "slant ranges [m] — B0 red, B1 green, B2 blue, B3 grey; × measured, ○ predicted"),
    )
    radar_views = [
        plot_view(
            name,
            layout.ENTRY_PLOT_RADAR,
            contents=[layout.entry_radar_plot_path(ch, s) for s in (layout.MEASURED_SERIES, layout.PREDICTED_SERIES)],
            span=radar_span,
        )
        for ch, name in radar
    ]
    # a tab each (stacked in the residual row, each view was too short for a y label)
    res_tabs.append(rrb.Tabs(*radar_views, name="radar meas vs pred"))
    residuals = rrb.Tabs(*res_tabs, active_tab=residual_tab)
    right = rrb.Vertical(
        plots,
        residuals,
        report_view("Scorecard", extra=[events_view()]),
        # residuals tall enough for two or three y labels (the axis labels decades: at 2 of 7 the
        # slant-out residual showed only "0")
        row_shares=[3, 2.8, 1.7],
    )
    key = rrb.TextDocumentView(name="3D key", origin=layout.SCENE_KEY, contents="$origin")
    left = rrb.Vertical(scenes, key, profiles, row_shares=[12, 3, 10])
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
    )


def residual_ranges(filter_result: EntryFilterResult, min_px: float = RESIDUAL_VIEW_PX) -> dict:
    """{radar channel: (lo, hi)} the y range [m or m/s] of its residual view: symmetric about 0,
    holding every smoothed residual and its ±3σ, widened (``blueprint.legible_range``) so that a
    view ``min_px`` [CSS px] high labels three ticks or more."""
    out = {}
    for ch, res in filter_result.smoothed_residuals.items():
        if not len(res.t):
            continue
        sd = np.sqrt(np.einsum("nii->ni", res.S))
        b = float(np.nanmax(np.concatenate([np.abs(res.y).ravel(), 3.0 * sd.ravel()])))
        if np.isfinite(b) and b > 0.0:
            out[ch] = legible_range(-b, b, min_px=min_px)
    return out


def residual_spans(filter_result: EntryFilterResult) -> dict:
    """{radar channel: (first, last)} [s] the time span of its smoothed residuals (the radar's)."""
    out = {}
    for ch, res in filter_result.smoothed_residuals.items():
        t = np.asarray(res.t, dtype=float)
        if t.size > 1 and t[-1] > t[0]:
            out[ch] = (float(t[0]), float(t[-1]))
    return out


def run_span(summary: dict) -> tuple[float, float] | None:
    """(first, last) [s] of a run summary's ``event_table`` ("First data" to the last event): the
    span of its time plots."""
    t = [float(r["t_s"]) for r in summary.get("event_table", [])]
    return (min(t), max(t)) if len(t) > 1 and max(t) > min(t) else None


def sigma_label(half_sizes: np.ndarray, nsigma: float = 3.0) -> list[str]:
    """One text per step naming an ellipsoid's principal semi-axes, largest first: ``half_sizes``
    (n, 3) [m] -> ``"3σ ellipsoid ±38.2 km × ±9.94 km × ±123 m"`` (m below 1 km, else km)."""

    def fmt(x: float) -> str:
        return f"±{x:.3g} m" if x < 1e3 else f"±{x / 1e3:.3g} km"

    hs = -np.sort(-np.asarray(half_sizes, float).reshape(-1, 3), axis=1)
    return [f"{nsigma:g}σ ellipsoid " + " × ".join(fmt(float(x)) for x in row) for row in hs]


def sigma_name_positions(P_L: np.ndarray, above: bool, nsigma: float = 3.0) -> np.ndarray:
    """Where an ellipsoid's name is written at each step: (n, 3) [m, site axes from its centre],
    :data:`SIGMA_NAME_GAP_M` above the top (``above``) or below the bottom of the ``nsigma``
    ellipsoid of the position covariances ``P_L`` (n, 3, 3) [m², site axes]: the two ellipsoids'
    names, one above and one below, stay apart however the ellipsoids overlap."""
    h = nsigma * np.sqrt(np.clip(np.asarray(P_L, float)[:, 2, 2], 0.0, None)) + SIGMA_NAME_GAP_M
    out = np.zeros((h.size, 3))
    out[:, 2] = h if above else -h
    return out


def descent_window(summary: dict) -> tuple[float, float] | None:
    """(PDD − 5 s, last data) [s] from a run summary's ``event_table``: the span of the AGL plot."""
    t = {r["event"]: float(r["t_s"]) for r in summary.get("event_table", [])}
    if "PDD" not in t:
        return None
    t1 = max(t.values())
    t0 = t["PDD"] - 5.0
    return (t0, t1) if t1 > t0 else None


class EntryRecorder:
    """Draws the stages of :func:`workbench.problems.entry.pipeline.reconstruct` (and the truth, if given).

    ``truth``: a mapping with the :class:`~workbench.problems.entry.truth.EntryTruth` arrays (``t``, ``p_M``,
    ``v_M``, ``q_M_G``, ``h_amr``, ``wind_NE`` ...) and ``atmosphere`` (or None for user data).
    ``vehicle``: the :class:`~workbench.models.aerodynamics.EntryVehicle` (meshes, riser length).
    """

    def __init__(
        self, rec: Recorder, vehicle, truth=None, *, r_ground: float, jd_tdb0: float, body, beams_G=None
    ) -> None:
        from workbench.models.radar import beam_directions_G

        self.beams_G = beam_directions_G() if beams_G is None else np.asarray(beams_G, float)
        self.rec = rec
        self.vehicle = vehicle
        self.truth = truth
        self.r_ground = r_ground
        self.jd0 = jd_tdb0
        self.body = body
        self.site: LandingSiteFrame | None = None
        self.events: dict[str, float] = {}
        self.default_atmosphere = None
        self.dispatch = StageDispatch(
            {
                EntryTelemetry: self._on_telemetry,
                PreprocessedIMU: self._on_imu,
                NominalIntegration: self._on_nominal,
                DispersionResult: self._on_dispersion,
                EntryFilterResult: self._on_filter,
                AtmosphereResult: self._on_atmosphere,
                WindResult: self._on_winds,
            },
            # not drawn: the smoother's start (it goes into the summary) and the final bundle of all stages
            ignored=(SmootherStart, EntryResult),
        )

    # ------------------------------------------------------------------ dispatch
    def handle(self, stage) -> None:
        """Draw one stage of :func:`workbench.problems.entry.pipeline.reconstruct`; a stage of a type the
        recorder does not know is a ``TypeError`` (see :class:`~workbench.recording.dispatch.StageDispatch`)."""
        self.dispatch(stage)

    # ------------------------------------------------------------------ helpers
    def _L(self, t, p_M):
        return self.site.points(np.asarray(t, float), p_M)

    def _static_scene(self) -> None:
        rec, site = self.rec, self.site
        rec.view_coordinates()
        rec.mesh(layout.SURFACE, terrain_patch(site, (-700e3, 60e3), (-120e3, 120e3), 80), color=(190, 150, 120, 255))
        rec.axes(layout.ENTRY_SITE_AXES, 2000.0)
        m = capsule_meshes(self.vehicle.diameter, self.vehicle.nose_radius)
        rec.mesh(layout.ENTRY_BACK_SHELL, m["back_shell"], color=(220, 220, 225, 255))
        self._front_shield = m["front_shield"]  # logged on the timeline (from the first sample to FSR)
        rec.axes(layout.ENTRY_BODY_AXES, 3.0)

    # ------------------------------------------------------------------ stages
    def _on_telemetry(self, tm) -> None:
        rec = self.rec
        self.events = dict(tm.events)
        # landing-site frame: ground point below the on-board position at PDD (before it drifts)
        t_site = self.events.get("PDD", float(tm.t_nav[len(tm.t_nav) // 2]))
        p_site = interp_rows(t_site, tm.t_nav, tm.p_M_nav)
        if self.jd0 is None:  # user data without [scenario] epoch_utc: the telemetry's epoch line
            from workbench.core.frames import julian_date_from_utc

            self.jd0 = julian_date_from_utc(tm.epoch_utc)
        self.site = site_frame_below(self.body, p_site, t_site, self.r_ground, self.jd0)
        self.t_first = float(tm.t_gnc[0])
        self._static_scene()
        rec.scalars(layout.ENTRY_SENSOR_GNC_RATE, tm.t_gnc, np.degrees(tm.w_G), names=["x", "y", "z"], colors=XYZ)
        ok = tm.a_valid
        rec.scalars(layout.ENTRY_SENSOR_GNC_ACCEL, tm.t_gnc[ok], tm.a_M_total[ok], names=["x", "y", "z"], colors=XYZ)
        if len(tm.t_rda):
            rec.scalars(layout.ENTRY_SENSOR_RDA_SLANT_OUT, tm.t_rda, tm.slant_out, names="slant-out", colors=EST)
            rec.scalars(layout.ENTRY_SENSOR_RDA_V_OUT, tm.t_rda, tm.v_out_G, names=["x", "y", "z"], colors=XYZ)
        if len(tm.t_sr):
            rec.scatter(layout.ENTRY_SENSOR_RDA_SLANT_RANGE, tm.t_sr, tm.slant_ranges, names=BEAMS, colors=XYZ + [GREY])
        # on-board navigation track (it goes wrong after the gyro saturation)
        p_L = self._L(tm.t_nav, tm.p_M_nav)
        rec.line_strip(layout.ENTRY_ONBOARD_TRACK, p_L, color=[ONBOARD], radius=TRACK_THIN)
        ev = [
            (float(t), f"{k} (telemetry event)", "INFO") for k, t in sorted(self.events.items(), key=lambda kv: kv[1])
        ]
        ev += [(float(tm.t_gnc[0]), p, "WARN" if p.startswith("WARN") else "INFO") for p in tm.problems]
        rec.events(ev)
        if self.truth is not None:
            tt = self.truth
            step = max(1, int(round(0.1 / float(tt["t"][1] - tt["t"][0]))))
            ts = tt["t"][::step]
            p_T = self._L(ts, tt["p_M"][::step])
            rec.line_strip(layout.ENTRY_TRUTH_TRACK, p_T, color=[TRUTH], radius=TRACK_THIN)
            g = self.site.ground_point_L(p_T)
            rec.line_strip(layout.ENTRY_TRUTH_GROUND_TRACK, g + [0, 0, 30.0], color=[TRUTH], radius=TRACK_THIN)
            rec.poses(layout.TRUTH_VEHICLE, ts, p_T, self.site.attitudes(ts, tt["q_M_G"][::step]))
            rec.axes(layout.ENTRY_TRUTH_VEHICLE_AXES, 4.0)
            if tt.get("parachute_p_M") is not None:
                pp = np.asarray(tt["parachute_p_M"][::step])
                ok = np.all(np.isfinite(pp), axis=1)
                if ok.any():
                    rec.points_series(
                        layout.ENTRY_TRUTH_PARACHUTE,
                        ts[ok],
                        self._L(ts[ok], pp[ok]),
                        colors=TRUTH,
                        radii=-4.0,
                    )

    def _on_imu(self, imu) -> None:
        rec = self.rec
        rec.scalars(layout.ENTRY_PLOT_IMU_F, imu.t, imu.f_G, names=["x", "y", "z"], colors=XYZ)
        rec.scalars(layout.ENTRY_PLOT_IMU_W, imu.t, np.degrees(imu.w_G), names=["x", "y", "z"], colors=XYZ)
        sat = np.asarray(imu.saturated, bool)
        if sat.any():
            rec.scatter(
                layout.ENTRY_PLOT_IMU_W_REBUILT,
                imu.t[sat],
                np.degrees(imu.w_G[sat, 0]),
                names="x rebuilt",
                colors=ONBOARD,
            )
        res = np.asarray(imu.resampled, bool)
        if res.any():
            rec.scatter(layout.ENTRY_PLOT_IMU_F_RESAMPLED, imu.t[res], imu.f_G[res, 2], names="z 100 Hz", colors=GREY)
        ev = [
            (g.t_a, f"gap {g.t_b - g.t_a:.1f} s bridged with on-board Δv, Δp, ΔC (until t = {g.t_b:.2f} s)", "INFO")
            for g in imu.gaps
        ]
        if sat.any():
            n_tm = int(np.sum(sat & ~res))
            ev.append(
                (
                    float(imu.t[sat][0]),
                    f"gyro saturated in {n_tm} telemetry samples: rate rebuilt from the Y acceleration "
                    f"({int(sat.sum())} samples of the 100 Hz window flagged)",
                    "WARN",
                )
            )
        rec.events(ev)

    def _on_nominal(self, nom) -> None:
        rec = self.rec
        sp = nom.strapdown
        p_L = self._L(sp.t, sp.p_M)
        rec.line_strip(layout.ENTRY_NOMINAL_TRACK, p_L, color=[NOMINAL], radius=TRACK_THIN)
        h = np.linalg.norm(sp.p_M, axis=1) - R_MOLA
        sd = radial_sigma(sp.p_M, sp.P)
        t = np.asarray(sp.t, float)
        rec.series_with_bounds(  # in km, as its view says (it drew metres under a [km] title)
            layout.ENTRY_PLOT_STRAPDOWN_H_AMR,
            t,
            h / 1e3,
            sd / 1e3,
            names="h AMR (nominal strapdown) [km]",
            color=[NOMINAL],
            gap_s=5.0 * float(np.median(np.diff(t))) if t.size > 2 else None,  # the blackouts bridged
        )
        if nom.onboard_t is not None:
            d = nom.diff_position_m
            rec.scalars(
                layout.ENTRY_PLOT_ONBOARD_POSITION_DIFF,
                nom.onboard_t,
                d,
                names="|Δp| recon − on-board [m]",
                colors=ONBOARD,
            )
            rec.scalars(
                layout.ENTRY_PLOT_ONBOARD_ATTITUDE_DIFF,
                nom.onboard_t,
                nom.diff_attitude_deg,
                names="Δθ [deg]",
                colors=EST,
            )

    def _on_dispersion(self, d) -> None:
        rec = self.rec
        acc = np.asarray(d.accepted, bool)
        idx = np.arange(d.n)
        # event quantities on the `sample` timeline (one row per member)
        for key, vals in d.events.items():
            v = np.asarray(vals, float)
            for name, m, col in ((layout.ACCEPTED, acc, TRUTH), (layout.REJECTED, ~acc, GREY)):
                if m.any():
                    self._sample_scatter(layout.entry_dispersion_plot_path(key, name), idx[m], v[m], col)
        # cloud: positions at PDD and thinned tracks
        ct = np.asarray(d.cloud_t, float)
        cp = np.asarray(d.cloud_p_M, float)
        if cp.size:
            k = int(np.argmin(np.abs(ct - self.events.get("PDD", ct[-1]))))
            pts = np.stack([self._L(ct, cp[i]) for i in range(cp.shape[0])])  # (m, k, 3)
            ca = np.asarray(d.cloud_accepted, bool)
            for name, m, col in (
                (layout.ACCEPTED, ca, (44, 160, 44, 255)),
                (layout.REJECTED, ~ca, (160, 160, 160, 90)),
            ):
                if m.any():
                    rec.points(layout.entry_dispersion_at_pdd_path(name), pts[m, k], colors=col, radii=-3.0)
                    # a few evenly picked tracks: all of them drew a hairball that hid the cloud
                    sel = np.flatnonzero(m)
                    sel = sel[np.unique(np.linspace(0, sel.size - 1, min(sel.size, MAX_DISPERSION_TRACKS)).astype(int))]
                    rec.line_strip(layout.entry_dispersion_tracks_path(name), list(pts[sel]), color=col, radius=-0.5)

    def _sample_scatter(self, entity: str, samples: np.ndarray, values: np.ndarray, color) -> None:
        s = self.rec.stream
        s.send_columns(
            entity, indexes=[rr.TimeColumn(layout.SAMPLE, sequence=samples)], columns=rr.Scalars.columns(scalars=values)
        )
        s.log(entity, rr.SeriesPoints(colors=[color], markers=["circle"], marker_sizes=[2.0]), static=True)

    def _on_filter(self, fr) -> None:
        rec, site = self.rec, self.site
        sm, fw = fr.smoothed, fr.forward
        t = np.asarray(sm.t, float)
        p_L = self._L(t, sm.p_M)
        q_L = site.attitudes(t, sm.q_M_G)
        rec.poses(layout.VEHICLE, t, p_L, np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1)), step=np.arange(len(t)))
        # at the Entry view's hundreds of km the capsule is invisible: a dot of fixed screen size
        rec.points(layout.VEHICLE_MARKER, np.zeros((1, 3)), colors=(20, 20, 20, 255), radii=-6.0)
        rec.poses(layout.VEHICLE_BODY, t, np.zeros((len(t), 3)), q_L, step=np.arange(len(t)))
        P_L = site.covariances(t, sm.P[:, DP, DP])
        half_sizes, _ = rec.ellipsoids(
            layout.UNCERTAINTY,
            t,
            np.zeros((len(t), 3)),
            P_L,
            nsigma=3.0,
            color=EST,
            line_radius=ELLIPSOID_LINE,
            fill=False,
            step=np.arange(len(t)),
        )
        rec.text_labels_series(
            layout.ENTRY_UNCERTAINTY_SIGMA_LABEL,
            t,
            sigma_name_positions(P_L, above=True),
            ["3σ smoothed"],
            color=EST,
            step=np.arange(len(t)),
        )
        # the Descent view (metres) leaves the ellipsoid out: its size as text beside the vehicle
        rec.text_labels_series(
            layout.ENTRY_UNCERTAINTY_LABEL,
            t,
            np.tile(SIGMA_LABEL_OFFSET, (len(t), 1)),
            [[f"{lab} (smoothed; drawn in the Entry view)"] for lab in sigma_label(half_sizes)],
            color=EST,
            step=np.arange(len(t)),
        )
        rec.line_strip(layout.ESTIMATE_SMOOTHED, p_L, color=[EST], radius=TRACK_MAIN)
        fw_L = self._L(fw.t, fw.p_M)
        rec.line_strip(layout.ESTIMATE_FORWARD, fw_L, color=[FWD], radius=TRACK_THIN)
        rec.report(SCENE_KEY_MD + ("" if self.truth is None else SCENE_KEY_TRUTH_MD), entity=layout.SCENE_KEY)
        # the forward (filter) pass's own 3σ: it grows through the blackout and collapses vertically at
        # the radar fix (the smoothed one above already knows the fix from the start)
        fwd_vehicle = layout.ENTRY_FORWARD_VEHICLE
        steps_f = np.arange(len(fw.t))
        rec.poses(fwd_vehicle, fw.t, fw_L, np.tile([0.0, 0.0, 0.0, 1.0], (len(fw.t), 1)), step=steps_f)
        P_fw = site.covariances(fw.t, fw.P[:, DP, DP])
        rec.ellipsoids(
            layout.ENTRY_FORWARD_UNCERTAINTY,
            fw.t,
            np.zeros((len(fw.t), 3)),
            P_fw,
            nsigma=3.0,
            color=FWD,
            line_radius=ELLIPSOID_LINE,
            fill=False,
            step=steps_f,
        )
        rec.text_labels_series(
            layout.ENTRY_FORWARD_SIGMA_LABEL,
            fw.t,
            sigma_name_positions(P_fw, above=False),
            ["3σ forward"],
            color=FWD,
            step=steps_f,
        )
        sd_hf = fw.sigma_radial
        rec.scalars(
            layout.ENTRY_PLOT_ALTITUDE_3SIGMA_FORWARD,
            fw.t,
            3.0 * sd_hf,
            names="3σ altitude, forward [m]",
            colors=[FWD],
        )
        g = site.ground_point_L(p_L)
        rec.line_strip(layout.ENTRY_GROUND_TRACK, g + [0, 0, 20.0], color=[EST], radius=TRACK_THIN)
        # front shield leaves at FSR; the parachute appears at PDD (temporal logs, not static)
        s = rec.stream
        if "PDD" in self.events:
            rr.set_time(layout.TIME, duration=self.events["PDD"], recording=s)
            d_chute = float(np.sqrt(4.0 * self.vehicle.parachute.ref_area / np.pi))
            pm = parachute_mesh(d_chute, self.vehicle.riser_length)
            s.log(layout.ENTRY_PARACHUTE, mesh3d(pm, [230, 120, 40, 255]))
            a = np.asarray(self.vehicle.attach_point_G, float)
            rim = [
                [r * np.cos(u), r * np.sin(u), self.vehicle.riser_length]
                for u in np.linspace(0, 2 * np.pi, 9)[:-1]
                for r in [0.35 * d_chute]
            ]
            s.log(
                layout.ENTRY_RISERS,
                rr.LineStrips3D([[a, r] for r in rim], colors=[[120, 120, 120]], radii=[0.05]),
            )
        fsm = self._front_shield
        rr.set_time(layout.TIME, duration=float(t[0]), recording=s)
        s.log(layout.ENTRY_FRONT_SHIELD, mesh3d(fsm, [90, 60, 40, 255]))
        if "FSR" in self.events:
            rr.set_time(layout.TIME, duration=self.events["FSR"], recording=s)
            s.log(layout.ENTRY_FRONT_SHIELD, rr.Clear(recursive=False))
        s.reset_time()
        # radar beams from the module to the ground along the smoothed attitude, while the radar is on
        on = t >= self.events.get("RDA_ON", np.inf)
        if "slant_out" in fr.innovations and len(fr.innovations["slant_out"].t):
            on = t >= min(float(fr.innovations["slant_out"].t[0]), self.events.get("RDA_ON", np.inf))
        if on.any():
            C = quat_to_dcm(q_L[on])
            beams = self.beams_G
            nsig = self._beam_colour_source(fr, t[on])
            for b in range(4):
                d = np.einsum("nij,j->ni", C, beams[b])
                end = site.ray_to_ground(p_L[on], d) - p_L[on]
                strips = [np.stack([np.zeros(3), e]) for e in end]
                cols = self._residual_colours(nsig[:, b])
                rec.line_strips_series(
                    layout.radar_beam_path(b), t[on], strips, colors=cols, radii=BEAM_WIDTH, step=np.flatnonzero(on)
                )
        # plots: altitude AGL, AMR, velocity, tilt with ±3σ and truth
        self._trajectory_plots(fr)
        self._residual_plots(fr)
        if fr.plane_fits:
            ev = [
                (
                    float(tp),
                    f"RDA slant-range packet: plane fit AGL {pf.h_agl:.1f} m, off-vertical "
                    f"{np.degrees(pf.off_vertical):.2f}°, rms {pf.rms:.1f} m",
                    "INFO",
                )
                for tp, pf in fr.plane_fits
            ]
            rec.events(ev)
            rec.scatter(
                layout.ENTRY_PLOT_ALTITUDE_AGL_PLANE_FIT,
                [tp for tp, _ in fr.plane_fits],
                [pf.h_agl for _, pf in fr.plane_fits],
                names="plane fit (Table 4 method)",
                colors=ONBOARD,
                marker="diamond",
                size=6.0,
            )

    def _beam_colour_source(self, fr, t_on: np.ndarray) -> np.ndarray:
        """|normalised residual| per beam at each drawn step (NaN where no measurement)."""
        out = np.full((len(t_on), 4), np.nan)
        so = fr.smoothed_residuals.get("slant_out")
        if so is not None and len(so.t):
            z = np.abs(so.y[:, 0]) / np.sqrt(so.S[:, 0, 0])
            k = np.searchsorted(t_on, so.t).clip(0, len(t_on) - 1)
            out[k, 0] = z
        sr = fr.smoothed_residuals.get("slant_range")
        if sr is not None and len(sr.t):
            for i, tp in enumerate(sr.t):
                z = np.abs(sr.y[i]) / np.sqrt(np.diag(sr.S[i]))
                m = (t_on >= tp) & (t_on < tp + 1.0)  # hold a packet's colour for 1 s
                out[m, :] = z
        return out

    @staticmethod
    def _residual_colours(z: np.ndarray) -> np.ndarray:
        """Green (|r| ≤ 1σ) → yellow → red (≥ 3σ); grey where there is no measurement."""
        c = np.tile(np.array([170, 170, 170, 140], np.uint8), (len(z), 1))
        ok = np.isfinite(z)
        f = np.clip(z[ok] / 3.0, 0.0, 1.0)
        c[ok, 0] = (60 + 195 * f).astype(np.uint8)
        c[ok, 1] = (200 - 150 * np.clip(f - 0.33, 0, 1) / 0.67).astype(np.uint8)
        c[ok, 2] = 40
        c[ok, 3] = 255
        return c

    def _truth_at(self, t: np.ndarray, key: str) -> np.ndarray | None:
        if self.truth is None:
            return None
        a = np.asarray(self.truth[key], float)
        tt = np.asarray(self.truth["t"], float)
        return interp_rows(t, tt, a)

    def _trajectory_plots(self, fr) -> None:
        rec, site = self.rec, self.site
        sm = fr.smoothed
        t = np.asarray(sm.t, float)
        # an IMU blackout is bridged in one step: no estimate inside, so the plots break there
        gap = 5.0 * float(np.median(np.diff(t))) if t.size > 2 else None
        r = np.linalg.norm(sm.p_M, axis=1)
        sd_r = sm.sigma_radial
        h_agl = r - self.r_ground
        tr_p = self._truth_at(t, "p_M")
        tr_r = None if tr_p is None else np.linalg.norm(tr_p, axis=1)
        m = t >= self.events.get("PDD", t[0]) - 5.0
        rec.series_with_bounds(
            layout.join(layout.ENTRY_PLOT_ALTITUDE_AGL, layout.SMOOTHED_SERIES),
            t[m],
            h_agl[m],
            sd_r[m],
            truth=None if tr_r is None else (tr_r - self.r_ground)[m],
            names="h AGL",
            color=[EST],
            gap_s=gap,
        )
        fw = fr.forward
        rf = np.linalg.norm(fw.p_M, axis=1)
        mf = fw.t >= self.events.get("PDD", fw.t[0]) - 5.0
        rec.scalars(
            layout.join(layout.ENTRY_PLOT_ALTITUDE_AGL, layout.FORWARD_SERIES),
            fw.t[mf],
            (rf - self.r_ground)[mf],
            names="h AGL forward",
            colors=FWD,
        )
        rec.series_with_bounds(
            layout.ENTRY_PLOT_ALTITUDE_AMR,
            t,
            (r - R_MOLA) / 1e3,
            sd_r / 1e3,
            truth=None if tr_r is None else (tr_r - R_MOLA) / 1e3,
            names="h AMR [km]",
            color=[EST],
            gap_s=gap,
        )
        # ground-relative velocity in NED (site axes), its 1σ
        omega = np.array([0.0, 0.0, self.body.rotation_rate])
        v_rel_M = sm.v_M - np.cross(omega, sm.p_M)
        v_N = ned_from_enu(site.vectors(t, v_rel_M))
        C = site.C_L_M(t)
        Pv = C @ sm.P[:, DV, DV] @ np.swapaxes(C, -1, -2)
        sd_L = np.sqrt(np.einsum("nii->ni", Pv))
        sd_N = sd_L[:, [1, 0, 2]]
        tv = None
        if tr_p is not None:
            tv_M = self._truth_at(t, "v_M") - np.cross(omega, tr_p)
            tv = ned_from_enu(site.vectors(t, tv_M))
        rec.series_with_bounds(
            layout.ENTRY_PLOT_VELOCITY_NED,
            t,
            v_N,
            sd_N,
            truth=tv,
            names=["v_N", "v_E", "v_D"],
            color=XYZ,
            gap_s=gap,
        )
        # tilt: angle between +Z_G and local up
        up_M = sm.p_M / r[:, None]
        zG_M = quat_to_dcm(sm.q_M_G)[:, :, 2]
        tilt = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", up_M, zG_M), -1, 1)))
        sd_att = np.degrees(sm.sigma_attitude)
        tt = None
        if tr_p is not None:
            qT = self._truth_at(t, "q_M_G")
            qT = qT / np.linalg.norm(qT, axis=1, keepdims=True)
            zT = quat_to_dcm(qT)[:, :, 2]
            tt = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", tr_p / tr_r[:, None], zT), -1, 1)))
        rec.series_with_bounds(
            layout.ENTRY_PLOT_TILT,
            t,
            tilt,
            np.linalg.norm(sd_att[:, :2], axis=1),
            truth=tt,
            names="Z_G from local up [deg]",
            color=[EST],
            gap_s=gap,
        )
        sd_p, sd_v = sm.sigma_position, sm.sigma_velocity
        rec.scalars(
            layout.ENTRY_PLOT_SIGMA_POSITION_NORM, t, np.linalg.norm(sd_p, axis=1), names="|σ_p| [m]", colors=NOMINAL
        )
        rec.scalars(
            layout.ENTRY_PLOT_ALTITUDE_3SIGMA_SMOOTHED,
            t,
            3.0 * sd_r,
            names="3σ altitude, smoothed [m]",
            colors=[EST],
        )
        rec.scalars(layout.ENTRY_PLOT_SIGMA_VELOCITY, t, np.linalg.norm(sd_v, axis=1), names="|σ_v| [m/s]", colors=FWD)
        rec.scalars(
            layout.ENTRY_PLOT_SIGMA_ATTITUDE, t, np.linalg.norm(sd_att, axis=1), names="|σ_θ| [deg]", colors=TRUTH
        )
        if tr_p is not None:
            rec.series_with_bounds(
                layout.ENTRY_PLOT_ERROR_ALTITUDE, t, r - tr_r, sd_r, names="h error [m]", color=[EST], gap_s=gap
            )

    def _residual_plots(self, fr) -> None:
        rec = self.rec
        for ch, res in fr.smoothed_residuals.items():
            if not len(res.t):
                continue
            sd = np.sqrt(np.einsum("nii->ni", res.S))
            if ch == "slant_range":
                for b in range(res.y.shape[1]):
                    base = layout.entry_residual_path(ch, BEAMS[b])
                    plus, minus = layout.bound_names(3.0)
                    rec.scatter(
                        layout.join(base, layout.VALUE),
                        res.t,
                        res.y[:, b],
                        names=f"{BEAMS[b]} [m]",
                        colors=[EST],
                        size=6.0,
                    )
                    rec.scatter(layout.join(base, plus), res.t, 3 * sd[:, b], names="+3σ", colors=[GREY], size=4.0)
                    rec.scatter(layout.join(base, minus), res.t, -3 * sd[:, b], names="−3σ", colors=[GREY], size=4.0)
                for series, z, marker, size in (
                    (layout.MEASURED_SERIES, res.z, "cross", 6.0),
                    (layout.PREDICTED_SERIES, res.z_pred, "circle", 4.0),
                ):
                    rec.scatter(
                        layout.entry_radar_plot_path(ch, series),
                        res.t,
                        z,
                        names=BEAMS,
                        colors=XYZ + [GREY],
                        marker=marker,
                        size=size,
                    )
                continue
            names = ["slant-out [m]"] if ch == "slant_out" else ["x [m/s]", "y [m/s]", "z [m/s]"]
            plus, minus = layout.bound_names(3.0)
            for i in range(res.y.shape[1]):
                sub = (
                    layout.entry_residual_path(ch) if res.y.shape[1] == 1 else layout.entry_residual_path(ch, "xyz"[i])
                )
                col = EST if len(names) == 1 else XYZ[i]
                rec.scalars(layout.join(sub, layout.VALUE), res.t, res.y[:, i], names=names[i], colors=col)
                rec.scalars(layout.join(sub, plus), res.t, 3 * sd[:, i], names="+3σ", colors=GREY)
                rec.scalars(layout.join(sub, minus), res.t, -3 * sd[:, i], names="−3σ", colors=GREY)
            rec.scalars(
                layout.entry_radar_plot_path(ch, layout.MEASURED_SERIES),
                res.t,
                res.z,
                names=[f"{n} meas" for n in names],
                colors=[GREY] * len(names),
            )
            rec.scalars(
                layout.entry_radar_plot_path(ch, layout.PREDICTED_SERIES),
                res.t,
                res.z_pred,
                names=[f"{n} smoothed" for n in names],
                colors=XYZ[: len(names)] if len(names) > 1 else [EST],
            )

    # ------------------------------------------------------------------ profiles (2D, altitude up)
    def _profile_axes(
        self, root: str, x_ticks, y_km_ticks, scale: float, x_unit: str, legend: list[tuple[str, tuple]] = ()
    ) -> None:
        """Grid, tick labels (altitude left of the grid, the quantity below it, apart so they never
        overlap at the corner) and the colour key ``legend`` [(label, colour)] right of the grid."""
        s = self.rec.stream
        x0, x1 = min(x_ticks), max(x_ticks)
        y0, y1 = min(y_km_ticks) * scale, max(y_km_ticks) * scale
        w, h = x1 - x0, max(y1 - y0, 1e-9)
        grid = [[[x0, -y * scale], [x1, -y * scale]] for y in y_km_ticks] + [[[x, -y0], [x, -y1]] for x in x_ticks]
        s.log(layout.join(root, layout.GRID), rr.LineStrips2D(grid, colors=[[70, 70, 70]], radii=[-0.5]), static=True)
        labels = [f"{y:g} km" for y in y_km_ticks] + [f"{x:g} {x_unit}" for x in x_ticks]
        pos = [[x0 - 0.1 * w, -y * scale] for y in y_km_ticks] + [[x, -y0 + 0.06 * h] for x in x_ticks]
        s.log(
            layout.join(root, layout.LABELS),
            rr.Points2D(pos, labels=labels, radii=[0.01], show_labels=True),
            static=True,
        )
        if legend:
            names, cols = zip(*legend, strict=True)
            lpos = [[x1 + 0.22 * w, -y1 + 0.13 * h * i] for i in range(len(names))]
            s.log(
                layout.join(root, layout.LEGEND),
                rr.Points2D(lpos, labels=list(names), colors=list(cols), radii=[-6.0], show_labels=True),
                static=True,
            )

    def _profile(
        self, root: str, x: np.ndarray, h_km: np.ndarray, scale: float, color, width: float = 0.15, static: bool = True
    ) -> None:
        ok = np.isfinite(x) & np.isfinite(h_km)
        if ok.sum() < 2:
            return
        pts = np.column_stack([x[ok], -h_km[ok] * scale])  # 2D views have +y down: negate so altitude goes up
        self.rec.stream.log(root, rr.LineStrips2D([pts], colors=[color], radii=[-10.0 * width]), static=static)

    def _on_atmosphere(self, atm) -> None:
        from workbench.core.atmosphere import MarsEngineeringAtmosphere

        fin = atm.final
        h = np.asarray(fin.h_amr, float)
        hk = h / 1e3
        dflt = self.default_atmosphere or MarsEngineeringAtmosphere()
        rho_d, p_d, T_d = dflt.density(h), dflt.pressure(h), dflt.temperature(h)
        sc = PROFILE_SCALE
        top = float(np.nanmax(hk)) if hk.size else 120.0
        ticks = [v for v in range(0, int(top) + 11, 10)]
        has_truth = self.truth is not None and self.truth.get("atmosphere") is not None
        key = [("smoothed", EST), ("raw", RAW), ("±1σ", GREY), ("default model", NOMINAL)]
        key += [("truth", TRUTH)] if has_truth else []
        filled_key = [("blackout fill", ONBOARD)] if np.asarray(fin.filled, bool).any() else []
        iter_key = [("iterations", ITER)] if atm.iterations else []
        pct_ticks = [-60, -40, -20, 0, 20, 40, 60]
        self._profile_axes(
            layout.ENTRY_PROFILE_DENSITY, pct_ticks, ticks, sc["density"], "%", key + filled_key + iter_key
        )
        self._profile_axes(layout.ENTRY_PROFILE_PRESSURE, pct_ticks, ticks, sc["pressure"], "%", key + filled_key)
        self._profile_axes(layout.ENTRY_PROFILE_TEMPERATURE, [120, 160, 200, 240, 280], ticks, 1.0, "K", key)
        pct = lambda a, b: 100.0 * (a / b - 1.0)  # noqa: E731
        j = layout.join
        plus1, minus1 = layout.bound_names(1.0)
        for root, raw, val, sig, ref, scale in (
            (layout.ENTRY_PROFILE_DENSITY, fin.rho, atm.rho_smooth, atm.sigma_rho, rho_d, sc["density"]),
            (layout.ENTRY_PROFILE_PRESSURE, fin.p, atm.p_smooth, atm.sigma_p, p_d, sc["pressure"]),
        ):
            self._profile(j(root, layout.RAW_SERIES), pct(raw, ref), hk, scale, RAW, 0.08)
            self._profile(j(root, layout.SMOOTHED_SERIES), pct(val, ref), hk, scale, EST, 0.2)
            self._profile(j(root, plus1), pct(val + sig, ref), hk, scale, GREY, 0.08)
            self._profile(j(root, minus1), pct(val - sig, ref), hk, scale, GREY, 0.08)
            self._profile(j(root, layout.DEFAULT_SERIES), np.zeros_like(hk), hk, scale, NOMINAL, 0.12)
            filled = np.asarray(fin.filled, bool)
            if filled.any():
                fill = np.where(filled, pct(val, ref), np.nan)
                self._profile(j(root, layout.BLACKOUT_FILL_SERIES), fill, hk, scale, ONBOARD, 0.2)
        root = layout.ENTRY_PROFILE_TEMPERATURE
        self._profile(j(root, layout.RAW_SERIES), fin.T, hk, 1.0, RAW, 0.08)
        self._profile(j(root, layout.SMOOTHED_SERIES), atm.T_smooth, hk, 1.0, EST, 0.2)
        self._profile(j(root, plus1), atm.T_smooth + atm.sigma_T, hk, 1.0, GREY, 0.08)
        self._profile(j(root, minus1), atm.T_smooth - atm.sigma_T, hk, 1.0, GREY, 0.08)
        self._profile(j(root, layout.DEFAULT_SERIES), T_d, hk, 1.0, NOMINAL, 0.12)
        if self.truth is not None and self.truth.get("atmosphere") is not None:
            ta = self.truth["atmosphere"]
            hg = np.linspace(max(0.0, float(np.nanmin(h))), float(np.nanmax(h)), 400)
            hgk = hg / 1e3
            rho_t, p_t = pct(ta.density(hg), dflt.density(hg)), pct(ta.pressure(hg), dflt.pressure(hg))
            self._profile(j(layout.ENTRY_PROFILE_DENSITY, layout.TRUTH_SERIES), rho_t, hgk, sc["density"], TRUTH)
            self._profile(j(layout.ENTRY_PROFILE_PRESSURE, layout.TRUTH_SERIES), p_t, hgk, sc["pressure"], TRUTH)
            self._profile(j(layout.ENTRY_PROFILE_TEMPERATURE, layout.TRUTH_SERIES), ta.temperature(hg), hgk, 1.0, TRUTH)
        # each iteration of the drag-coefficient loop on the `iteration` timeline
        s = self.rec.stream
        for it in atm.iterations:
            s.set_time(layout.ITERATION, sequence=int(it.iteration))
            hk_i = np.asarray(it.h_amr, float) / 1e3
            x = pct(np.asarray(it.rho, float), dflt.density(np.asarray(it.h_amr, float)))
            ok = np.isfinite(x)
            if ok.sum() > 1:
                s.log(
                    j(layout.ENTRY_PROFILE_DENSITY, layout.ITERATION_SERIES),
                    rr.LineStrips2D([np.column_stack([x[ok], -hk_i[ok] * sc["density"]])], colors=[ITER], radii=[0.1]),
                )
            if np.isfinite(it.max_rel_change):  # undefined for the first iteration
                s.log(layout.ENTRY_PLOT_ATMOSPHERE_MAX_REL_CHANGE, rr.Scalars(float(it.max_rel_change)))
        s.reset_time()
        # time series too (for scrubbing against the trajectory)
        t = np.asarray(fin.t, float)
        self.rec.scalars(
            layout.ENTRY_PLOT_DENSITY_RATIO, t, pct(atm.rho_smooth, rho_d), names="ρ vs default [%]", colors=EST
        )
        tr = self._truth_at(t, "h_amr") if self.truth is not None else None
        if tr is not None and self.truth.get("atmosphere") is not None:
            ta = self.truth["atmosphere"]
            self.rec.scalars(
                layout.ENTRY_PLOT_DENSITY_RATIO_TRUTH,
                t,
                pct(ta.density(h), rho_d),
                names="truth ρ vs default [%]",
                colors=TRUTH,
            )

    def _on_winds(self, w) -> None:
        sc = PROFILE_SCALE["wind"]
        ok = np.asarray(w.valid, bool)
        hk = np.asarray(w.h_amr, float) / 1e3
        if not ok.any():
            return
        lo, hi = float(np.floor(hk[ok].min())), float(np.ceil(hk[ok].max()))
        key = [("north", XYZ[0]), ("east", XYZ[2]), ("±1σ", GREY)]
        key += [("truth north", TRUTH), ("truth east", TRUTH_EAST)] if self.truth is not None else []
        self._profile_axes(
            layout.ENTRY_PROFILE_WIND, [-30, -20, -10, 0, 10, 20, 30], list(range(int(lo), int(hi) + 1)), sc, "m/s", key
        )
        plus1, minus1 = layout.bound_names(1.0)
        for name, v, s_, col in (("north", w.wind_N, w.sigma_N, XYZ[0]), ("east", w.wind_E, w.sigma_E, XYZ[2])):
            v = np.where(ok, v, np.nan)
            self._profile(layout.entry_wind_profile_path(name), v, hk, sc, col, 0.12)
            self._profile(layout.entry_wind_profile_path(name, plus1), v + s_, hk, sc, GREY, 0.05)
            self._profile(layout.entry_wind_profile_path(name, minus1), v - s_, hk, sc, GREY, 0.05)
            # from the first to the last valid sample, NaN (a break) where not valid: rows left out
            # were joined by a straight line across the gap
            k = np.flatnonzero(ok)
            span = slice(int(k[0]), int(k[-1]) + 1)
            self.rec.series_with_bounds(
                layout.entry_wind_plot_path(name),
                w.t[span],
                v[span],
                np.where(ok, s_, np.nan)[span],
                names=f"wind {name} [m/s]",
                color=[col],
                truth=None
                if self.truth is None
                else self._truth_at(w.t[span], "wind_NE")[:, 0 if name == "north" else 1],
            )
        if self.truth is not None:
            tw = self._truth_at(w.t, "wind_NE")
            north_t, east_t = np.where(ok, tw[:, 0], np.nan), np.where(ok, tw[:, 1], np.nan)
            self._profile(layout.entry_wind_profile_path("north", layout.TRUTH_SERIES), north_t, hk, sc, TRUTH, 0.08)
            self._profile(layout.entry_wind_profile_path("east", layout.TRUTH_SERIES), east_t, hk, sc, TRUTH_EAST, 0.08)

    def finish(self, events_table: list[tuple[float, str, str]], report_md: str) -> None:
        """Final events and the scorecard."""
        self.rec.events(events_table)
        self.rec.report(report_md)
