"""A wheel installs like a library: built from the repository, installed (not editable) into a
fresh virtual environment, it lists and runs the shipped scenarios from another directory.

Slow tier: building a wheel and running a drop test take about a minute.  The fresh venv reuses
the dependencies of the running interpreter through a ``.pth`` line (no download), but the
``workbench`` package itself comes only from the wheel (checked).
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def wheel_env(tmp_path_factory):
    """(python, workbench script, work dir) of a venv holding only the built wheel."""
    tmp = tmp_path_factory.mktemp("wheel")
    dist = tmp / "dist"
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(ROOT)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    (whl,) = dist.glob("edl_workbench-*.whl")
    env_dir = tmp / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    py = env_dir / "bin" / "python"
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], capture_output=True, text=True
    ).stdout.strip()
    # dependencies from the running interpreter, appended after the venv's own site-packages
    # (and wherever the running interpreter actually finds them, e.g. through a .pth of its own)
    import numpy
    import rerun
    import scipy
    import trimesh

    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    deps |= {str(Path(m.__file__).resolve().parents[1]) for m in (numpy, scipy, trimesh, rerun)}
    Path(site, "zz_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    r = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(whl)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    work = tmp / "elsewhere"
    work.mkdir()
    return py, env_dir / "bin" / "workbench", work


def test_wheel_ships_the_package_and_assets(wheel_env):
    py, _, work = wheel_env
    r = subprocess.run(
        [str(py), "-c", "import workbench, workbench.io.assets as a; print(workbench.__file__); print(a.assets_dir())"],
        capture_output=True,
        text=True,
        cwd=work,
    )
    assert r.returncode == 0, r.stderr
    pkg, assets = r.stdout.split()
    assert str(py.parent.parent) in pkg, f"workbench imported from {pkg}, not from the wheel"
    assert str(py.parent.parent) in assets
    assert (Path(assets) / "landers" / "mer_drop_lander.toml").is_file()


def test_wheel_lists_and_runs_a_scenario(wheel_env, tmp_path):
    _, wb, work = wheel_env
    env = {**os.environ, "PYTHONPATH": ""}
    r = subprocess.run([str(wb), "list"], capture_output=True, text=True, cwd=work, env=env)
    assert r.returncode == 0, r.stderr
    names = {line.split()[0] for line in r.stdout.splitlines() if line.strip()}
    assert {"droptest", "schiaparelli"} <= names
    out = tmp_path / "out"
    r = subprocess.run(
        [str(wb), "run", "droptest", "--out", str(out)], capture_output=True, text=True, cwd=work, env=env
    )
    assert r.returncode == 0, r.stderr
    assert (out / "droptest.rrd").stat().st_size > 1_000_000
    assert (out / "droptest.summary.json").is_file()
