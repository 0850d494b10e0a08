"""What in a drop test with ranging can see a wrong declared lander height (issue 26, the fuzz suite's
last SILENT row: ``height_m`` × 1.2 in the lander asset of ``droptest_ranging``).

Five measurements, each an idea for a check that would catch the mistake:

1. **what moves**: the body points the declared ``height_m`` sets, against the points a sensor sees —
   the instruments' lever arms, the ranging reflector and the odometer's rope attachment (all written
   in the lander frame), the base bag's lobes (the first contact) and the side bags' lobes;
2. **the run itself**: ``droptest_ranging`` (its own seed) reconstructed with the shipped and with
   the taller lander: max stroke, the first-contact clearance, the IMU's sharpest jerk, the interval
   over which the declared lobes press into the ramp, the calibrated verdict;
3. **where the bag force acts**: the centre of pressure of the truth's own contact force and torque
   (m·a_ng, I·α + ω×Iω, exact, no estimation noise) against the convex hull of the footprint centres
   of the declared lobes that press into the ramp — with either declared geometry, how far outside;
4. **the bags' load**: the declared bags' quasi-static load (the gas law on the declared pressure,
   volume and γ over the footprints of the declared lobes at the smoothed pose) against the measured
   m·|f̄| over the impact, with either declared geometry;
5. **honest near misses**: the truth max stroke of dispersed drops of the REDLand envelope (the drop
   Monte Carlo's ``disperse_drop``, validation stream) and the reconstruction of those that came
   within 10 cm without the frame touching — the signature of the taller lander's run on honest data.

    python tests/benchmarks/bench_height_observability.py [--members 80] [--factor 1.2] [--out FILE]
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

from workbench.core.rotation import quat_rotate, quat_to_dcm  # noqa: E402
from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import resolve_scenario  # noqa: E402
from workbench.problems.calibration import VALIDATION_STREAM, seeds_of  # noqa: E402
from workbench.problems.droptest import model as rl  # noqa: E402
from workbench.problems.droptest.lander import load_lander  # noqa: E402
from workbench.problems.droptest.physics import lobe_clearance, measured_impact  # noqa: E402
from workbench.problems.droptest.pipeline import run_droptest, score, truth_stroke  # noqa: E402
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402
from workbench.problems.droptest.synthetic import dispersed_truth, load_truth, synthesize_droptest  # noqa: E402
from workbench.problems.runner import judge_health  # noqa: E402

SCENARIO = "droptest_ranging"


def taller_lander(lander_file: Path, factor: float, folder: Path) -> Path:
    """A copy of the lander asset in ``folder`` with ``height_m`` × ``factor`` (the fuzz mutation)."""
    text = lander_file.read_text(encoding="utf-8")
    m = re.search(r"^height_m\s*=\s*([0-9.eE+-]+)", text, flags=re.M)
    if m is None:
        raise SystemExit(f"{lander_file}: no height_m (the MER layout) to scale")
    new = text[: m.start(1)] + repr(float(m.group(1)) * factor) + text[m.end(1) :]
    out = folder / lander_file.name
    out.write_text(new, encoding="utf-8")
    return out


def what_moves(nominal, taller, settings, setup: dict) -> dict:
    """Largest shift [m] in the body frame of each group of body points between the two landers."""
    refl = [nominal.to_body(r) - taller.to_body(r) for r in settings.ranging.reflectors_body_m.values()]
    attach = setup.get("bungee", {}).get("attach_body_m")
    dv = np.linalg.norm(np.asarray(nominal.body.vertices) - np.asarray(taller.body.vertices), axis=1)
    dl = np.linalg.norm(nominal.lobe_centers_B - taller.lobe_centers_B, axis=1)
    return {
        "apex_vertex": float(dv[3]),
        "base_vertices": float(dv[:3].max()),
        "base_bag_lobes": float(dl[nominal.lobe_bag == 0].max()),
        "side_bag_lobes": [float(dl[nominal.lobe_bag > 0].min()), float(dl[nominal.lobe_bag > 0].max())],
        "instruments": float(
            max(np.linalg.norm(nominal.instruments[k] - taller.instruments[k]) for k in nominal.instruments)
        ),
        "ranging_reflectors": float(max((np.linalg.norm(r) for r in refl), default=0.0)),
        "odometer_attachment": None
        if attach is None
        else float(np.linalg.norm(nominal.to_body(attach) - taller.to_body(attach))),
    }


def run_facts(res, summary: dict) -> dict:
    """The run's max stroke, first-contact clearance, sharpest jerk, pressed interval and verdict."""
    smo, st, tel = res.smoothed, res.stroke, res.telemetry
    checks = {c["name"]: c for c in summary["health"]["checks"]}
    clear = lobe_clearance(smo.x[:, rl.SP], smo.x[:, rl.SQ], st.lander, st.surface)
    imp = measured_impact(tel)
    pressed = np.flatnonzero((clear < 0.0) & (smo.t >= tel.events["release"]))
    return {
        "max_stroke_m": float(st.max.distance),
        "max_stroke_sigma_m": float(st.max.sigma),
        "max_stroke_vertex": int(st.max.vertex),
        "first_contact_clearance_m": checks.get("geometry.first_contact", {}).get("value"),
        "first_contact_status": checks.get("geometry.first_contact", {}).get("status"),
        "full_stroke_jerk_g_s": checks.get("geometry.full_stroke", {}).get("value"),
        "full_stroke_status": checks.get("geometry.full_stroke", {}).get("status"),
        "lobes_pressed_s": [float(smo.t[pressed[0]]), float(smo.t[pressed[-1]])] if pressed.size else None,
        "impact_over_2g_s": None if imp is None else [imp[0], imp[1]],
        "verdict": summary["health"]["verdict"],
        "not_ok": sorted(f"{n}:{c['status']}" for n, c in checks.items() if c["status"] != "OK"),
    }


