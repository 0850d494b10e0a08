"""Shared, session-scoped drop-test runs for the pipeline tests.

A CLI run (truth simulation ~7–12 s, reconstruction ~2 s, recording ~5 s) is far too costly to
repeat per test, so each shipped scenario is run at most once per session through the same
entry point the command line calls (``workbench.problems.runner.run_scenario``), lazily, the first time a test asks
for it. The clean reconstruction of the ``droptest`` telemetry (``run_droptest`` on the files the
CLI wrote) is shared too: the recording tests compare the logged numbers with it and the
telemetry-defect tests use it as the no-defect baseline.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import Scenario, resolve_scenario
from workbench.problems.droptest import pipeline as dt
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.synthetic import load_truth
from workbench.problems.runner import run_scenario


@dataclass(frozen=True)
class CliRun:
    """One ``run_scenario(name, out)`` (quiet): where it wrote, and the summary it returned."""

    name: str
    out: Path
    summary: dict

    @property
    def scenario(self) -> Scenario:
        return resolve_scenario(self.name, assets_dir())

    @property
    def settings(self):
        """The run's frozen settings (``DropTestProblem().settings``)."""
        return DropTestProblem().settings(self.scenario)

    @property
    def rrd(self) -> Path:
        return self.out / f"{self.name}.rrd"

    @property
    def summary_json(self) -> Path:
        return self.out / f"{self.name}.summary.json"

    @property
    def telemetry_dir(self) -> Path:
        return self.out / self.name / "telemetry"

    def telemetry_paths(self, folder: Path | None = None) -> dict[str, Path]:
        """The pipeline's ``paths`` dict for the telemetry files in ``folder`` (default: as written)."""
        d = self.telemetry_dir if folder is None else Path(folder)
        return DropTestProblem().telemetry_files(self.settings, d)

    def truth(self) -> dict:
        return load_truth(self.telemetry_dir / "truth.npz")


@pytest.fixture(scope="session")
def cli_run(tmp_path_factory) -> Callable[[str], CliRun]:
    """``cli_run(name)`` -> :class:`CliRun`; each shipped scenario is run once per session."""
    cache: dict[str, CliRun] = {}

    def get(name: str) -> CliRun:
        if name not in cache:
            out = tmp_path_factory.mktemp(f"cli_{name}")
            cache[name] = CliRun(name, out, run_scenario(name, out).summary)
        return cache[name]

    return get


@pytest.fixture(scope="session")
def droptest_run(cli_run) -> CliRun:
    return cli_run("droptest")


@pytest.fixture(scope="session")
def droptest_result(droptest_run) -> dt.DropResult:
    """The reconstruction re-run (no recorder) on the telemetry files the ``droptest`` CLI run wrote."""
    run = droptest_run
    return dt.run_droptest(run.settings, run.telemetry_paths(), seed=run.summary["seed"])


@pytest.fixture(scope="session")
def droptest_truth(droptest_run) -> dict:
    return droptest_run.truth()
