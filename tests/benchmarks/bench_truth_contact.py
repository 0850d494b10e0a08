"""The drop-test truth simulator's bag contact, drop by drop: does a pressed bag always push?

Runs the truth (no sensors, no reconstruction) of the four shipped drop-test scenarios' own drops and of
``--members`` dispersed drops of ``droptest`` (the drop Monte Carlo's ``disperse_drop``, validation stream),
and reports per drop:

* **zero-force spells**: the time [s] during which some lobe is pressed more than 10 cm into the ramp and the
  bags' gauge pressure exceeds the fabric damping's pull (damping × the CM's speed away from the ramp) while
  the total bag force is zero (such a bag pushes with its net pressure over its footprint, so this is a
  defect of the footprint-area model, never physics; a vented bag below ambient is limp until compressed,
  and a bag barely above it goes slack while it rebounds, as the damper cannot pull);
* the deepest lobe penetration [m], the peak bag force [N];
* the truth max stroke [m] (the body's closest approach to the ramp, negative: the frame struck it), the
  body vertex it rests on, and the time [s] the frame is on the ramp;
* **compressions before the closest approach**: samples where the lander moves away from the ramp
  (v_n > 0.05 m/s) under more than 3 g while the body is 5 cm above its closest approach so far — a
  bounce off one face before the deepest compression on another.

Used once per model change, on the commit before (``--out docs/results/before/...``) and after.

    python tests/benchmarks/bench_truth_contact.py [--members 20] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import resolve_scenario  # noqa: E402
from workbench.problems.calibration import VALIDATION_STREAM, seeds_of  # noqa: E402
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402
from workbench.problems.droptest.stroke import stroke_history  # noqa: E402
from workbench.problems.droptest.synthetic import dispersed_truth, truth_for  # noqa: E402

SCENARIOS = ("droptest", "droptest_ranging", "droptest_fullstroke", "droptest_rocks")
G0 = 9.80665


def drop_row(tr, lander, surface) -> dict:
    """The measures of one truth drop ``tr`` (a ``DropTruth``) of ``lander`` on ``surface``."""
    dt = float(np.median(np.diff(tr.t)))
    n = np.asarray(surface.normal, float)
    vn = tr.v_I @ n
    net = tr.gauge_pressure - float(lander.damping or 0.0) * np.maximum(vn, 0.0)  # [Pa]
    pressed = (tr.lobe_penetration.max(axis=1) > 0.1) & (net > 0.0)
    h = stroke_history(
        np.asarray(lander.body.vertices, float),
        tr.p_I,
        tr.q_I_B,
        np.zeros((tr.t.size, 6, 6)),
        surface,
        faces_B=np.asarray(lander.body.faces),
    )
    d = h.distance
    after = tr.t >= 0.0
    k_min = int(np.flatnonzero(after)[np.argmin(d[after])])
    load = np.linalg.norm(tr.a_ng_I, axis=1)
    i0 = int(np.argmax(tr.contact_force > 0.0))
    run_min = np.minimum.accumulate(d[i0 : k_min + 1]) if k_min > i0 else np.array([])
    bounce = [
        i0 + j
        for j in range(1, run_min.size)
        if vn[i0 + j] > 0.05 and load[i0 + j] > 3.0 * G0 and d[i0 + j] > run_min[j] + 0.05
    ]
    return {
        "zero_force_spell_s": float(np.sum(pressed & (tr.contact_force <= 0.0)) * dt),
        "max_lobe_penetration_m": float(tr.lobe_penetration.max()),
        "peak_bag_force_n": float(tr.contact_force.max()),
        "max_stroke_m": float(d[k_min]),
        "max_stroke_time_s": float(tr.t[k_min]),
        "max_stroke_vertex": int(h.vertex[k_min]),
        "frame_on_ramp_s": float(np.sum(tr.body_penetration > 0.0) * dt),
        "bounce_samples_before_max_stroke": len(bounce),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=20, help="dispersed drops of droptest (validation stream)")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_truth_contact.json"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows: dict[str, dict] = {}
    for name in SCENARIOS:
        st = DropTestProblem().settings(resolve_scenario(name, assets_dir()))
        tr, lander, surf = truth_for(st)
        rows[name] = drop_row(tr, lander, surf)
        print(f"[bench] {name}: {rows[name]}", flush=True)
    base = DropTestProblem().settings(resolve_scenario("droptest", assets_dir()))
    dispersed = []
    for seed in seeds_of(VALIDATION_STREAM, args.members):
        tr, lander, surf = dispersed_truth(base, seed)
        dispersed.append({"seed": int(seed), **drop_row(tr, lander, surf)})
    spells = np.array([r["zero_force_spell_s"] for r in dispersed])
    scen_spells = np.array([r["zero_force_spell_s"] for r in rows.values()])
    results = {
        "scenarios": rows,
        "dispersed": dispersed,
        "summary": {
            "members": len(dispersed),
            "scenario_drops_with_zero_force_spell": int(np.sum(scen_spells > 0)),
            "dispersed_with_zero_force_spell": int(np.sum(spells > 0)),
            "dispersed_zero_force_spell_s_max": float(spells.max()),
            "dispersed_zero_force_spell_s_nonzero_min": float(spells[spells > 0].min()) if np.any(spells > 0) else 0.0,
            "dispersed_with_bounce_before_max_stroke": int(
                sum(r["bounce_samples_before_max_stroke"] > 0 for r in dispersed)
            ),
            "dispersed_apex_closest": int(sum(r["max_stroke_vertex"] == 3 for r in dispersed)),
            "dispersed_frame_on_ramp": int(sum(r["frame_on_ramp_s"] > 0 for r in dispersed)),
            "dispersed_max_stroke_m_median": float(np.median([r["max_stroke_m"] for r in dispersed])),
            "dispersed_max_lobe_penetration_m_median": float(
                np.median([r["max_lobe_penetration_m"] for r in dispersed])
            ),
        },
        "wall_s": time.perf_counter() - t0,
    }
    print(f"[bench] {results['summary']}")
    print(f"wrote {write_benchmark_json(args.out, __file__, results, argv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