def bag_load_ratio(res, lander) -> dict:
    """The declared bags' quasi-static load against the measured one over the impact: the gas law on
    the declared pressure, volume and γ (p0 (V0 / (V0 − V_caps))^γ − p_amb) over the spherical-cap
    footprints of the declared lobes at the smoothed pose (no overlap correction), against m·|f̄| of
    the mean triad (samples above 30 % of the peak): the median and 10–90th percentiles of their ratio."""
    from workbench.problems.droptest.physics import mean_triad_force

    smo, st, tel = res.smoothed, res.stroke, res.telemetry
    c_B = np.asarray(lander.lobe_centers_B, float)
    R = float(lander.lobe_radius)
    n, m = smo.t.size, c_B.shape[0]
    cI = np.repeat(smo.x[:, rl.SP], m, 0) + quat_rotate(np.repeat(smo.x[:, rl.SQ], m, 0), np.tile(c_B, (n, 1)))
    pe = np.clip(R - st.surface.distance(cI)[0].reshape(n, m), 0.0, R)
    caps = np.sum(np.pi * pe**2 * (3.0 * R - pe) / 3.0, axis=1)
    gauge = lander.pressure_pa * (lander.gas_volume_m3 / (lander.gas_volume_m3 - caps)) ** lander.gamma
    model = (gauge - lander.ambient_pressure_pa) * np.sum(np.pi * (2.0 * R * pe - pe**2), axis=1)
    t, f = mean_triad_force(tel)
    measured = np.interp(smo.t, t - tel.group_delay_s, lander.mass * np.linalg.norm(f, axis=1))
    imp = measured_impact(tel)
    inside = (smo.t >= imp[0]) & (smo.t <= imp[1])
    use = inside & (measured > 0.3 * measured[inside].max())
    r = model[use] / measured[use]
    return {"median": float(np.median(r)), "p10_p90": [float(x) for x in np.percentile(r, [10, 90])]}


