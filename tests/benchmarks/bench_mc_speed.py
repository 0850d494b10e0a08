"""Monte Carlo speed benchmark of issue #30: each problem's truth Monte Carlo against a named baseline
commit in the same run, and the entry dispersion at 10⁶ members on every executor.

Run on demand from the repository root, on an otherwise idle machine (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_mc_speed.py [--parts mc,scale] [--seeds 50]
        [--baseline b028478] [--baseline-seeds 10] [--problems droptest,schiaparelli,...]
        [--dispersion-members 1000000] [--cluster-mc schiaparelli --cluster-mc-seeds 200]
        [--json docs/results/bench_mc_speed.json]
    .venv/bin/python tests/benchmarks/bench_mc_speed.py --table     # print the table of the JSON

Part ``mc``, per problem: ``workbench mc <scenario> --truth-sim --seeds N --workers 2`` as a child
process of this checkout, and the same command on the ``--baseline`` commit (extracted with ``git
archive`` into a scratch folder) with ``--baseline-seeds`` members — the same members, the first ones
of the same stream.  Each is warmed first (one member, not timed: numba's cache and Python's bytecode
are per checkout).  Measured: wall [s] of the whole command, CPU [s] of the command and its worker
processes (``RUSAGE_CHILDREN``), peak resident memory of the process tree (psutil, sampled every
0.1 s).  Identity: both checkouts run ``--seeds 4 --workers 1`` and their ``<name>_truth.mc.json``
are compared number by number (``compare_summaries.differences``, timings skipped): the max relative
difference is reported, the differing keys listed.

Part ``scale``: the entry dispersion (``schiaparelli`` scenario's preprocessed telemetry, one pass,
no refinement, chunks of ``--chunk-size``) with ``--dispersion-members`` members in-process, on a Dask
``LocalCluster`` with 1 and with 2 worker processes, and on a ``tcp://`` scheduler started here
(``dask scheduler`` + 2 ``dask worker`` processes, one thread each); per executor its wall [s] and
the peak resident memory of this process and of the whole process tree; the accepted flags and event
quantities must be bit-identical across executors.  Then ``--cluster-mc-seeds`` truth Monte Carlo
members of ``--cluster-mc`` on the same ``tcp://`` cluster, and the same members' JSON against an
in-process pool run of the first 4 members (identity).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)
from compare_summaries import differences, relative_differences  # noqa: E402

RESULTS = ROOT / "docs" / "results"
PROBLEMS = ("droptest", "schiaparelli", "msl_meads", "post2_huygens")
TARGET_S = 60.0
TIMING_KEY = re.compile(r"wall|_median_s\b|/executor|member_wall")


class PeakRss:
    """Peak resident memory [MB] of a process and its descendants, sampled every ``dt`` seconds in a
    thread while the ``with`` block runs: ``.tree_mb`` (sum over the tree), ``.self_mb`` (the root)."""

    def __init__(self, pid: int | None = None, dt: float = 0.1):
        import psutil

        self._proc = psutil.Process(pid or os.getpid())
        self._dt = dt
        self.tree_mb = 0.0
        self.self_mb = 0.0
        self._stop = threading.Event()

    def _sample(self) -> None:
        import psutil

        while not self._stop.is_set():
            try:
                procs = [self._proc, *self._proc.children(recursive=True)]
                tot = 0
                for p in procs:
                    try:
                        tot += p.memory_info().rss
                    except psutil.Error:
                        pass
                self.tree_mb = max(self.tree_mb, tot / 1e6)
                self.self_mb = max(self.self_mb, self._proc.memory_info().rss / 1e6)
            except psutil.Error:
                return
            self._stop.wait(self._dt)

    def __enter__(self):
        self._t = threading.Thread(target=self._sample, daemon=True)
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_cli(checkout: Path, args: list[str], *, log: Path) -> dict:
    """``python -m workbench.cli <args>`` with ``checkout`` first on the path (cwd there); wall [s],
    CPU [s] of the command and its workers, peak RSS [MB] of its process tree. Raises on failure,
    with the tail of the log."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    cpu0, t0 = _children_cpu(), time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "workbench.cli", *args, "--quiet"],
            cwd=checkout,
            env=env,
            stdout=fh,
            stderr=subprocess.STDOUT,
        )
        import psutil

        peak = 0.0
        ps = psutil.Process(proc.pid)
        while proc.poll() is None:
            try:
                tot = sum(p.memory_info().rss for p in [ps, *ps.children(recursive=True)])
                peak = max(peak, tot / 1e6)
            except psutil.Error:
                pass
            time.sleep(0.1)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} in {checkout}: exit {proc.returncode}\n{log.read_text()[-3000:]}")
    return {"wall_s": wall, "cpu_s": cpu, "peak_rss_tree_mb": peak}


