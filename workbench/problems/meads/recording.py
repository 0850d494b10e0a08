"""Recording of a MEADS run: heat shield with its ports, air data with ±3σ and truth, per-port fits.

Scene (``/world``, a local East-North-Up frame at the vehicle, metres): the heat shield mesh
(``/world/vehicle/heat_shield``) rotated by the *reconstructed* attitude (IMU strapdown), its
seven ports coloured by the measured pressure (``.../ports``, blue low → red high, scaled to the
sample's highest reading) and, 0.15 m in front of each, a smaller marker coloured by the
normalised fit residual (``.../port_residuals``: green |r| < 1σ → yellow 3σ → red ≥ 6σ, grey
when the port is not used), and the wind-relative velocity as a 3 m segment from the nose towards
where the air comes from (``/world/vehicle/air_velocity``; its angle to the axis is α_T).

Plots (``/plots/<quantity>``, bounded series with truth): ``alpha_deg``, ``beta_deg``,
``qbar_kPa``, ``mach``, ``p_inf_Pa``, ``density_pct_error`` (ρ̂ vs truth, when known, otherwise
ρ̂ in kg/m³), ``wind_north_mps``, ``wind_east_mps``, ``lag_delay_ms``, ``lag_correction_Pa`` (the pneumatic-lag
inversion: corrected − measured pressure of P1 and P4); per port measured vs
modelled (``/plots/ports/<port>/measured|predicted``) and its residual ±3σ
(``/residuals/pressure/<port>``, NaN where the port was not used: a dropped port's line breaks, a
failed port's ends, never a flat zero); failed ports and singular wind intervals in ``/events``.
The least-squares wind is NaN (a gap) where it is not published; truths are wide pale green bands.

The EKF passes (:mod:`.ekf`, smoothed): under each air-data plot, ``ekf_pass<i>`` (pass 2, or the
only pass, with ±3σ; pass 1 as a line only when a pass 2 follows); the transducer scale factors
[%] at ``/plots/scale_factors/pass<i>`` (pass 1: the forward filter's estimate converging, ±3σ;
pass 2: the correction applied, constant) with the true ones at ``/plots/scale_factors/truth``
when known; the forward pressure innovations per port with ±3σ (``√S_ii``) at
``/residuals/pressure_ekf_pass<i>/<port>`` (only where the port was processed).
"""

from __future__ import annotations

import math

import numpy as np
import rerun.blueprint as rrb
import trimesh
from scipy.optimize import linear_sum_assignment

from workbench.core.rotation import quat_conjugate, quat_rotate
from workbench.models.flush_airdata import FadsVehicle
from workbench.problems.meads.ekf import EkfPass
from workbench.problems.meads.pipeline import (
    AirDataStage,
    LagCorrection,
    MeadsResult,
    Navigation,
    PressureData,
    WindStage,
)
from workbench.problems.meads.synthetic import TruthArrays
from workbench.problems.meads.telemetry import true_runs
from workbench.recording import layout
from workbench.recording.blueprint import events_view, plot_view, report_view, tab, y_range_if_needed
from workbench.recording.dispatch import StageDispatch
from workbench.recording.writer import PALETTE, PALETTE_NAMES

__all__ = [
    "meads_blueprint",
    "MeadsRecorder",
    "heat_shield_mesh",
    "PLOTS",
    "view_y_ranges",
    "AIR_DATA_VIEW_PX",
    "PORT_FIT_VIEW_PX",
    "port_label_points",
    "LABEL_RING_M",
    "SCENE_EYE",
    "SCENE_LOOK",
]

