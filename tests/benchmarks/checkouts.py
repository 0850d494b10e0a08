"""A baseline commit beside this checkout, for the A/B benchmarks that run the workbench of two
commits in child processes (``bench_first_run.py``, ``bench_memory.py``).

:func:`baseline_worktree` checks the commit out with ``git worktree`` into a temporary folder,
byte-compiles both checkouts (neither run pays for it), checks that a child process with
``PYTHONPATH`` = a checkout imports that checkout's own ``workbench``, and removes the worktree at
the end. The shipped assets come from the installed package (an editable install maps
``workbench.assets`` to this checkout's ``assets/``), so a baseline whose ``assets/`` differ from
this checkout's is refused.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: runs the command line it is given and prints the rusage of its process tree as JSON: exit code,
#: CPU of every process [s], the largest peak resident set of any one of them [MB]
RUSAGE = (
    "import json, resource, subprocess, sys\n"
    "code = subprocess.run(sys.argv[1:]).returncode\n"
    "u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
    "print(json.dumps({'code': code, 'cpu_s': u.ru_utime + u.ru_stime, 'max_rss_mb': u.ru_maxrss / 1024}))\n"
)


def git(*args: str, cwd: Path = ROOT) -> str:
    """``git args`` in ``cwd``; its stdout, stripped (raises on a non-zero exit)."""
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def checkout_env(root: Path, **extra: str) -> dict[str, str]:
    """The environment of a child that runs checkout ``root``'s workbench: ``PYTHONPATH`` = root
    (after ``extra['PYTHONPATH']`` when given), numba's cache beside that checkout's sources."""
    env = dict(os.environ, **extra)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (extra.get("PYTHONPATH"), str(root)) if p)
    env.pop("NUMBA_CACHE_DIR", None)
    return env


@contextlib.contextmanager
def baseline_worktree(commit: str, tmp: Path) -> Iterator[dict[str, Path]]:
    """``{"baseline": worktree of commit, "current": this checkout}``, both byte-compiled and each
    importing its own ``workbench`` in a child; the worktree is removed on exit."""
    if git("status", "--porcelain", "--untracked-files=no", "--", "workbench"):
        print("note: this checkout's workbench/ has uncommitted changes; they are what runs as 'current'")
    if subprocess.run(["git", "diff", "--quiet", commit, "--", "assets"], cwd=ROOT).returncode != 0:
        raise SystemExit(f"assets/ differ between {commit} and this checkout: both runs would read this one's")
    base_root = tmp / "baseline"
    git("worktree", "add", "--detach", str(base_root), commit)
    try:
        roots = {"baseline": base_root, "current": ROOT}
        for name, root in roots.items():
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(root / "workbench")], check=True)
            probe = subprocess.run(
                [sys.executable, "-c", "import workbench; print(workbench.__file__)"],
                cwd=root, env=dict(os.environ, PYTHONPATH=str(root)), capture_output=True, text=True,
            )  # fmt: skip
            if Path(probe.stdout.strip()).resolve().parent.parent != root.resolve():
                raise SystemExit(f"the {name} run would not import its own workbench: {probe.stdout or probe.stderr}")
        yield roots
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(base_root)], cwd=ROOT, capture_output=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, capture_output=True)