def extract(rev: str, dest: Path) -> str:
    """The commit ``rev`` of this repository extracted (``git archive``) into ``dest``, reading its own
    shipped assets; its full hash."""
    full = subprocess.run(["git", "rev-parse", rev], cwd=ROOT, check=True, capture_output=True, text=True).stdout
    dest.mkdir(parents=True, exist_ok=True)
    arch = subprocess.run(["git", "archive", rev], cwd=ROOT, check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch, check=True)
    # its own assets: the editable install maps the package ``workbench.assets`` to this checkout's
    # folder, and the extracted code would read today's scenario files (a link inside its package wins)
    link = dest / "workbench" / "assets"
    if (dest / "assets").is_dir() and not link.exists():
        link.symlink_to("../assets", target_is_directory=True)
    return full.strip()


def mc_json(folder: Path, scenario: str) -> dict:
    return json.loads((folder / f"{scenario}_truth.mc.json").read_text())


def identity(a: dict, b: dict) -> dict:
    """Max relative difference of the numbers two Monte Carlo JSONs share (timings skipped) and the
    differences beyond 1e-9 relative, or in strings and keys (the first 10)."""
    rel = [r for r in relative_differences(a, b) if not TIMING_KEY.search(r[1])]
    out: list[str] = []
    differences(a, b, "", "", "", 1e-9, out)
    out = [d for d in out if not TIMING_KEY.search(d.split(":")[0])]
    return {"n_differing": len(out), "max_rel_diff": rel[0][0] if rel else 0.0, "differing": out[:10]}


def mc_args(scenario: str, seeds: int, workers: int, out: Path) -> list[str]:
    """The ``workbench mc`` arguments of a truth Monte Carlo of ``seeds`` members on ``workers`` processes."""
    return ["mc", scenario, "--truth-sim", "--seeds", str(seeds), "--workers", str(workers), "--out", str(out)]


def part_mc(problems: list[str], seeds: int, baseline: str, baseline_seeds: int, work: Path) -> dict:
    """Per problem: the baseline's and this checkout's truth Monte Carlo (2 workers), and the
    identity check on 4 members (1 worker)."""
    base_dir = work / "baseline"
    base_full = extract(baseline, base_dir)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    out: dict = {"baseline_commit": base_full, "commit": head, "seeds": seeds, "baseline_seeds": baseline_seeds}
    for sc in problems:
        row: dict = {}
        for name, checkout, n in (("baseline", base_dir, baseline_seeds), ("current", ROOT, seeds)):
            d = work / f"{sc}_{name}"
            run_cli(checkout, mc_args(sc, 1, 1, d / "warm"), log=work / f"{sc}_{name}_warm.log")
            ident = run_cli(checkout, mc_args(sc, 4, 1, d / "id"), log=work / f"{sc}_{name}_id.log")
            timed = run_cli(checkout, mc_args(sc, n, 2, d / "mc"), log=work / f"{sc}_{name}_mc.log")
            row[name] = {
                **timed,
                "members": n,
                "per_member_wall_s": timed["wall_s"] / n,
                "per_member_cpu_s": timed["cpu_s"] / n,
                "identity_run_cpu_per_member_s": ident["cpu_s"] / 4,
            }
            print(f"[{sc}] {name}: {n} members, {timed['wall_s']:.1f} s wall, {timed['cpu_s'] / n:.2f} s CPU/member, "
                  f"peak {timed['peak_rss_tree_mb']:.0f} MB", flush=True)  # fmt: skip
        row["identity_4_members"] = identity(
            mc_json(work / f"{sc}_baseline" / "id", sc), mc_json(work / f"{sc}_current" / "id", sc)
        )
        b, c = row["baseline"], row["current"]
        row["ratio_per_member_wall"] = b["per_member_wall_s"] / c["per_member_wall_s"]
        row["ratio_per_member_cpu"] = b["per_member_cpu_s"] / c["per_member_cpu_s"]
        row["meets_60s"] = bool(c["wall_s"] <= TARGET_S) if seeds == 50 else None
        out[sc] = row
    cur = [out[s]["current"]["wall_s"] for s in problems]
    out["all_current_wall_s"] = float(sum(cur))
    return out


