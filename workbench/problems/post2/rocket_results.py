"""Rocket results of a post2 reconstruction of a flight with a ``[launch]`` pad (issue #27 item 2): the
smoothed trajectory in the pad's local frame and the numbers a rocketeer asks for, from the
reconstruction alone (references — the metadata's apogee, the landed coordinates — are scored apart,
:func:`workbench.problems.post2.rocket.score_flight`, which reads its apogee and landing covariance here).

Frames (the import's convention): the inertial frame M has the planet-fixed axes at t = 0 (launch),
so the planet-fixed position is R_z(−ω t) p_M.  The pad is at the launch coordinates (geodetic latitude
taken as spherical, as the import does) at ``pad_altitude_m`` above the reference sphere; east, north,
up are along the pad's ENU axes (planet-fixed, m from the pad).  The altitude above the pad is along the
local vertical at the vehicle, h = |p| − R − h_pad, 1σ √(uᵀ P_pp u) with u = p/|p|.  Velocities are
relative to the rotating planet, v_M − ω × p_M; the vertical speed is along u, the speed its norm.

The summary block (:func:`summary_block`, JSON-ready, SI; latitude/longitude and bearings in deg,
named so):

* ``apogee`` — the highest smoothed altitude above the pad ± 1σ and its time;
* ``max_speed`` — the largest planet-relative speed over the reconstructed span (it starts after
  the burnout: the boost is integrated from the IMU by the import, outside this run);
* ``burnout`` — the speed ± 1σ at the first grid time at or after ``[launch] burnout_s``;
* ``landing`` — latitude/longitude at the last grid time (touchdown when the span reaches
  ``touchdown_s``, else where the data end) and the 1σ and 3σ ellipses of the horizontal position
  covariance there (semi-axes [m], major axis bearing from north [deg]; they hold 39.3 % and 98.9 %
  of a 2-D Gaussian);
* ``descent`` — the mean downward speed under the drogue and under the main (events with ``chute``)
  from DESCENT_SETTLE_S after the opening to the next opening or the end, with the mean 1σ of the
  estimate over the phase (an upper bound of the mean's 1σ) and the spread of the rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from workbench.core.bodies import EARTH

__all__ = [
    "DESCENT_SETTLE_S",
    "LocalTrack",
    "enu_axes",
    "pad_frame",
    "earth_fixed",
    "altitude_above_pad",
    "vertical_sigma",
    "horizontal_covariance",
    "ellipse",
    "LANDING_MIXTURE_SPAN_SIGMA",
    "LANDING_MIXTURE_MAX_NODES",
    "LANDING_MIXTURE_SAMPLES",
    "LANDING_MIXTURE_SEED",
    "landing_heading_mixture",
    "heading_ring",
    "covariance_given_heading",
    "local_track",
    "summary_block",
    "moments",
    "headline",
    "markdown",
    "format_lat_lon",
]

#: the descent rates start this long after each parachute opening [s] (the opening transient: the
#: rate reaches the canopy's within ~2 s on the three FIRM flights)
DESCENT_SETTLE_S = 3.0
#: probability content of the 1σ and 3σ ellipses of a 2-D Gaussian: 1 − exp(−k²/2)
_ELLIPSE_CONTENT = {1: 1.0 - math.exp(-0.5), 3: 1.0 - math.exp(-4.5)}


@dataclass(frozen=True, eq=False)
class LocalTrack:
    """The smoothed trajectory in the pad's frame at the grid ``t`` (n,) [s after launch]:
    ``altitude`` (n,) [m above the pad along the local vertical] and its 1σ ``sigma_altitude``;
    ``enu`` (n, 3) [m east, north, up of the pad, the pad's axes] and 1σ ``sigma_enu`` (n, 3);
    ``downrange`` (n,) [m, horizontal distance from the pad] and 1σ; ``vertical_speed`` (n,) [m/s, up
    positive] and 1σ; ``speed`` (n,) [m/s, planet-relative] and 1σ; ``lat``, ``lon`` (n,) [rad]
    (spherical, the import's convention) with 1σ ``sigma_lat``, ``sigma_lon`` [rad]."""

    t: np.ndarray
    altitude: np.ndarray
    sigma_altitude: np.ndarray
    enu: np.ndarray
    sigma_enu: np.ndarray
    downrange: np.ndarray
    sigma_downrange: np.ndarray
    vertical_speed: np.ndarray
    sigma_vertical_speed: np.ndarray
    speed: np.ndarray
    sigma_speed: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    sigma_lat: np.ndarray
    sigma_lon: np.ndarray


def enu_axes(lat: float, lon: float) -> np.ndarray:
    """C_M_ENU (3, 3): columns east, north, up at spherical latitude/longitude [rad] (M = the
    planet-fixed axes at launch)."""
    up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    return np.column_stack([east, np.cross(up, east), up])


def _rotation_to_fixed(t: np.ndarray, omega: float) -> np.ndarray:
    """R_z(−ω t) (n, 3, 3): inertial M (planet-fixed at t = 0) to planet-fixed axes at t (n,) [s]."""
    a = -omega * np.asarray(t, float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((a.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def pad_frame(launch, t: float, radius_ref: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """(C (3, 3), p0 (3,) [m]) of the ``[launch]`` pad at ``t`` [s after launch]: east/north/up of the
    pad = C (p_I − p0) for an inertial position p_I [m] (C: inertial M to the pad's planet-fixed east,
    north, up axes; p0: the pad in M at t, ``launch.pad_altitude_m`` above the sphere of ``radius_ref``
    [m], the planet turned by ``omega`` [rad/s] t about +Z)."""
    lat, lon = math.radians(launch.lat_deg), math.radians(launch.lon_deg)
    C_M_ENU = enu_axes(lat, lon)
    R_fix = _rotation_to_fixed(np.array([t]), omega)[0]  # M -> planet-fixed at t
    p_pad = (radius_ref + launch.pad_altitude_m) * C_M_ENU[:, 2]
    return C_M_ENU.T @ R_fix, R_fix.T @ p_pad


def earth_fixed(p_M: np.ndarray, t: np.ndarray, omega: float = EARTH.rotation_rate) -> np.ndarray:
    """Planet-fixed position (n, 3) [m] of inertial ``p_M`` (n, 3) [m] at ``t`` (n,) [s after launch]
    (M = the planet-fixed axes at launch; rotation ``omega`` [rad/s] about +Z)."""
    a = -omega * np.asarray(t, float)
    c, s = np.cos(a), np.sin(a)
    return np.column_stack([c * p_M[:, 0] - s * p_M[:, 1], s * p_M[:, 0] + c * p_M[:, 1], p_M[:, 2]])


def altitude_above_pad(p_M: np.ndarray, radius: float, h_pad: float) -> np.ndarray:
    """Altitude above the pad (n,) [m] along the local vertical of positions ``p_M`` (n, 3) [m]:
    |p| − ``radius`` − ``h_pad`` (sphere of ``radius`` [m], pad ``h_pad`` [m] above it)."""
    return np.linalg.norm(p_M, axis=1) - radius - h_pad


def vertical_sigma(p_M: np.ndarray, P_pp: np.ndarray) -> np.ndarray:
    """1σ (n,) [m] of the altitude at positions ``p_M`` (n, 3) [m] with position covariances ``P_pp``
    (n, 3, 3) [m²]: √(uᵀ P u), u = p/|p| the local vertical."""
    u = p_M / np.linalg.norm(p_M, axis=1)[:, None]
    return np.sqrt(np.einsum("ni,nij,nj->n", u, P_pp, u))


def horizontal_covariance(p_M: np.ndarray, t: float, P_pp: np.ndarray, omega: float = EARTH.rotation_rate):
    """(lat_deg, lon_deg, P_en): spherical latitude/longitude [deg] of the inertial position ``p_M``
    (3,) [m] at ``t`` [s after launch] and its position covariance ``P_pp`` (3, 3) [m²] projected on
    the local east/north there, (2, 2) [m²]."""
    pe = earth_fixed(np.asarray(p_M, float)[None, :], np.array([t]), omega)[0]
    lat = math.degrees(math.asin(pe[2] / np.linalg.norm(pe)))
    lon = math.degrees(math.atan2(pe[1], pe[0]))
    C_M_ENU = enu_axes(math.radians(lat), math.radians(lon))
    C_EN_I = (C_M_ENU.T @ _rotation_to_fixed(np.array([t]), omega)[0])[:2]
    return lat, lon, C_EN_I @ P_pp @ C_EN_I.T


def ellipse(P_en: np.ndarray, k: float = 1.0) -> tuple[float, float, float]:
    """The kσ ellipse of a horizontal covariance ``P_en`` (2, 2) [m², east/north]: (semi-major,
    semi-minor [m], bearing of the major axis from north towards east [deg, 0..180))."""
    w, V = np.linalg.eigh(0.5 * (P_en + P_en.T))
    e, n = V[:, 1]
    return k * math.sqrt(max(w[1], 0.0)), k * math.sqrt(max(w[0], 0.0)), math.degrees(math.atan2(e, n)) % 180.0


#: the landing's non-linear verdict: the heading grid spans ±LANDING_MIXTURE_SPAN_SIGMA σ with nodes
#: at most half the smaller landing 1σ apart along the ring (at most LANDING_MIXTURE_MAX_NODES);
#: draws and seed of its Monte Carlo level
LANDING_MIXTURE_SPAN_SIGMA = 4.0
LANDING_MIXTURE_MAX_NODES = 4001
LANDING_MIXTURE_SAMPLES = 20000
LANDING_MIXTURE_SEED = 9


def covariance_given_heading(P: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, float]:
    """(P_given (n_e, n_e), σ_ψ [rad]) from an error covariance ``P`` (n_e, n_e) that carries the pad
    heading as the turn ``n`` (n_e,) per radian: σ_ψ² = 1 / (nᵀ P⁻¹ n), the largest share of ``P`` along
    ``n`` (what the data left of the heading), and P_given = P − σ_ψ² n nᵀ the covariance given the
    heading (P Jacobi-scaled before its inverse)."""
    d = np.sqrt(np.diag(P))
    w, V = np.linalg.eigh(P / np.outer(d, d))
    m = V.T @ (n / d)
    var = 1.0 / float(np.sum(m**2 / np.maximum(w, 1e-300)))
    G = P - var * np.outer(n, n)
    return 0.5 * (G + G.T), math.sqrt(var)


def landing_heading_mixture(landing_en, P_en, t, wind_en, sigma_heading: float):
    """The landing point's distribution under a pad heading error of 1σ ``sigma_heading`` [rad],
    pushed through exactly instead of linearised: (means (K, 2) [m], covariances (K, 2, 2) [m²],
    weights (K,), wind drift (2,) [m]), a Gaussian mixture over a grid of heading errors (spacing
    along the ring at most half the smaller 1σ of ``P_en``, so the ring stays continuous).

    A heading error turns the whole air-relative path about the pad (the boost is integrated in a
    frame turned by it, and the coast and descent follow from the boost), while the drift with the
    wind does not turn: with ``landing_en`` (2,) [m east/north of the pad] the reconstructed landing
    and ``wind_en`` (n, 2) [m/s] the smoothed wind at ``t`` (n,) [s] (None: no wind state), the wind
    drift is D_w = ∫ w dt and the node ψ_k lands at D_w + R(ψ_k)(landing − D_w).  Each node's
    covariance is ``P_en`` (2, 2), the error given the heading: the filter's own where it did not
    carry the heading, else its covariance less the heading's share (:func:`covariance_given_heading`)."""
    landing_en = np.asarray(landing_en, float)
    if wind_en is None:
        d_w = np.zeros(2)
    else:
        w = np.asarray(wind_en, float)
        d_w = np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(np.asarray(t, float))[:, None], axis=0)
    e, n = landing_en - d_w
    span = LANDING_MIXTURE_SPAN_SIGMA * sigma_heading
    sig_min = math.sqrt(float(np.min(np.linalg.eigvalsh(P_en))))
    k = int(np.clip(math.ceil(2.0 * span * math.hypot(e, n) / (0.5 * sig_min)) + 1, 41, LANDING_MIXTURE_MAX_NODES))
    psi = np.linspace(-span, span, k | 1)  # odd: a node at no heading error
    wts = np.exp(-0.5 * (psi / sigma_heading) ** 2)
    c, s = np.cos(psi), np.sin(psi)
    means = d_w + np.column_stack([c * e + s * n, -s * e + c * n])  # a heading error ψ turns bearings by +ψ
    covs = np.broadcast_to(np.asarray(P_en, float), (psi.size, 2, 2))
    return means, covs, wts / wts.sum(), d_w


def heading_ring(landing_en, P_en, t, wind_en, sigma_heading_deg: float) -> dict:
    """Where a flight whose pad heading is untrusted can have landed (JSON-ready): the air-relative
    path turned about the pad by the heading error (:func:`landing_heading_mixture`) puts the landing
    on an arc of ``radius_m`` about the wind drift ``centre_en_m`` [m east/north of the pad], bearings
    (from the centre, deg from north) ``bearing_deg`` ± 3σ of the heading (the whole ring when 3σ ≥
    180°), each point with the filter's ``P_en`` (2, 2) [m²] about it; ``max_miss_3sigma_m`` the
    farthest a 3σ landing lies from the reconstructed point (chord plus the ellipse's 3σ)."""
    means, _covs, _w, d_w = landing_heading_mixture(landing_en, P_en, t, wind_en, math.radians(sigma_heading_deg))
    r = np.asarray(landing_en, float) - d_w
    radius = float(np.hypot(*r))
    half = min(3.0 * float(sigma_heading_deg), 180.0)
    chord = 2.0 * radius * math.sin(math.radians(half) / 2.0)
    return {
        "heading_sigma_deg": float(sigma_heading_deg),
        "centre_en_m": d_w.tolist(),
        "radius_m": radius,
        "bearing_deg": float(math.degrees(math.atan2(r[0], r[1])) % 360.0),
        "half_width_3sigma_deg": half,
        "whole_ring": bool(half >= 180.0),
        "max_miss_3sigma_m": chord + 3.0 * math.sqrt(float(np.max(np.linalg.eigvalsh(P_en)))),
    }


def local_track(site, t, p_M, v_M, P_pp, P_vv, radius: float, omega: float) -> LocalTrack:
    """The :class:`LocalTrack` of a smoothed trajectory: ``site`` the settings' ``[launch]``
    (:class:`~workbench.problems.post2.config.LaunchSite`), ``t`` (n,) [s after launch], inertial
    ``p_M``, ``v_M`` (n, 3) [m, m/s], their covariances ``P_pp``, ``P_vv`` (n, 3, 3), the reference
    sphere's ``radius`` [m] and the planet's rotation ``omega`` [rad/s]."""
    t = np.asarray(t, float)
    R = _rotation_to_fixed(t, omega)
    C_M_ENU = enu_axes(math.radians(site.lat_deg), math.radians(site.lon_deg))
    pad = (radius + site.pad_altitude_m) * C_M_ENU[:, 2]
    pe = np.einsum("nij,nj->ni", R, p_M)
    enu = (pe - pad) @ C_M_ENU
    C = np.einsum("ji,njk->nik", C_M_ENU, R)  # C_ENU_M(t) (n, 3, 3)
    P_enu = np.einsum("nij,njk,nlk->nil", C, P_pp, C)
    sig_enu = np.sqrt(np.einsum("nii->ni", P_enu))
    d = np.hypot(enu[:, 0], enu[:, 1])
    w = np.where(d[:, None] > 0.0, enu[:, :2] / np.maximum(d, 1e-12)[:, None], [1.0, 0.0])
    sig_d = np.sqrt(np.einsum("ni,nij,nj->n", w, P_enu[:, :2, :2], w))
    r = np.linalg.norm(p_M, axis=1)
    u = p_M / r[:, None]
    v_rel = v_M - np.cross([0.0, 0.0, omega], p_M)
    speed = np.linalg.norm(v_rel, axis=1)
    s_hat = v_rel / np.maximum(speed, 1e-12)[:, None]
    lat = np.arcsin(pe[:, 2] / r)
    return LocalTrack(
        t,
        altitude_above_pad(p_M, radius, site.pad_altitude_m),
        vertical_sigma(p_M, P_pp),
        enu,
        sig_enu,
        d,
        sig_d,
        np.einsum("ni,ni->n", v_rel, u),
        np.sqrt(np.einsum("ni,nij,nj->n", u, P_vv, u)),
        speed,
        np.sqrt(np.einsum("ni,nij,nj->n", s_hat, P_vv, s_hat)),
        lat,
        np.arctan2(pe[:, 1], pe[:, 0]),
        sig_enu[:, 1] / r,
        sig_enu[:, 0] / (r * np.maximum(np.cos(lat), 1e-12)),
    )


def _phases(events, chutes: dict[str, str], t_end: float) -> list[tuple[str, float, float]]:
    """[(chute, opening time, end time)] of the parachute phases: ``events`` ((t [s], name), ...) fired,
    ``chutes`` {event name: "drogue" | "main"}; a phase ends at the next opening or ``t_end`` [s]."""
    opens = sorted((float(te), chutes[n]) for te, n in events if chutes.get(n) in ("drogue", "main"))
    return [(c, te, opens[i + 1][0] if i + 1 < len(opens) else t_end) for i, (te, c) in enumerate(opens)]


def summary_block(
    site, track: LocalTrack, P_pp_last: np.ndarray, events, chutes, omega: float, p_last, wind_en=None,
    given_heading=None,
) -> dict:  # fmt: skip
    """The ``summary["rocket"]`` block (module docstring): ``site`` the ``[launch]`` settings,
    ``track`` the :class:`LocalTrack`, ``P_pp_last`` (3, 3) [m²] and ``p_last`` (3,) [m] the inertial
    position covariance and position at the last grid time, ``events`` ((t [s], name), ...) fired,
    ``chutes`` {event name: "drogue" | "main"}, ``omega`` [rad/s] the planet's rotation, ``wind_en``
    (n, 2) [m/s] the smoothed wind on the grid (None: no wind state) — with an untrusted pad heading
    the landing's region is the heading ring (:func:`heading_ring`), not the linearised ellipse;
    ``given_heading`` (P_pp (3, 3) [m²], σ_ψ [rad]) when ``P_pp_last`` carries the heading itself
    (:func:`covariance_given_heading`): the ring's nodes then take P_pp and σ_ψ, not the declared σ."""
    tr = track
    t = tr.t
    k = int(np.argmax(tr.altitude))
    m = int(np.argmax(tr.speed))
    out: dict = {
        "frame": "pad ENU (planet-fixed); altitude above the pad along the local vertical; planet-relative velocity",
        "pad": {"lat_deg": site.lat_deg, "lon_deg": site.lon_deg, "pad_altitude_m": site.pad_altitude_m},
        "span_s": [float(t[0]), float(t[-1])],
        "apogee": {
            "altitude_m": float(tr.altitude[k]),
            "sigma_m": float(tr.sigma_altitude[k]),
            "t_s": float(t[k]),
        },
        "max_speed": {
            "speed_m_s": float(tr.speed[m]),
            "sigma_m_s": float(tr.sigma_speed[m]),
            "t_s": float(t[m]),
            "note": "over the reconstructed span, which starts after the burnout",
        },
    }
    if site.burnout_s is not None:
        b = int(min(np.searchsorted(t, site.burnout_s - 1e-9), t.size - 1))
        out["burnout"] = {
            "t_s": float(site.burnout_s),
            "at_t_s": float(t[b]),
            "speed_m_s": float(tr.speed[b]),
            "sigma_m_s": float(tr.sigma_speed[b]),
            "altitude_m": float(tr.altitude[b]),
        }
    lat, lon, P_en = horizontal_covariance(p_last, float(t[-1]), P_pp_last, omega)
    a1, b1, o1 = ellipse(P_en, 1.0)
    a3, b3, _ = ellipse(P_en, 3.0)
    touched = site.touchdown_s is not None and float(t[-1]) >= site.touchdown_s - 1e-6
    out["landing"] = {
        "touchdown": bool(touched),
        "t_s": float(t[-1]),
        "lat_deg": lat,
        "lon_deg": lon,
        "east_m": float(tr.enu[-1, 0]),
        "north_m": float(tr.enu[-1, 1]),
        "drift_from_pad_m": float(tr.downrange[-1]),
        "bearing_from_pad_deg": float(math.degrees(math.atan2(tr.enu[-1, 0], tr.enu[-1, 1])) % 360.0),
        "altitude_m": float(tr.altitude[-1]),
        "sigma_east_m": float(math.sqrt(P_en[0, 0])),
        "sigma_north_m": float(math.sqrt(P_en[1, 1])),
        "ellipse_1sigma": {"semi_major_m": a1, "semi_minor_m": b1, "orientation_deg": o1,
                           "probability": _ELLIPSE_CONTENT[1]},
        "ellipse_3sigma": {"semi_major_m": a3, "semi_minor_m": b3, "orientation_deg": o1,
                           "probability": _ELLIPSE_CONTENT[3]},
        "heading_trusted": bool(site.heading_trusted),
    }  # fmt: skip
    if not touched:
        out["landing"]["note"] = "the data end before touchdown: the position at the end of the span"
    if not site.heading_trusted:
        sig, P_ring = site.heading_sigma_deg, P_en
        if given_heading is not None:
            P_ring = horizontal_covariance(p_last, float(t[-1]), given_heading[0], omega)[2]
            sig = math.degrees(given_heading[1])
        ring = heading_ring(np.array([tr.enu[-1, 0], tr.enu[-1, 1]]), P_ring, t, wind_en, sig)
        half = ring["half_width_3sigma_deg"]
        out["landing"]["heading_ring"] = ring
        out["landing"]["ellipse_note"] = (
            f"the pad heading is untrusted ({sig:.0f}° 1σ): the linearised ellipse "
            + ("is the heading's first order" if given_heading is not None else "understates the cross-range")
            + "; "
            f"the landing lies on {'a ring' if ring['whole_ring'] else 'an arc'} of radius {ring['radius_m']:.0f} m "
            f"about the wind drift ({ring['centre_en_m'][0]:.0f} m E, {ring['centre_en_m'][1]:.0f} m N of the pad)"
            + ("" if ring["whole_ring"] else f", bearings {ring['bearing_deg']:.0f}° ± {half:.0f}° (3σ)")
            + f", up to {ring['max_miss_3sigma_m']:.0f} m from the point reported (heading_ring)"
        )
    descent = {}
    for chute, t_a, t_b in _phases(events, chutes, float(t[-1])):
        sel = (t >= t_a + DESCENT_SETTLE_S) & (t <= t_b)
        if np.count_nonzero(sel) < 2 or chute in descent:
            continue
        rate = -tr.vertical_speed[sel]
        descent[chute] = {
            "rate_m_s": float(np.mean(rate)),
            "sigma_m_s": float(np.mean(tr.sigma_vertical_speed[sel])),
            "spread_m_s": float(np.std(rate)),
            "window_s": [float(t[sel][0]), float(t[sel][-1])],
        }
    out["descent"] = descent
    return out


def moments(block: dict) -> list[tuple[str, float, str]]:
    """[(name, t [s], one-line description)] of the rocket's key moments from its summary block:
    ``burnout`` (at the first grid time after it: the reconstruction starts after the tail-off),
    ``apogee`` and ``landing`` (only when the span reaches the touchdown)."""
    out = []
    b = block.get("burnout")
    if b is not None:
        out.append(
            (
                "burnout",
                b["at_t_s"],
                f"motor burnout at {b['t_s']:.2f} s (first coast row); here {b['speed_m_s']:.0f} ± "
                f"{b['sigma_m_s']:.1f} m/s, {b['altitude_m']:.0f} m above the pad",
            )
        )
    a = block["apogee"]
    out.append(("apogee", a["t_s"], f"apogee {a['altitude_m']:.0f} ± {a['sigma_m']:.1f} m above the pad"))
    la = block["landing"]
    if la["touchdown"]:
        out.append(("landing", la["t_s"], f"touchdown at {format_lat_lon(la['lat_deg'], la['lon_deg'])}"))
    return out


def format_lat_lon(lat_deg: float, lon_deg: float) -> str:
    """``32.12345°N 106.12345°W`` from latitude/longitude [deg] (5 decimals: ~1 m)."""
    lon = (lon_deg + 180.0) % 360.0 - 180.0
    return f"{abs(lat_deg):.5f}°{'N' if lat_deg >= 0 else 'S'} {abs(lon):.5f}°{'E' if lon >= 0 else 'W'}"


def headline(block: dict) -> str:
    """One line: apogee ± 1σ above the pad and its time; max speed; landing point with the 3σ ellipse
    (with an untrusted pad heading: the heading ring's 3σ reach instead)."""
    a, s, la = block["apogee"], block["max_speed"], block["landing"]
    e = la["ellipse_3sigma"]
    where = "landing" if la["touchdown"] else f"last fix (t = {la['t_s']:.1f} s, in flight)"
    ring = la.get("heading_ring")
    spread = (
        f"3σ ellipse {e['semi_major_m']:.0f} × {e['semi_minor_m']:.0f} m"
        if ring is None
        else f"heading untrusted: within {ring['max_miss_3sigma_m']:.0f} m (3σ), on "
        f"{'a ring' if ring['whole_ring'] else 'an arc'} of radius {ring['radius_m']:.0f} m about the wind drift"
    )
    return (
        f"apogee {a['altitude_m']:.0f} ± {a['sigma_m']:.0f} m above the pad at {a['t_s']:.1f} s; "
        f"max speed {s['speed_m_s']:.0f} m/s; {where} {format_lat_lon(la['lat_deg'], la['lon_deg'])} ({spread})"
    )


def markdown(block: dict) -> str:
    """The rocket results as a markdown table (the scorecard's first section)."""
    a, s, la = block["apogee"], block["max_speed"], block["landing"]
    e1, e3 = la["ellipse_1sigma"], la["ellipse_3sigma"]
    rows = [("apogee above the pad", f"{a['altitude_m']:.1f} ± {a['sigma_m']:.1f} m", f"{a['t_s']:.2f}")]
    rows.append(("max speed (planet-relative)", f"{s['speed_m_s']:.1f} ± {s['sigma_m_s']:.1f} m/s", f"{s['t_s']:.2f}"))
    b = block.get("burnout")
    if b is not None:
        rows.append(
            (
                f"speed after burnout ({b['t_s']:.2f} s)",
                f"{b['speed_m_s']:.1f} ± {b['sigma_m_s']:.1f} m/s",
                f"{b['at_t_s']:.2f}",
            )
        )
    where = "landing point" if la["touchdown"] else "last position (data end in flight)"
    rows.append((where, format_lat_lon(la["lat_deg"], la["lon_deg"]), f"{la['t_s']:.2f}"))
    rows.append(
        (
            "… from the pad",
            f"{la['drift_from_pad_m']:.0f} m towards {la['bearing_from_pad_deg']:.0f}° "
            f"(E {la['east_m']:.0f}, N {la['north_m']:.0f} m)",
            "",
        )
    )
    rows.append(
        (
            "… 1σ / 3σ ellipse",
            f"{e1['semi_major_m']:.0f} × {e1['semi_minor_m']:.0f} m / {e3['semi_major_m']:.0f} × "
            f"{e3['semi_minor_m']:.0f} m, major axis {e1['orientation_deg']:.0f}° from north",
            "",
        )
    )
    for chute, d in block.get("descent", {}).items():
        rows.append(
            (
                f"descent rate under the {chute}",
                f"{d['rate_m_s']:.1f} ± {d['sigma_m_s']:.1f} m/s (spread {d['spread_m_s']:.1f})",
                f"{d['window_s'][0]:.1f}–{d['window_s'][1]:.1f}",
            )
        )
    md = "## Rocket results (from the reconstruction; pad frame)\n\n| result | value ± 1σ | t [s] |\n|---|---|---|\n"
    md += "".join(f"| {n} | {v} | {tt} |\n" for n, v, tt in rows)
    for key in ("note", "ellipse_note"):
        if key in la:
            md += f"\n{la[key]}\n"
    return md + "\n"