PLOTS = (
    ("α [deg]", "alpha_deg"),
    ("β [deg]", "beta_deg"),
    ("q∞ [kPa]", "qbar_kPa"),
    ("Mach [-]", "mach"),
    ("p∞ [Pa]", "p_inf_Pa"),
    ("density [kg/m³]", "density"),
    ("wind N [m/s]", "wind_north_mps"),
    ("wind E [m/s]", "wind_east_mps"),
    ("scale factors [%]", "scale_factors"),
    ("lag [ms]", "lag_delay_ms"),
    ("lag correction [Pa]", "lag_correction_Pa"),
)
#: EKF outputs drawn next to the least-squares ones: (plot quantity, output, scale, label)
EKF_PLOTS = (
    ("alpha_deg", "alpha", 180 / math.pi, "α [deg]"),
    ("beta_deg", "beta", 180 / math.pi, "β [deg]"),
    ("qbar_kPa", "qbar", 1e-3, "q∞ [kPa]"),
    ("mach", "mach", 1.0, "Mach"),
    ("p_inf_Pa", "p_inf", 1.0, "p∞ [Pa]"),
    ("wind_north_mps", "wind_north", 1.0, "north [m/s]"),
    ("wind_east_mps", "wind_east", 1.0, "east [m/s]"),
)


def meads_blueprint(
    ports: tuple[str, ...],
    ekf_passes: int,
    has_truth: bool = False,
    span: tuple[float, float] | None = None,
    air_span: tuple[float, float] | None = None,
    y_ranges: dict[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """Default layout: the heat shield (left top), air-data plots (right top, one tab per quantity),
    per-port tabs (right bottom, one per name of ``ports``, the vehicle's: the pressure left, its
    residual and EKF innovation stacked right; the innovations of the last of ``ekf_passes``, none
    when 0), scorecard and events
    (left bottom). ``has_truth``: the density tab shows the error against the truth [%] (as drawn).
    Views with many series name their colours in the title (a legend covered the curves). ``span``
    (t0, t1) [s]: the pressure samples' span, on which the port views open their x axis, and
    ``air_span`` the span where q∞ is above the objectives' threshold, on which the air-data views
    open theirs (below it the least squares is noise of tens of degrees, and the viewer fits the y
    axis to the x range shown); without them the viewer opens a run of minutes on about a minute
    around the time cursor. ``y_ranges`` {view origin: (lo, hi)} fixes the y axis of those views
    (:func:`view_y_ranges`)."""
    yr = y_ranges or {}
    scene = rrb.Spatial3DView(
        name="Heat shield (reconstructed attitude, local ENU)",
        origin=layout.WORLD,
        eye_controls=rrb.EyeControls3D(position=list(SCENE_EYE), look_target=list(SCENE_LOOK), eye_up=[0.0, 0.0, 1.0]),
    )
    ekf_q = {q for q, _, _, _ in EKF_PLOTS}
    key = "blue least squares, grey ±3σ, wide pale green truth"
    if ekf_passes:
        key += ", magenta EKF pass " + str(ekf_passes) + (", purple earlier passes" if ekf_passes > 1 else "")

    last = f", magenta EKF pass {ekf_passes}" if ekf_passes else ""
    colours = ", ".join(f"{p} {c}" for p, c in zip(ports, PALETTE_NAMES, strict=False))
    titles = {
        "density": (
            f"ρ error vs truth [%] — blue least squares{last}, grey ±3σ, wide pale green truth (0)"
            if has_truth
            else f"density [kg/m³] — blue least squares{last}, grey ±3σ"
        ),
        "scale_factors": f"scale factors [%] — {colours}; thin grey ±3σ; pass 1 converging, later passes flat",
    }

    def quantity(n: str, q: str):
        # the estimators' curves span the whole width: a legend there covered their right ends
        kw = {"span": air_span or span, "y_range": yr.get(layout.plot_path(q))}
        if q in ekf_q:
            return plot_view(f"{n} — {key}", layout.plot_path(q), **kw)
        if q in titles:
            return plot_view(titles[q], layout.plot_path(q), **kw)
        return plot_view(n, layout.plot_path(q), legend="RightTop", **kw)

    def tab_name(n: str, q: str) -> str:
        return "ρ error [%]" if q == "density" and has_truth else n

    plots = rrb.Tabs(*[tab(tab_name(n, q), quantity(n, q)) for n, q in PLOTS], active_tab=0)
    port_tabs = []
    for p in ports:
        # the pressure at full height on the left, residual (and innovation) stacked on the right:
        # three views stacked were each too low for more than one y label (the axis labels decades)
        pressure = plot_view(
            f"{p} [Pa] — black dots measured, orange model", layout.join(layout.MEADS_PLOT_PORTS, p), span=span
        )
        res = layout.residual_path("pressure", p)
        fits = [plot_view(f"{p} residual [Pa] — grey ±3σ", res, span=span, y_range=yr.get(res))]
        if ekf_passes:
            fits.append(
                plot_view(
                    f"{p} EKF pass {ekf_passes} innovation [Pa] — grey ±3σ",
                    layout.meads_ekf_innovation_path(ekf_passes, p),
                    span=span,
                    y_range=yr.get(layout.meads_ekf_innovation_path(ekf_passes, p)),
                )
            )
        port_tabs.append(rrb.Horizontal(pressure, rrb.Vertical(*fits), column_shares=[1, 1], name=p))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                scene,
                rrb.TextDocumentView(name="3D key", origin=layout.SCENE_KEY, contents="$origin"),
                report_view("Scorecard", extra=[events_view()]),
                row_shares=[12, 3, 8],
            ),
            # the port tabs taller than the plots above: their stacked residual and innovation views
            # need the height for two or three y labels; the one view above keeps enough at 2 of 5
            rrb.Vertical(plots, rrb.Tabs(*port_tabs), row_shares=[2, 3]),
            column_shares=[2, 3],
        ),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
    )