@contextmanager
def tcp_cluster(n_workers: int = 2):
    """A ``dask scheduler`` and ``n_workers`` ``dask worker`` processes (one thread each, this
    checkout on their path) started as child processes; yields the ``tcp://`` address."""
    dask = shutil.which("dask", path=str(Path(sys.executable).parent)) or "dask"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    tmp = Path(tempfile.mkdtemp(prefix="bench_tcp_"))
    port = 8700 + os.getpid() % 200
    addr = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              cwd=tmp, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]  # fmt: skip
    try:
        from distributed import Client

        time.sleep(2.0)
        for _ in range(n_workers):
            procs.append(subprocess.Popen(
                [dask, "worker", addr, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                 "--local-directory", str(tmp)], cwd=tmp, env=env, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL))  # fmt: skip
        with Client(addr, timeout=60) as cl:
            cl.wait_for_workers(n_workers, timeout=120)
        yield addr
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
        shutil.rmtree(tmp, ignore_errors=True)


def part_scale(members: int, chunk: int, cluster_mc: str, cluster_mc_seeds: int, work: Path) -> dict:
    """The entry dispersion with ``members`` members on four executors (wall, peak memory,
    identity), then ``cluster_mc_seeds`` truth Monte Carlo members on the ``tcp://`` cluster."""
    from bench_dispersion import scenario_input
    from distributed import LocalCluster

    from workbench.problems.entry import dispersion as ds

    imu, nom, events, _truth0, r_ground, desc = scenario_input(1)
    v0, q0, p0 = nom
    kw = dict(events_t=events, seed=2016, r_ground=r_ground, bridge_mode="relative", chunk_size=chunk, n_cloud=300)
    ds.run_dispersion(imu, v0, q0, p0, None, 4, **{**kw, "n_cloud": 0})  # compile / load the kernel
    out: dict = {"dispersion": {"members": members, "chunk_size": chunk, "input": desc}}
    ref = None

    def one(label: str, scheduler: str | None, workers: int = 1) -> None:
        nonlocal ref
        with PeakRss() as mem:
            t0 = time.perf_counter()
            res = ds.run_dispersion(imu, v0, q0, p0, None, members, scheduler=scheduler, workers=workers, **kw)
            wall = time.perf_counter() - t0
        same = None
        if ref is None:
            ref = res
        else:
            same = bool(np.array_equal(ref.accepted, res.accepted)) and all(
                np.array_equal(ref.events[k], res.events[k], equal_nan=True) for k in ds.EVENT_NAMES
            )
        out["dispersion"][label] = {"wall_s": wall, "peak_rss_self_mb": mem.self_mb, "peak_rss_tree_mb": mem.tree_mb,
                                    "members_per_s": members / wall, "identical_to_in_process": same,
                                    "accepted": int(np.count_nonzero(res.accepted))}  # fmt: skip
        print(f"[dispersion {members}] {label}: {wall:.1f} s, peak {mem.tree_mb:.0f} MB (tree), identical {same}",
              flush=True)  # fmt: skip

    one("in_process", None)
    for w in (1, 2):
        t0 = time.perf_counter()
        with LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
            out["dispersion"][f"local_cluster_{w}_startup_s"] = time.perf_counter() - t0
            one(f"local_cluster_{w}", cl.scheduler_address)
    with tcp_cluster(2) as addr:
        one("tcp_2_workers", addr)
        d = out["dispersion"]
        d["efficiency_local_2_vs_1"] = d["local_cluster_1"]["wall_s"] / (2 * d["local_cluster_2"]["wall_s"])
        d["efficiency_tcp_2_vs_in_process"] = d["in_process"]["wall_s"] / (2 * d["tcp_2_workers"]["wall_s"])
        if cluster_mc_seeds > 0:
            folder = work / "cluster_mc"
            timed = run_cli(ROOT, ["mc", cluster_mc, "--truth-sim", "--seeds", str(cluster_mc_seeds), "--scheduler",
                                   addr, "--out", str(folder)], log=work / "cluster_mc.log")  # fmt: skip
            first = run_cli(ROOT, ["mc", cluster_mc, "--truth-sim", "--seeds", str(cluster_mc_seeds), "--workers", "2",
                                   "--out", str(work / "pool_mc")], log=work / "pool_mc.log")  # fmt: skip
            out["cluster_mc"] = {"scenario": cluster_mc, "members": cluster_mc_seeds, "tcp_2_workers": timed,
                                 "process_pool_2_workers": first,
                                 "identity_vs_process_pool": identity(mc_json(work / "pool_mc", cluster_mc),
                                                                      mc_json(folder, cluster_mc))}  # fmt: skip
            print(f"[cluster mc] {cluster_mc} {cluster_mc_seeds} members: tcp {timed['wall_s']:.0f} s, "
                  f"pool {first['wall_s']:.0f} s", flush=True)  # fmt: skip
    return out


