"""Where the first run of a fresh checkout spends its compile time: per scenario, the numba kernels
compiled with an empty cache, each with its exclusive and inclusive compile time.

For each scenario a child interpreter runs ``workbench.problems.precompile`` (the scenario's truth
and reconstruction until every compiled module is cached) with ``NUMBA_CACHE_DIR`` set to a fresh
temporary folder, and listens to numba's ``numba:compile`` events: the exclusive time of a kernel
is its own typing, lowering and LLVM optimisation, without the kernels it calls. The child's CPU
time (user + system) is the compile plus what the scenario computes up to the last cold kernel.
The child also splits the compile CPU (``time.process_time``) between LLVM (every llvmlite C call,
grouped into optimisation passes, machine-code generation and IR parsing) and numba's own passes
(``numba:run_pass`` events; ``native_lowering`` contains the LLVM work it triggers).
Run on an otherwise idle machine: the kernel times are wall clock of one process.

    python tests/benchmarks/bench_compile.py [--scenarios msl_meads,droptest,schiaparelli,post2_huygens] [--top 12]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

#: the child: numba's compile events around ``precompile.main``, a JSON line on stdout
_CHILD = r"""
import collections, json, resource, sys, time
from llvmlite.binding import ffi
from numba.core import event
stack, excl, incl, count = [], collections.Counter(), collections.Counter(), collections.Counter()
llvm, passes, pstack = collections.Counter(), collections.Counter(), []
_call = ffi._lib_fn_wrapper.__call__
def _timed(self, *a, **k):
    t = time.process_time()
    try:
        return _call(self, *a, **k)
    finally:
        llvm[getattr(self._cfn, "__name__", "?")] += time.process_time() - t
ffi._lib_fn_wrapper.__call__ = _timed
class Passes(event.Listener):
    def on_start(self, ev):
        pstack.append([time.process_time(), 0.0])
    def on_end(self, ev):
        t0, child = pstack.pop()
        dt = time.process_time() - t0
        passes[ev.data["name"].split(" [")[0]] += dt - child
        if pstack:
            pstack[-1][1] += dt
event.register("numba:run_pass", Passes())
class Listener(event.Listener):
    def on_start(self, ev):
        stack.append([time.perf_counter(), 0.0])
    def on_end(self, ev):
        d = ev.data.get("dispatcher")
        t0, child = stack.pop()
        dt = time.perf_counter() - t0
        name = f"{d.py_func.__module__}.{d.py_func.__qualname__}"
        excl[name] += dt - child
        incl[name] += dt
        count[name] += 1
        if stack:
            stack[-1][1] += dt
event.register("numba:compile", Listener())
from workbench.problems import precompile
code = precompile.main([sys.argv[1]])
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"code": code, "cpu_s": ru.ru_utime + ru.ru_stime,
                  "kernels": {k: [excl[k], incl[k], count[k]] for k in excl},
                  "llvm": dict(llvm), "passes": dict(passes)}))
"""


def profile(scenario: str, top: int) -> dict:
    """One scenario's cold compile: the child's CPU [s], the summed exclusive compile time [s], the
    workbench kernels' and numba's own implementations' shares, and the ``top`` kernels."""
    with tempfile.TemporaryDirectory(prefix="wb-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, WORKBENCH_PRECOMPILE="0")
        t0 = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", _CHILD, scenario], env=env, capture_output=True, text=True, check=True
        )
        wall = time.perf_counter() - t0
    doc = json.loads(out.stdout.strip().splitlines()[-1])
    kernels = doc["kernels"]
    ranked = sorted(kernels.items(), key=lambda kv: -kv[1][0])
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(doc["cpu_s"], 2),
        "compile_excl_sum_s": round(sum(v[0] for v in kernels.values()), 2),
        "numba_internal_excl_s": round(sum(v[0] for k, v in kernels.items() if k.startswith("numba.")), 2),
        "kernels_compiled": len(kernels),
        **_split(doc["llvm"], doc["passes"]),
        "top": [
            {"kernel": k, "excl_s": round(v[0], 2), "incl_s": round(v[1], 2), "signatures": v[2]}
            for k, v in ranked[:top]
        ],
    }


#: LLVM C API calls by what they do (llvmlite's ``LLVMPY_*`` names)
_LLVM_GROUPS = {
    "optimise_s": ("LLVMPY_RunNewModulePassManager", "LLVMPY_RunNewFunctionPassManager"),
    "codegen_s": ("LLVMPY_FinalizeObject",),
    "parse_ir_s": ("LLVMPY_ParseAssembly",),
}


def _split(llvm: dict[str, float], passes: dict[str, float]) -> dict:
    """Where the compile CPU goes: inside LLVM (optimisation passes, machine-code generation, parsing
    numba's IR text, the rest) and in numba's own (Python) passes, each exclusive [s]; numba's
    ``native_lowering`` includes the LLVM work it triggers, so its Python share is the difference."""
    groups = {g: round(sum(llvm.get(n, 0.0) for n in names), 2) for g, names in _LLVM_GROUPS.items()}
    llvm_total = sum(llvm.values())
    groups["other_s"] = round(llvm_total - sum(groups.values()), 2)
    ranked = sorted(passes.items(), key=lambda kv: -kv[1])
    lowering = passes.get("native_lowering", 0.0)
    return {
        "llvm_s": round(llvm_total, 2),
        "llvm": groups,
        "numba_passes_s": round(sum(passes.values()), 2),
        "lowering_python_s": round(max(lowering - llvm_total, 0.0), 2),
        "passes_top": {k: round(v, 2) for k, v in ranked[:6]},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="msl_meads,droptest,schiaparelli,post2_huygens")
    ap.add_argument("--top", type=int, default=12, help="kernels listed per scenario")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_compile.json"))
    a = ap.parse_args(argv)
    per = {}
    for name in a.scenarios.split(","):
        per[name] = profile(name, a.top)
        p = per[name]
        print(
            f"{name}: CPU {p['cpu_s']:.1f} s, compile {p['compile_excl_sum_s']:.1f} s "
            f"({p['numba_internal_excl_s']:.1f} s numba's own), {p['kernels_compiled']} kernels",
            flush=True,
        )
        print(
            f"  LLVM {p['llvm_s']:.1f} s ({', '.join(f'{k[:-2]} {v:.1f}' for k, v in p['llvm'].items())}); "
            f"numba passes {p['numba_passes_s']:.1f} s, of which lowering's Python {p['lowering_python_s']:.1f} s"
        )
        for row in p["top"]:
            print(f"  {row['excl_s']:6.2f} excl {row['incl_s']:6.2f} incl  {row['kernel']}")
    results = {
        "scenarios": per,
        "cpu_s_total": round(sum(p["cpu_s"] for p in per.values()), 1),
        "compile_s_total": round(sum(p["compile_excl_sum_s"] for p in per.values()), 1),
        "llvm_s_total": round(sum(p["llvm_s"] for p in per.values()), 1),
    }
    out = write_benchmark_json(a.out, __file__, results, argv)
    print(f"CPU {results['cpu_s_total']} s, compile {results['compile_s_total']} s -> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
