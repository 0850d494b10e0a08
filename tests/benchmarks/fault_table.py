"""The interruption / fault table of ``workbench run`` and ``workbench mc``: exit code, the last line
on stderr, whether a traceback was printed, and what is left on disk, measured by running the
command line in a subprocess and hurting it.

Cases: SIGINT, SIGTERM and SIGKILL while the recording is being written (and, after SIGKILL, what
the next run leaves), a read-only output folder and a new sub-folder on a read-only folder (run as
an unprivileged user when measured as root, since root ignores permissions), an output path below a
regular file ("missing" location), a full disk (the Rerun stream's flush made to fail as Rerun does
on ENOSPC, "File-writer thread shut down prematurely"), a Dask worker killed during ``mc`` and a
closed pipe (``workbench list | head -1``).

    .venv/bin/python tests/benchmarks/fault_table.py [--code DIR] [--label NAME] [--no-json]

``--code DIR``: measure another checkout's ``workbench`` package (e.g. an export of an old commit;
it is put first on ``PYTHONPATH``). Writes ``docs/results/fault_table.json`` unless ``--no-json``
(with ``--code`` it prints only).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = "droptest"
NOBODY = 65534


def _env(code: str | None, tmpdir: str | None = None) -> dict:
    env = dict(os.environ)
    if code:
        env["PYTHONPATH"] = code + os.pathsep + env.get("PYTHONPATH", "")
    if tmpdir:
        env["TMPDIR"] = tmpdir
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def _listing(folder: Path) -> list[str]:
    """Every file and every empty folder below ``folder`` (relative), or a note when none."""
    if not folder.exists():
        return ["(no folder)"]
    out = []
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if p.is_dir():
            if not any(p.iterdir()):
                out.append(f"{rel}/ (empty)")
        else:
            out.append(str(rel))
    return out or ["(empty folder)"]


def _summarise(folder: Path) -> str:
    """What is left, compactly: partials, recordings, summaries, telemetry files, empty folders."""
    items = _listing(folder)
    if items in (["(no folder)"], ["(empty folder)"]):
        return items[0]
    partial = [i for i in items if i.endswith(".partial")]
    rrd = [i for i in items if i.endswith(".rrd")]
    summ = [i for i in items if i.endswith(".summary.json") or i.endswith(".mc.json")]
    empty = [i for i in items if i.endswith("(empty)")]
    tel = [i for i in items if "telemetry/" in i]
    other = [i for i in items if i not in partial + rrd + summ + empty + tel]
    parts = []
    if partial:
        parts.append(f"{len(partial)} .partial")
    if rrd:
        parts.append(f"{len(rrd)} .rrd")
    if summ:
        parts.append(f"{len(summ)} summary")
    if tel:
        parts.append(f"synthetic telemetry ({len(tel)} files)")
    if empty:
        parts.append(f"empty folders {empty}")
    if other:
        parts.append(f"{len(other)} other files, e.g. {other[0]}")
    return ", ".join(parts)


def _default_signals() -> None:
    """In the child: SIGINT back to its default (a shell's background job starts with it ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _run(argv: list[str], code: str | None, *, user: int | None = None, tmpdir=None, cwd=None) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "workbench.cli", *argv]
    if user is not None:
        cmd = ["setpriv", f"--reuid={user}", f"--regid={user}", "--clear-groups", *cmd]
    return subprocess.Popen(
        cmd,
        env=_env(code, tmpdir),
        cwd=cwd or tempfile.gettempdir(),
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        preexec_fn=_default_signals,
    )


def _finish(p: subprocess.Popen, timeout: float = 1800.0) -> tuple[int, str, bool]:
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        return None, f"(no exit within {timeout:.0f} s: killed by the benchmark)", False
    text = err.decode(errors="replace").strip().splitlines()
    last = text[-1] if text else ""
    return p.returncode, last[:160], any("Traceback" in line for line in text)


def _wait_for_partial(out: Path, p: subprocess.Popen, timeout: float = 900.0) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and p.poll() is None:
        if out.is_dir() and any(out.glob("*.partial")):
            time.sleep(0.3)  # well inside the reconstruction
            return True
        time.sleep(0.02)
    return False


def case_signal(base: Path, code: str | None, sig: int) -> dict:
    out = base / f"sig{sig}"
    p = _run(["run", SCENARIO, "--out", str(out)], code)
    if not _wait_for_partial(out, p):
        p.kill()
        rc, last, tb = _finish(p)
        return {"exit": rc, "stderr": last, "left": "no partial recording appeared in time", "traceback": tb}
    os.kill(p.pid, sig)
    rc, last, tb = _finish(p)
    row = {"exit": rc, "stderr": last, "traceback": tb, "left": _summarise(out)}
    if sig == signal.SIGKILL:  # what the next run leaves of the killed run's partial
        p2 = _run(["run", SCENARIO, "--out", str(out)], code)
        rc2, _, tb2 = _finish(p2)
        row["next_run_exit"] = rc2
        row["left_after_next_run"] = _summarise(out)
    return row


def case_readonly(base: Path, code: str | None, sub: bool) -> dict:
    ro = base / ("ro_parent" if sub else "ro_out")
    ro.mkdir()
    os.chmod(base, 0o755)
    os.chmod(ro, 0o555)
    out = ro / "new" if sub else ro
    user = NOBODY if os.geteuid() == 0 else None
    p = _run(["run", SCENARIO, "--out", str(out)], code, user=user)
    rc, last, tb = _finish(p)
    os.chmod(ro, 0o755)
    return {"exit": rc, "stderr": last, "traceback": tb, "left": _summarise(ro)}


def case_missing(base: Path, code: str | None) -> dict:
    f = base / "a_file"
    f.write_text("not a folder\n")
    p = _run(["run", SCENARIO, "--out", str(f / "out")], code)
    rc, last, tb = _finish(p)
    return {"exit": rc, "stderr": last, "traceback": tb, "left": "(nothing can be written)"}


_FULL = (
    "import sys, rerun as rr\n"
    "def flush(self, *a, **k):\n"
    "    raise RuntimeError('File-writer thread shut down prematurely')\n"
    "rr.RecordingStream.flush = flush\n"
    "from workbench.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)


def case_full_disk(base: Path, code: str | None) -> dict:
    out = base / "full"
    p = subprocess.Popen(
        [sys.executable, "-c", _FULL, "run", SCENARIO, "--out", str(out)],
        env=_env(code),
        cwd=tempfile.gettempdir(),
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    rc, last, tb = _finish(p)
    return {"exit": rc, "stderr": last, "traceback": tb, "left": _summarise(out)}


def _descendants(pid: int) -> list[int]:
    kids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if ppid == pid:
            kids.append(int(d.name))
    return kids + [g for k in kids for g in _descendants(k)]


def case_dask_worker(base: Path, code: str | None) -> dict:
    out = base / "dask_out"
    tmp = base / "dask_tmp"
    tmp.mkdir()
    cwd = base / "dask_cwd"
    cwd.mkdir()
    p = _run(
        ["mc", SCENARIO, "--seeds", "3", "--workers", "2", "--scheduler", "local", "--out", str(out)],
        code,
        tmpdir=str(tmp),
        cwd=str(cwd),
    )
    killed = None
    work = out / f"{SCENARIO}_mc_work"
    t0 = time.monotonic()
    while time.monotonic() - t0 < 900 and p.poll() is None and killed is None:
        time.sleep(0.2)
        if not (work.is_dir() and any(work.glob("seed*"))):
            continue  # no member is being computed yet
        time.sleep(1.0)  # well inside a member
        workers = []
        for q in _descendants(p.pid):
            try:
                cmd = Path(f"/proc/{q}/cmdline").read_bytes().decode(errors="replace")
            except OSError:
                continue
            if "spawn_main" in cmd or "forkserver" in cmd:
                workers.append(q)
        if workers:
            killed = workers[0]
            os.kill(killed, signal.SIGKILL)
    rc, last, tb = _finish(p, timeout=2400)
    return {
        "exit": rc,
        "stderr": last,
        "traceback": tb,
        "killed_worker_pid": killed,
        "left": _summarise(out),
        "left_in_tmpdir": _listing(tmp),
        "left_in_cwd": _listing(cwd),
    }


def case_pipe(code: str | None) -> dict:
    cmd = f"{sys.executable} -m workbench.cli list | head -1 >/dev/null; echo ${{PIPESTATUS[0]}}"
    r = subprocess.run(["bash", "-c", cmd], env=_env(code), capture_output=True, text=True, timeout=120)
    err = r.stderr.strip().splitlines()
    return {
        "exit": int(r.stdout.strip() or -1),
        "stderr": err[-1][:160] if err else "",
        "traceback": "Traceback" in r.stderr,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--code", default=None, help="a checkout whose workbench package to measure")
    ap.add_argument("--label", default="this commit")
    ap.add_argument("--no-json", action="store_true")
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--only", nargs="*", default=None, help="run only the cases whose name contains one of these")
    args = ap.parse_args(argv)
    code = str(Path(args.code).resolve()) if args.code else None
    base = Path(tempfile.mkdtemp(prefix="wb-faults-"))
    rows: dict[str, dict] = {}
    cases = [
        ("SIGINT", lambda: case_signal(base, code, signal.SIGINT)),
        ("SIGTERM", lambda: case_signal(base, code, signal.SIGTERM)),
        ("SIGKILL", lambda: case_signal(base, code, signal.SIGKILL)),
        ("read-only output folder", lambda: case_readonly(base, code, sub=False)),
        ("new folder in a read-only folder", lambda: case_readonly(base, code, sub=True)),
        ("output below a regular file", lambda: case_missing(base, code)),
        ("full disk (Rerun flush fails)", lambda: case_full_disk(base, code)),
        ("list | head -1", lambda: case_pipe(code)),
    ]
    if not args.skip_dask:
        cases.append(("killed Dask worker (mc)", lambda: case_dask_worker(base, code)))
    try:
        for name, case in cases:
            if args.only and not any(o.lower() in name.lower() for o in args.only):
                continue
            r = rows[name] = case()
            print(f"{name:34s} exit {r.get('exit')!s:5s} traceback {r.get('traceback')!s:5s} left: {r.get('left', '')}")
            for k in ("stderr", "next_run_exit", "left_after_next_run", "left_in_tmpdir", "left_in_cwd"):
                if k in r:
                    print(f"{'':34s} {k}: {r[k]}")
            sys.stdout.flush()
    finally:
        shutil.rmtree(base, ignore_errors=True)
    results = {"label": args.label, "scenario": SCENARIO, "cases": rows}
    if not args.no_json and code is None:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench_json import write_benchmark_json

        write_benchmark_json(ROOT / "docs" / "results" / "fault_table.json", __file__, results, argv)
    else:
        print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