#: why a problem's numbers differ from the baseline's, when they do by design (shown in its table cell)
NOTES = {
    "msl_meads": " (the EKF retuned on the tuning seed stream: docs/tuning/meads.md)",
    "droptest": ' (the truth\'s contact area fixed and the scenarios re-set since: RESULTS.md, "Drop-test truth")',
}


def markdown(res: dict) -> str:
    """The issue #30 table of a ``bench_mc_speed`` JSON ``results``."""
    lines = []
    mc = res.get("mc")
    if mc:
        lines += [
            f"Truth Monte Carlo, `workbench mc <scenario> --truth-sim --workers 2`; baseline commit "
            f"`{mc['baseline_commit'][:7]}` ({mc['baseline_seeds']} members) vs `{mc['commit'][:7]}` "
            f"({mc['seeds']} members), one run:",
            "",
            "| problem | baseline wall | per member (wall / CPU) | now wall | per member (wall / CPU) | ratio "
            "(wall / CPU) | peak tree RSS | ≤ 60 s | same numbers (4 members) |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for sc in PROBLEMS:
            r = mc.get(sc)
            if not r:
                continue
            b, c, i = r["baseline"], r["current"], r["identity_4_members"]
            keys = [d.split(":")[0] for d in i["differing"] if d.endswith(("only in new", "only in old"))]
            n_num = i["n_differing"] - len(keys)
            same = (
                "yes (≤ 1e-9)"
                if n_num == 0
                else f"no: {n_num} numbers beyond 1e-9, max rel {i['max_rel_diff']:.1e}{NOTES.get(sc, '')}"
            )
            if keys:
                same += f"; keys in one only: {', '.join(f'`{k}`' for k in keys)}"
            meets = {True: "yes", False: "**no**", None: "—"}[r["meets_60s"]]
            lines.append(
                f"| {sc} | {b['wall_s']:.0f} s | {b['per_member_wall_s']:.2f} / {b['per_member_cpu_s']:.2f} s "
                f"| {c['wall_s']:.0f} s | {c['per_member_wall_s']:.2f} / {c['per_member_cpu_s']:.2f} s "
                f"| {r['ratio_per_member_wall']:.1f}× / {r['ratio_per_member_cpu']:.1f}× "
                f"| {c['peak_rss_tree_mb']:.0f} MB | {meets} | {same} |"
            )
        lines += ["", f"All four now: {mc['all_current_wall_s']:.0f} s wall (target ≤ 240 s).", ""]
    sc = res.get("scale")
    if sc:
        d = sc["dispersion"]
        lines += [
            f"Entry dispersion, {d['members']:,} members (chunks of {d['chunk_size']}), one pass:",
            "",
            "| executor | wall | members/s | peak RSS (this process / tree) | identical |",
            "|---|---|---|---|---|",
        ]
        for k in ("in_process", "local_cluster_1", "local_cluster_2", "tcp_2_workers"):
            e = d.get(k)
            if e:
                same = "reference" if e["identical_to_in_process"] is None else str(e["identical_to_in_process"])
                lines.append(f"| {k.replace('_', ' ')} | {e['wall_s']:.1f} s | {e['members_per_s']:,.0f} "
                             f"| {e['peak_rss_self_mb']:.0f} / {e['peak_rss_tree_mb']:.0f} MB | {same} |")  # fmt: skip
        eff_tcp = d["local_cluster_1"]["wall_s"] / (2 * d["tcp_2_workers"]["wall_s"])
        lines += [
            "",
            f"Scaling efficiency (one worker's wall / (2 × two workers' wall)): LocalCluster "
            f"{d['efficiency_local_2_vs_1']:.2f}, `tcp://` scheduler {eff_tcp:.2f}. In-process the compiled "
            "kernel already runs its chunks on Python threads over both cores, so a 2-worker cluster on this "
            "machine only adds transport; the cluster is for more machines.",
            "",
        ]
        cm = sc.get("cluster_mc")
        if cm:
            i = cm["identity_vs_process_pool"]
            tcp, pool = cm["tcp_2_workers"]["wall_s"], cm["process_pool_2_workers"]["wall_s"]
            lines.append(
                f"Truth Monte Carlo of {cm['members']} {cm['scenario']} members: tcp cluster {tcp:.0f} s, "
                f"process pool {pool:.0f} s; same numbers: {'yes' if i['n_differing'] == 0 else i['differing']}."
            )
    return "\n".join(lines)


def markdown_of(results_dir: Path = RESULTS) -> str:
    """The table of ``results_dir/bench_mc_speed.json`` with its reproducing command (README, RESULTS.md)."""
    doc = json.loads((results_dir / "bench_mc_speed.json").read_text())
    return f"{markdown(doc['results'])}\n\nReproduce: `{doc['command']}` ({doc['utc'][:10]}).\n"


def results_section_of(results_dir: Path = RESULTS) -> str:
    """The "Monte Carlo speed" section of docs/RESULTS.md (the same table as the README's)."""
    return "## Monte Carlo speed (issue #30)\n\n" + markdown_of(results_dir) + "\n" + _WHAT_CHANGED


_WHAT_CHANGED = """\
What changed, per problem (each compiled path keeps the Python one as its reference, with a test that the
two agree):

* **schiaparelli** — the entry truth simulator's derivative, RK4 and output loop compiled
  (`problems/entry/truth_fast.py`, bit-identical to the Python model over full flights), and the smoother's
  IMU step (RK4, Φ = expm(A dt), Qd) one compiled call (`estimation/strapdown_kernel.py`: the state
  bit-identical, Φ and Qd to rounding).
* **msl_meads** — the EKF carries the 39 states it uses, not 46 (the 7 second-order rate states are zero
  with the first-order model error); its forward pass, RTS smoother, measurement and transition are
  compiled; the air data propagate only the 14 states they read; the strapdown navigation uses the
  compiled step. Its numbers are not bit-identical: sums over 39 instead of 46 states differ in the last
  digit, and the iterated update's stop rule (absolute steps of 1 m and 0.01 m/s) turns that into
  differences of the kind a one-ulp change of the input pressures makes; the largest is on a mean error
  near zero (the table's "same numbers" column).
* **post2_huygens** — the table atmosphere's interpolation and the axial accelerometer compiled, the
  EKF's h and H from one batched Jacobian call; still over 60 s: each member's 2000-member initial-state
  selection (a diagnostic of the delivered start) is a large part of it.
* **droptest** — already compiled (its truth integrates with scipy's DOP853 around a compiled force
  model); members write their temporary truth file uncompressed.
* **every study** — a cold checkout compiles its kernels once in a child process before the workers
  start (as `workbench run` does).
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", default="mc,scale")
    ap.add_argument("--problems", default=",".join(PROBLEMS))
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--baseline", default="b028478", help="the commit measured as the baseline")
    ap.add_argument("--baseline-seeds", type=int, default=10)
    ap.add_argument("--dispersion-members", type=int, default=1_000_000)
    ap.add_argument("--chunk-size", type=int, default=5000)
    ap.add_argument("--cluster-mc", default="schiaparelli")
    ap.add_argument("--cluster-mc-seeds", type=int, default=200)
    ap.add_argument("--json", default=str(RESULTS / "bench_mc_speed.json"))
    ap.add_argument("--table", action="store_true", help="print the table of --json and exit")
    a = ap.parse_args(argv)
    if a.table:
        print(markdown(json.loads(Path(a.json).read_text())["results"]))
        return 0
    parts = a.parts.split(",")
    results: dict = {}
    old = Path(a.json)
    if old.is_file():  # parts not re-run keep their earlier values
        results = json.loads(old.read_text())["results"]
    with tempfile.TemporaryDirectory(prefix="bench_mc_speed_") as tmp:
        work = Path(tmp)
        if "mc" in parts:
            results["mc"] = part_mc(a.problems.split(","), a.seeds, a.baseline, a.baseline_seeds, work)
        if "scale" in parts:
            results["scale"] = part_scale(a.dispersion_members, a.chunk_size, a.cluster_mc, a.cluster_mc_seeds, work)
    write_benchmark_json(a.json, __file__, results, argv)
    print(markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