def cop_outside_hull(truth: dict, lander, surface, step: int = 5) -> float:
    """Largest distance [m] of the truth's centre of pressure on the ramp from the convex hull of the
    footprint centres of ``lander``'s lobes that press into the ramp, over the samples with a contact
    force above 2 g.  The centre of pressure: the point c of the plane about which the contact wrench
    (F = m a_ng, torque I α + ω × I ω about the CM) has no in-plane moment, c − p₀ = n × (T + h n × F) / F·n
    (p₀ the CM's foot on the plane, h its height)."""
    n = surface.normal
    q, p, w, al = truth["q_I_B"], truth["p_I"], truth["w_B"], truth["alpha_B"]
    F = lander.mass * truth["a_ng_I"]
    TB = al @ lander.inertia_B.T + np.cross(w, w @ lander.inertia_B.T)
    TI = np.einsum("nij,nj->ni", quat_to_dcm(q), TB)
    h = (p - surface.point) @ n
    Fn = F @ n
    sel = np.flatnonzero(Fn > 2.0 * 9.80665 * lander.mass)[::step]
    t1, t2 = surface.tangent_basis()
    worst = 0.0
    for k in sel:
        cop = p[k] - h[k] * n + np.cross(n, TI[k] + h[k] * np.cross(n, F[k])) / Fn[k]
        cI = p[k] + quat_rotate(np.repeat(q[k : k + 1], len(lander.lobe_centers_B), 0), lander.lobe_centers_B)
        dc = (cI - surface.point) @ n
        on = dc < lander.lobe_radius
        if not on.any():
            continue
        foot = cI[on] - dc[on, None] * n - surface.point
        P2 = np.stack([foot @ t1, foot @ t2])
        c2 = np.array([(cop - surface.point) @ t1, (cop - surface.point) @ t2])
        # distance to the hull: the closest convex combination (sum of weights enforced by a heavy row)
        lam, _ = nnls(np.vstack([P2, 1e3 * np.ones(P2.shape[1])]), np.r_[c2, 1e3])
        worst = max(worst, float(np.linalg.norm(P2 @ lam - c2)))
    return worst


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=80, help="dispersed drops of the near-miss search")
    ap.add_argument("--factor", type=float, default=1.2, help="the declared height_m's factor")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_height_observability.json"))
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    problem = DropTestProblem()
    settings = problem.settings(resolve_scenario(SCENARIO, assets_dir()))
    with tempfile.TemporaryDirectory(prefix="wb-height-") as tmp:
        work = Path(tmp)
        tall_file = taller_lander(settings.lander_file, a.factor, work)
        tall = replace(settings, lander=load_lander(tall_file), lander_file=tall_file)
        syn = synthesize_droptest(settings, work / "run")
        truth = load_truth(syn.truth_path)
        runs = {}
        for label, s in (("shipped", settings), ("taller", tall)):
            res = run_droptest(s, syn.telemetry, seed=settings.synthetic.seed)
            summary = dict(res.summary, truth=score(res, truth))
            judge_health(problem, summary)
            runs[label] = run_facts(res, summary)
            runs[label]["bag_load_over_measured"] = bag_load_ratio(res, s.lander)
        moves = what_moves(settings.lander, tall.lander, settings, res.telemetry.setup)
        surface = res.stroke.surface
        cop = {
            "shipped": cop_outside_hull(truth, settings.lander, surface),
            "taller": cop_outside_hull(truth, tall.lander, surface),
        }
        near, strokes = [], []
        for seed in seeds_of(VALIDATION_STREAM, a.members):
            tr, lander, surf = dispersed_truth(settings, seed)
            d = {k: getattr(tr, k) for k in ("t", "p_I", "q_I_B")}
            dmin = truth_stroke(d, lander, surf)[1]
            strokes.append(dmin)
            if 0.0 < dmin < 0.1 and float(np.max(tr.body_penetration)) == 0.0:
                syn_k = synthesize_droptest(settings, work / f"m{seed}", seed=seed, disperse=True, compress_truth=False)
                res_k = run_droptest(settings, syn_k.telemetry, seed=seed)
                sum_k = dict(res_k.summary, truth=score(res_k, load_truth(syn_k.truth_path)))
                judge_health(problem, sum_k)
                near.append({"seed": seed, "truth_stroke_m": dmin, **run_facts(res_k, sum_k)})
    s = np.array(strokes)
    results = {
        "scenario": SCENARIO,
        "factor": a.factor,
        "wall_s": round(time.perf_counter() - t0, 1),
        "what_moves_m": moves,
        "runs": runs,
        "cop_outside_hull_m": cop,
        "dispersed": {
            "members": int(s.size),
            "full_stroke": int(np.sum(s <= 0.0)),
            "within_0_10cm": int(np.sum((s > 0.0) & (s < 0.1))),
            "stroke_range_m": [float(s.min()), float(s.max())],
        },
        "near_misses": near,
    }
    out = write_benchmark_json(a.out, __file__, results, argv)
    sh, ta = runs["shipped"], runs["taller"]
    print(f"what moves with height_m x{a.factor:g} [m]: {moves}")
    for label, r in runs.items():
        print(f"{label}: {r}")
    print(f"centre of pressure outside the declared footprint hull (truth wrench) [m]: {cop}")
    print(f"dispersed drops: {results['dispersed']}")
    for r in near:
        print(f"honest near miss: {r}")
    print(
        f"max stroke {sh['max_stroke_m']:.4f} -> {ta['max_stroke_m']:.4f} m, "
        f"verdict {sh['verdict']} -> {ta['verdict']} ({results['wall_s']:.0f} s) -> {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