#: the heights [CSS px] of an air-data view and of a port's residual or innovation view (a 1400 x
#: 900 window: about 180 and 130)
AIR_DATA_VIEW_PX = 175.0
PORT_FIT_VIEW_PX = 125.0


def view_y_ranges(
    rec, ports: tuple[str, ...], ekf_passes: int, air_span: tuple[float, float] | None
) -> dict[str, tuple[float, float]]:
    """{view origin: (lo, hi)} for the views of :func:`meads_blueprint` whose data (what ``rec``,
    the run's :class:`~workbench.recording.writer.Recorder`, drew; the air-data views' over
    ``air_span`` (t0, t1) [s]) the viewer would label at fewer than three ticks (a span a little
    above a power of ten is labelled at one tick): a legible range (``blueprint.y_range_if_needed``)."""
    views = [(layout.plot_path(q), air_span, AIR_DATA_VIEW_PX) for _, q in PLOTS]
    for p in ports:
        views.append((layout.residual_path("pressure", p), None, PORT_FIT_VIEW_PX))
        if ekf_passes:
            views.append((layout.meads_ekf_innovation_path(ekf_passes, p), None, PORT_FIT_VIEW_PX))
    out = {}
    for origin, window, px in views:
        r = rec.value_range(origin, *(window or (None, None)))
        if r is not None and r[1] > r[0]:
            y = y_range_if_needed(r[0], r[1], px)
            if y is not None:
                out[origin] = y
    return out


def heat_shield_mesh(vehicle: FadsVehicle, n_r: int = 24, n_clock: int = 48) -> trimesh.Trimesh:
    """The forebody as a mesh in body axes B (+x out of the nose, nose at the origin) [m]."""
    r = vehicle.base_radius * np.sin(np.linspace(0.0, 0.5 * math.pi, n_r)) ** 1.0
    x = -vehicle.surface_axial(r)
    c = np.linspace(0.0, 2 * math.pi, n_clock, endpoint=False)
    R, C = np.meshgrid(r, c, indexing="ij")
    X = np.broadcast_to(x[:, None], R.shape)
    V = np.stack([X, R * np.sin(C), R * np.cos(C)], -1).reshape(-1, 3)
    faces = []
    for i in range(n_r - 1):
        for j in range(n_clock):
            a, b = i * n_clock + j, i * n_clock + (j + 1) % n_clock
            faces += [[a, a + n_clock, b], [b, a + n_clock, b + n_clock]]
    return trimesh.Trimesh(V, np.array(faces), process=False)


#: the heat-shield view's camera [m, local ENU at the vehicle, the nose at the origin]
SCENE_EYE = (6.0, -6.0, 3.0)
SCENE_LOOK = (0.0, 0.0, 0.0)
#: radius [m] of the port labels' ring around the nose, facing the camera (the shield's 2.25 m
#: radius and 0.7 m depth seen from any side stay inside 2.4 m)
LABEL_RING_M = 2.9


