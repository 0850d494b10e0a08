"""Scoring of a post2 result against the synthetic truth (truth reaches only this module and the drawing).

Numbers (thesis [R3] Ch. 3.2): for every estimated scalar parameter the error after the 1st, 4th and
10th observation of the first observation channel (forward pass, as the thesis' Fig. 3-1), the final
error and its ratio to the final 3σ; for the trajectory the position error at the start, after 15 s
of observations and at the end (forward and smoothed; Fig. 3-4), velocity, aerodynamic-angle and
body-rate errors at the end, and the fraction of grid steps where each position component is inside
its 3σ.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.rotation import attitude_error
from workbench.problems.post2.model import STATES

#: the trajectory blocks of the NEES (:func:`trajectory_nees`), in the error-state order of the state map
TRAJECTORY = ("position", "velocity", "attitude", "body_rates")

__all__ = ["truth_on_grid", "score", "headline", "TRAJECTORY", "trajectory_nees"]


def truth_on_grid(truth: dict, t: np.ndarray) -> dict:
    """Truth blocks at the grid times t (n,) [s]: linear interpolation for p, v, body rates; nearest
    sample for the aerodynamic angles [rad]."""
    tt = truth["t"]
    out = {}
    for name in ("position", "velocity", "body_rates", "attitude"):
        if name not in truth:
            continue
        a = truth[name]
        if name == "attitude":
            k = np.clip(np.searchsorted(tt, t), 0, tt.size - 1)
            out[name] = a[k]
        else:
            out[name] = np.column_stack([np.interp(t, tt, a[:, i]) for i in range(a.shape[1])])
    return out


def _scale(name: str) -> float:
    return 180.0 / math.pi if STATES[name].unit in ("deg", "deg/s") else 1.0


def score(result, truth: dict) -> dict:
    """Errors of a :class:`~workbench.problems.post2.pipeline.Post2Result` against ``truth`` (the
    arrays of ``truth.npz``); JSON-ready, in the problem file's units (deg, deg/s, m, m/s)."""
    t = result.t
    tg = truth_on_grid(truth, t)
    fwd, smo = result.history["forward"], result.history["smoothed"]
    out: dict = {}
    if "position" in tg:
        ef = np.linalg.norm(fwd["position"]["value"] - tg["position"], axis=1)
        es = np.linalg.norm(smo["position"]["value"] - tg["position"], axis=1)
        x0 = result.summary["states"]["position"]["initial"]
        e0 = float(np.linalg.norm(np.asarray(x0) - tg["position"][0]))
        k15 = int(np.searchsorted(t, t[0] + 15.0 - 1e-9))
        out["position_error_m"] = {
            "start": e0,
            "after_15s_forward": float(ef[min(k15, t.size - 1)]),
            "end_forward": float(ef[-1]),
            "end_smoothed": float(es[-1]),
            "max_smoothed": float(es.max()),
        }
        z = np.abs(smo["position"]["value"] - tg["position"]) / np.maximum(smo["position"]["sigma"], 1e-300)
        out["position_inside_3sigma_fraction"] = float(np.mean(z <= 3.0))
        out["position_error_history_forward_m"] = {
            "t_s": t[:: max(1, t.size // 200)].tolist(),
            "err": ef[:: max(1, t.size // 200)].tolist(),
        }
    for name in ("velocity", "attitude", "body_rates"):
        if name in tg and name in fwd:
            k = _scale(name)
            ef = (fwd[name]["value"] - tg[name]) * k
            es = (smo[name]["value"] - tg[name]) * k
            if name == "attitude":
                ef = (ef + 180.0) % 360.0 - 180.0
                es = (es + 180.0) % 360.0 - 180.0
            k15 = int(np.searchsorted(t, t[0] + 15.0 - 1e-9))
            out[f"{name}_error"] = {
                "unit": "deg" if name == "attitude" else STATES[name].unit,
                "start_forward": ef[0].tolist(),
                "after_15s_forward": ef[min(k15, t.size - 1)].tolist(),
                "end_forward": ef[-1].tolist(),
                "end_smoothed": es[-1].tolist(),
                "end_sigma_smoothed": (smo[name]["sigma"][-1] * k).tolist(),
            }
    if "propagated" in result.history:  # filtered vs propagation-only (thesis Ch. 3.2.3), at the end
        prop = result.history["propagated"]
        cmp = {}
        for name in ("position", "velocity", "attitude", "body_rates"):
            if name not in tg or name not in prop:
                continue
            k = _scale(name)
            ends = {}
            for label, h in (("propagation_only", prop), ("forward", fwd), ("smoothed", smo)):
                e = (h[name]["value"][-1] - tg[name][-1]) * k
                if name == "attitude":
                    e = (e + 180.0) % 360.0 - 180.0
                ends[label] = float(np.linalg.norm(e))
            cmp[name] = {"unit": "deg" if name == "attitude" else STATES[name].unit, "end_error_norm": ends}
        out["filtered_vs_propagation"] = cmp
    params = {}
    first = next(iter(result.forward.innovations.values()), None)
    for name in result.smap.blocks:
        key = f"param_{name}"
        if STATES[name].dynamic or key not in truth:
            continue
        tv = np.atleast_1d(truth[key]).astype(float)
        vf, sf = fwd[name]["value"], fwd[name]["sigma"]
        vs, ss = smo[name]["value"], smo[name]["sigma"]
        # the summary's initial value is in the problem file's unit (deg for angles), the truth in SI
        x0 = np.asarray(result.summary["states"][name]["initial"], float) / _scale(name)
        rec = {"truth": tv.tolist(), "initial_error": (x0 - tv).tolist()}
        if first is not None:
            steps = np.unique(first.step)
            for n in (1, 4, 10):
                if steps.size >= n:
                    rec[f"error_after_{n}_obs"] = (vf[steps[n - 1]] - tv).tolist()
                    rec[f"sigma_after_{n}_obs"] = sf[steps[n - 1]].tolist()
        rec["final_error_forward"] = (vf[-1] - tv).tolist()
        rec["final_3sigma_forward"] = (3.0 * sf[-1]).tolist()
        rec["final_error_over_3sigma_forward"] = ((vf[-1] - tv) / (3.0 * sf[-1])).tolist()
        rec["final_error_smoothed"] = (vs[-1] - tv).tolist()
        rec["final_error_over_3sigma_smoothed"] = ((vs[-1] - tv) / (3.0 * ss[-1])).tolist()
        rec["inside_3sigma_at_end"] = bool(np.all(np.abs(vf[-1] - tv) <= 3.0 * sf[-1]))
        st = result.summary["states"][name]
        if "informed_by_data" in st:  # posterior σ / prior σ (pipeline.INFORMED_RATIO)
            rec["posterior_over_prior_sigma"] = st["posterior_over_prior_sigma"]
            rec["informed_by_data"] = st["informed_by_data"]
        params[name] = rec
    out["parameters"] = params
    out["headline"] = headline(result, truth)
    return out


def headline(result, truth: dict) -> list[dict]:
    """The run's headline numbers against the truth, each ``{"name", "what", "error", "sigma",
    "unit"}`` (estimate − truth and the run's own 1σ, SI, final smoothed values): the end position
    (3 components, planet-centred inertial, m) and every estimated parameter with a planted truth
    (all its components; tilt in rad).  The runner judges each against ±3σ."""
    smo = result.history["smoothed"]
    out = []
    if "position" in truth and "position" in smo:
        tg = truth_on_grid(truth, result.t[-1:])
        out.append(
            {
                "name": "end_position",
                "what": "end position (smoothed, planet-centred inertial x/y/z)",
                "error": (smo["position"]["value"][-1] - tg["position"][-1]).tolist(),
                "sigma": smo["position"]["sigma"][-1].tolist(),
                "unit": "m",
            }
        )
    for name in result.smap.blocks:
        key = f"param_{name}"
        if STATES[name].dynamic or key not in truth:
            continue
        tv = np.atleast_1d(truth[key]).astype(float)
        v, sd = smo[name]["value"][-1], smo[name]["sigma"][-1]
        unit = {"deg": "rad", "deg/s": "rad/s"}.get(STATES[name].unit, STATES[name].unit)
        out.append(
            {
                "name": f"param.{name}",
                "what": f"estimated parameter {name} (smoothed, end)",
                "error": (v - tv).tolist(),
                "sigma": sd.tolist(),
                "unit": unit,
            }
        )
    return out


def trajectory_nees(result, truth: dict, names=TRAJECTORY) -> dict:
    """NEES of the trajectory blocks ``names`` present in the state over the grid: error
    e = estimate ⊟ truth (position [m], velocity [m/s], body small angle of the attitude [rad], body
    rates [rad/s]; the truth interpolated to the grid, its quaternion at the nearest truth sample) and
    ``e P⁻¹ e`` with the matching block of the error covariance.  Returns ``{"t": (n,) [s],
    "dim": int, "forward": (n,), "smoothed": (n,)}`` (χ²(dim) when the filter is consistent)."""
    sm = result.smap
    names = [n for n in names if n in sm.blocks]
    idx = np.concatenate([np.arange(sm.blocks[n].se.start, sm.blocks[n].se.stop) for n in names])
    t = result.t
    tg = truth_on_grid(truth, t)
    if "attitude" in names:
        k = np.clip(np.searchsorted(truth["t"], t - 1e-9), 0, truth["t"].size - 1)
        q_true = truth["quaternion"][k]
    out = {"t": t, "dim": int(idx.size)}
    passes = {"forward": (result.forward.x_post, result.forward.P_post), "smoothed": (result.x, result.P)}
    for label, (x, P) in passes.items():
        parts = []
        for n in names:
            if n == "attitude":
                parts.append(attitude_error(q_true, sm.raw(x, "attitude")))
            else:
                parts.append(sm.raw(x, n) - tg[n])
        e = np.concatenate(parts, axis=1)
        Ps = P[:, idx[:, None], idx[None, :]]
        out[label] = np.einsum("ni,ni->n", e, np.linalg.solve(Ps, e[..., None])[..., 0])
    return out