def port_label_points(
    ports_B: np.ndarray,
    q_ENU_B: np.ndarray,
    eye: tuple[float, float, float] = SCENE_EYE,
    look: tuple[float, float, float] = SCENE_LOOK,
    ring: float = LABEL_RING_M,
) -> np.ndarray:
    """Where each port's name is written at each attitude: (n, m, 3) [m, body axes B] for the ports
    ``ports_B`` (m, 3) [m, B] at the attitudes ``q_ENU_B`` (n, 4) (body → local ENU, scalar last)
    of a shield whose nose is at the ENU origin, seen from ``eye`` towards ``look`` [m, ENU].

    Written 0.3 m in front of their ports, the names of the ports near the nose and on one clock ray
    overlapped. Here, at each attitude, the m names take m slots 360°/m apart on a circle of radius
    ``ring`` around the nose in the plane facing the camera (outside the shield's outline from any
    side), each port the slot nearest the direction it is seen in from the nose (weighted by how far
    from the nose it is seen; a port seen on the nose takes a slot left over), the circle turned to
    fit them best, keeping the previous attitude's turn unless another fits clearly better (names
    that jump about while scrubbing are hard to follow). From the camera no two names are closer
    than the circle's chord, 2·ring·sin(π/m).
    """
    P = np.asarray(ports_B, float)
    q = np.asarray(q_ENU_B, float)
    m = P.shape[0]
    fwd = np.asarray(look, float) - np.asarray(eye, float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    W = quat_rotate(q[:, None, :], P[None, :, :])  # (n, m, 3) ENU
    u, v = W @ right, W @ up
    seen, weight = np.arctan2(v, u), np.hypot(u, v)
    shifts = np.linspace(0.0, 2 * math.pi / m, 12, endpoint=False)
    base = 2 * math.pi * np.arange(m) / m
    out = np.empty((q.shape[0], m, 3))
    prev = None
    for i in range(q.shape[0]):
        fits = []
        for sh in shifts:
            cost = weight[i][:, None] * (1.0 - np.cos(base[None, :] + sh - seen[i][:, None]))
            rows, cols = linear_sum_assignment(cost)
            fits.append((float(cost[rows, cols].sum()), sh, cols[np.argsort(rows)]))
        best = min(fits, key=lambda f: f[0])
        if prev is not None:
            cost = weight[i] * (1.0 - np.cos(base[prev[1]] + prev[0] - seen[i]))
            if float(cost.sum()) <= best[0] + 0.25 * ring:
                best = (float(cost.sum()), prev[0], prev[1])
        prev = (best[1], best[2])
        ang = base[best[2]] + best[1]
        L = ring * (np.cos(ang)[:, None] * right + np.sin(ang)[:, None] * up)
        out[i] = quat_rotate(quat_conjugate(q[i]), L)
    return out


def _port_points(vehicle: FadsVehicle, offset: float) -> np.ndarray:
    r, c, cone = vehicle.radius(), vehicle.clock(), vehicle.cone()
    x = -vehicle.surface_axial(r)
    base = np.stack([x, r * np.sin(c), r * np.cos(c)], 1)
    normal = np.stack([np.cos(cone), np.sin(cone) * np.sin(c), np.sin(cone) * np.cos(c)], 1)
    return base + (0.03 + offset) * normal


#: the truth as a wide translucent band: a thin truth line vanished under the EKF pass drawn on it
TRUTH_STYLE = ((40, 170, 40, 110), 5.0)

#: what the heat-shield scene shows (``layout.SCENE_KEY``, under it)
SCENE_KEY_MD = (
    "**3D key** — heat shield in the reconstructed attitude (local ENU). Large dots on the ports: measured "
    "pressure over the largest port's, blue (low) → red (highest); small dots just off them: the fit's normalised "
    "residual, green ≤ 1σ → yellow 3σ → red ≥ 6σ, grey where the port was not used (dropped or failed); labels: "
    "port names, a thin grey line to each port; blue line: the air-relative velocity (the flow direction, α and β)"
)


def _ramp(u: np.ndarray) -> np.ndarray:
    """Blue → red colours (..., 4) uint8 for u in [0, 1]."""
    u = np.clip(np.nan_to_num(u), 0, 1)
    return np.stack([255 * u, 60 + 80 * (1 - np.abs(2 * u - 1)), 255 * (1 - u), np.full_like(u, 255)], -1).astype(
        np.uint8
    )


def _used_span(use: np.ndarray) -> slice:
    """The rows from a port's first to its last used sample: a series drawn over them with NaN where
    the port was not used breaks at an interior dropout (rows simply left out would join its ends
    with a straight line) and ends where a failed port stopped (no trailing flat zero)."""
    k = np.flatnonzero(use)
    return slice(int(k[0]), int(k[-1]) + 1) if k.size else slice(0, 0)


def _residual_colors(z: np.ndarray, used: np.ndarray) -> np.ndarray:
    z = np.abs(np.nan_to_num(z, nan=0.0))
    g = np.clip(1 - (z - 1) / 5, 0, 1)
    col = np.stack([np.clip(z / 3, 0, 1) * 255, g * 220, np.zeros_like(z), np.full_like(z, 255)], -1)
    col[~used] = (120, 120, 120, 255)
    return col.astype(np.uint8)


class MeadsRecorder:
    """Draws the stages of :func:`workbench.problems.meads.pipeline.reconstruct` (truth: the arrays
    of ``truth.npz`` or None)."""

    def __init__(self, rec, truth: dict | None) -> None:
        self.rec = rec
        self.truth = None if truth is None else TruthArrays(truth)
        self.vehicle: FadsVehicle | None = None
        self.nav: Navigation | None = None
        self._fit = None
        self.handle = StageDispatch(
            {
                PressureData: self._data,
                Navigation: self._nav,
                LagCorrection: self._lag,
                AirDataStage: self._air,
                WindStage: self._wind,
                EkfPass: self._ekf,
                MeadsResult: self._result,
            }
        )

    def _truth(self, key: str, t: np.ndarray, scale: float = 1.0, col: int | None = None):
        return None if self.truth is None else self.truth.at(key, t, scale, col)

    def _data(self, st: PressureData) -> None:
        self.vehicle = st.vehicle
        self.rec.view_coordinates()
        self.rec.mesh(layout.MEADS_HEAT_SHIELD, heat_shield_mesh(st.vehicle), color=(170, 120, 80, 255))
        tel = st.telemetry
        for j, p in enumerate(tel.ports):
            self.rec.scatter(
                layout.meads_port_plot_path(p, layout.MEASURED_SERIES),
                tel.t_p,
                tel.p[:, j],
                names=f"{p} measured [Pa]",
                colors=(30, 30, 30),
                size=1.5,
            )
        self.rec.events([(float(tel.t_p[0]), d, "WARN") for d in tel.degradations])

    def _nav(self, st: Navigation) -> None:
        self.nav = st
        self.rec.poses(layout.VEHICLE, st.t_p, np.zeros((st.t_p.size, 3)), st.q_ENU_B())

    def _lag(self, st: LagCorrection) -> None:
        self.rec.scalars(
            layout.join(layout.plot_path("lag_delay_ms"), "P1_P4"),
            st.t,
            1e3 * st.delay[:, [0, 3]],
            names=["P1 delay [ms]", "P4 delay [ms]"],
        )
        # before/after the inversion: what the correction added to the measured pressure
        self.rec.scalars(
            layout.join(layout.plot_path("lag_correction_Pa"), "P1_P4"),
            st.t,
            np.nan_to_num(st.correction[:, [0, 3]]),
            names=["P1 corrected − measured [Pa]", "P4 corrected − measured [Pa]"],
        )

    def _air(self, st: AirDataStage) -> None:
        f, t = st.fit, st.t
        self._fit = f
        rec = self.rec
        # the fit's outputs in display units: value and 1σ (same conversion), truth scale, label
        for name, plot, to_unit, truth_scale, label in (
            ("alpha", "alpha_deg", np.degrees, 180 / math.pi, "α [deg]"),
            ("beta", "beta_deg", np.degrees, 180 / math.pi, "β [deg]"),
            ("qbar", "qbar_kPa", lambda v: v / 1e3, 1e-3, "q∞ [kPa]"),
        ):
            rec.series_with_bounds(
                layout.plot_path(plot),
                t,
                to_unit(getattr(f, name)),
                to_unit(getattr(f, f"sigma_{name}")),
                truth=self._truth(name, t, truth_scale),
                names=label,
                truth_style=TRUTH_STYLE,
            )
        z = f.normalized_residual
        for j, p in enumerate(self.vehicle.port_names):
            rec.scalars(
                layout.meads_port_plot_path(p, layout.PREDICTED_SERIES),
                t,
                f.predicted[:, j],
                names=f"{p} model ({f.model}) [Pa]",
                colors=(220, 90, 30),
            )
            r = st.residual_used[:, j]
            use = np.isfinite(r) & np.isfinite(f.sigma_p[:, j])
            if use.any():
                k = _used_span(use)
                rec.series_with_bounds(
                    layout.residual_path("pressure", p),
                    t[k],
                    np.where(use, r, np.nan)[k],
                    np.where(use, f.sigma_p[:, j], np.nan)[k],
                    names=f"{p} residual [Pa]",
                )
        # 3D: ports coloured by the measured pressure and by the normalised residual
        pts = _port_points(self.vehicle, 0.0)
        pr = _port_points(self.vehicle, 0.15)
        every = max(1, t.size // 600)
        k = np.arange(0, t.size, every)
        meas = f.measured
        u = meas[k] / np.maximum(np.nanmax(meas[k], axis=1, keepdims=True), 1e-9)
        rec.points_series(
            layout.MEADS_PORTS, t[k], np.broadcast_to(pts, (k.size, *pts.shape)), colors=_ramp(u), radii=0.09
        )
        rec.points_series(
            layout.MEADS_PORT_RESIDUALS,
            t[k],
            np.broadcast_to(pr, (k.size, *pr.shape)),
            colors=_residual_colors(z[k], st.mask[k]),
            radii=0.05,
        )
        # the port names around the shield, apart as the camera sees them, a leader line to each port
        nav = self.nav
        if nav is not None and nav.t_p.size == t.size:
            lab = port_label_points(pts, nav.q_ENU_B()[k])
            rec.text_labels_series(layout.MEADS_PORT_LABELS, t[k], lab, list(self.vehicle.port_names))
            leaders = np.stack([np.broadcast_to(pts, lab.shape), lab], 2)  # (n, m, 2, 3)
            rec.line_strips_series(layout.MEADS_PORT_LEADERS, t[k], leaders, colors=(110, 110, 110), radii=-0.75)
        rec.report(SCENE_KEY_MD, entity=layout.SCENE_KEY)
        rec.events([(fl.t, fl.message, "WARN") for fl in st.failures])

    def _wind(self, st: WindStage) -> None:
        rec, nav = self.rec, self.nav
        t = nav.t_p
        rec.series_with_bounds(
            layout.plot_path("mach"),
            t,
            st.mach,
            st.sigma_mach,
            truth=self._truth("mach", t),
            names="Mach",
            truth_style=TRUTH_STYLE,
        )
        rec.series_with_bounds(
            layout.plot_path("p_inf_Pa"),
            t,
            st.p_inf,
            st.sigma_p_inf,
            truth=self._truth("p_inf", t),
            names="p∞ [Pa]",
            truth_style=TRUTH_STYLE,
        )
        rt = self._truth("rho", t)
        if rt is not None:
            rec.series_with_bounds(
                layout.plot_path("density"),
                t,
                *st.density_error_pct(rt),
                truth=np.zeros_like(t),
                names="ρ error [%]",
                truth_style=TRUTH_STYLE,
            )
        else:
            rec.series_with_bounds(layout.plot_path("density"), t, st.density, st.sigma_density, names="ρ [kg/m³]")
        w = st.winds
        for j, q in enumerate(("wind_north_mps", "wind_east_mps")):
            # a gap (NaN) where the least squares publish no wind: a flat 0 with a zero-width band
            # read as a perfectly known calm
            v, sd = w.wind_NE[:, j], w.sigma_NE[:, j]
            shown = np.isfinite(v) & np.isfinite(sd)
            rec.series_with_bounds(
                layout.plot_path(q),
                t,
                np.where(shown, v, np.nan),
                np.where(shown, sd, np.nan),
                truth=self._truth("wind_NE", t, col=j),
                names=f"{'north' if j == 0 else 'east'} [m/s] (a gap where not published)",
                truth_style=TRUTH_STYLE,
            )
        # wind-relative velocity arrow in body axes, from the air-data angles
        d = self._fit.air_direction_B
        every = max(1, t.size // 600)
        k = np.arange(0, t.size, every)
        strips = np.stack([np.zeros((k.size, 3)), 3.0 * d[k]], 1)
        rec.line_strips_series(layout.MEADS_AIR_VELOCITY, t[k], strips, colors=(40, 160, 255), radii=0.03)
        ev = [
            (
                float(t[a0]),
                f"wind solution singular (|det Γ| small, flight-path angle near zero) {t[a0]:.1f}-"
                f"{t[b0]:.1f} s: not published",
                "INFO",
            )
            for a0, b0 in true_runs(w.singular)
        ]
        rec.events(ev)

    def _ekf(self, st: EkfPass) -> None:
        rec, t = self.rec, st.t
        last = st.index == st.passes
        col = (200, 40, 160) if last else (120, 90, 200)
        for q, name, scale, label in EKF_PLOTS:
            v, s = st.output(name)
            path = layout.meads_ekf_plot_path(q, st.index)
            lab = f"EKF pass {st.index} {label}"
            if last:
                rec.series_with_bounds(path, t, scale * v, scale * s, names=lab, color=[col])
            else:
                rec.scalars(layout.join(path, layout.VALUE), t, scale * v, names=lab, colors=[col])
        rho, srho = st.output("rho")
        rt = self._truth("rho", t)
        path = layout.meads_ekf_plot_path("density", st.index)
        if rt is not None:
            if last:
                rec.series_with_bounds(
                    path,
                    t,
                    *st.output_error_pct("rho", rt),
                    names=f"EKF pass {st.index} ρ error [%]",
                    color=[col],
                )
        elif last:
            rec.series_with_bounds(path, t, rho, srho, names=f"EKF pass {st.index} ρ [kg/m³]", color=[col])
        # scale factors [%]: pass 1 the forward estimate converging, pass 2 the correction applied
        ports = self.vehicle.port_names
        m = len(ports)
        lam, slam = st.scale_history()
        rec.series_with_bounds(
            layout.meads_scale_factor_path(f"pass{st.index}"),
            t,
            100 * lam,
            100 * slam,
            names=[f"{p} pass {st.index} [%]" for p in ports],
        )
        if self.truth is not None and "sensor_scale" in self.truth and st.index == 1:
            rec.scalars(
                layout.meads_scale_factor_path(layout.TRUTH_SERIES),
                t,
                100 * np.broadcast_to(np.asarray(self.truth["sensor_scale"], float), (t.size, m)),
                names=[f"{p} truth [%]" for p in ports],
                colors=[PALETTE[j % len(PALETTE)] for j in range(m)],  # its port's colour, as named
                widths=0.8,
            )
        inn, sd = st.forward.innovations.get("pressure"), st.innovation_sigma()
        if inn is not None:
            for j, p in enumerate(ports):
                use = np.isfinite(inn.y[:, j]) & np.isfinite(sd[:, j])
                if not use.any():
                    continue
                k = _used_span(use)
                rec.series_with_bounds(
                    layout.meads_ekf_innovation_path(st.index, p),
                    inn.t[k],
                    np.where(use, inn.y[:, j], np.nan)[k],
                    np.where(use, sd[:, j], np.nan)[k],
                    names=f"{p} EKF pass {st.index} innovation [Pa]",
                )

    def _result(self, st: MeadsResult) -> None:
        pass
