"""The Problem protocol: what a reconstruction problem (drop test, entry, ...) gives the runner.

A scenario file names its problem by ``[scenario] kind``; :mod:`workbench.problems.registry` maps
the kind to an object implementing :class:`Problem`, and :mod:`workbench.problems.runner` runs
any scenario through it with the same steps::

    settings (validate the scenario and every file it names, once, before any computation)
    -> synthesize (synthetic scenarios) -> reconstruct (yields stages) -> record each stage
    -> key moments -> score against the truth (synthetic) -> scorecard -> summary.json (-> CSV export)

The :class:`Problem` methods are a problem's entry point: :meth:`Problem.settings` is the only one
that sees the :class:`~workbench.io.scenario.Scenario`; every other receives the frozen settings
object it built (:class:`Settings`), and nothing below them receives a scenario.

A problem composes its own pipeline, truth simulator, recording and Monte Carlo modules; the
runner and the command line hold no problem knowledge.  The small frozen dataclasses below are
what crosses the boundary.  Units: SI; times in seconds from the problem's own epoch.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from workbench.io.moments import KeyMoment
from workbench.io.scenario import RunInfo, Scenario, ScenarioError

__all__ = [
    "require_synthetic",
    "ExportTable",
    "KeyMoment",
    "McOptions",
    "McOutcome",
    "Problem",
    "Progress",
    "RunOptions",
    "Settings",
    "StageRecorder",
    "Synthesized",
]

#: A progress sink: one human-readable line per call.  The command line passes a
#: :class:`workbench.io.progress.Reporter` (stderr; prefixes the scenario name; nothing under
#: ``--quiet``); counters with an ETA come from :func:`workbench.io.progress.current`.
Progress = Callable[[str], None]


@runtime_checkable
class Settings(Protocol):
    """The frozen settings of one run, built once by :meth:`Problem.settings` from the scenario and
    every file it names (assets, setup files), before any computation: per-stage frozen dataclasses
    (truth, sensors, filter, ...) with every default filled in from the schemas. ``run`` says which
    scenario file they came from (:class:`~workbench.io.scenario.RunInfo`)."""

    run: RunInfo


@dataclass(frozen=True)
class RunOptions:
    """Options of one reconstruction run.

    ``seed``: seed of the synthetic sensors and of any sampling in the reconstruction (None: the
    scenario's ``[synthetic] seed``, else 0); ``export``: also write the reconstructed histories as
    CSV; ``scheduler``: ensemble stages on Dask (``"local"`` or ``"tcp://host:port"``; None:
    in-process); ``members``: size of the problem's ensemble stage, if it has one (None: the
    scenario's setting); ``allow_unhealthy``: publish the outputs even when the health verdict
    (``summary["health"]``, :mod:`workbench.estimation.health`) is ERROR, marked as such (else the
    runner raises :class:`~workbench.estimation.health.UnhealthyError` and writes nothing).
    """

    seed: int | None = None
    export: bool = False
    scheduler: str | None = None
    members: int | None = None
    allow_unhealthy: bool = False


SEED_ENTROPY = 20261204
"""The entropy of every seed stream of the project (``np.random.SeedSequence``)."""

SEED_STREAMS = {"tuning": 1, "validation": 2, "calibration": 3, "tests": 4}
"""Spawn keys of the seed streams: tuning may use any seed of stream 1; consistency claims come from
stream 2, never used to choose a setting; the health bands from stream 3; the slow tests' truths from 4."""


def stream_seeds(stream: str | int, n: int) -> list[int]:
    """The first ``n`` integer seeds (< 2**31) of the seed stream ``stream`` (a name of
    :data:`SEED_STREAMS` or its spawn key): ``SeedSequence(SEED_ENTROPY, spawn_key=(k,))``."""
    k = SEED_STREAMS[stream] if isinstance(stream, str) else int(stream)
    ss = np.random.SeedSequence(SEED_ENTROPY, spawn_key=(k,))
    return [int(s) for s in ss.generate_state(int(n), dtype=np.uint32) % np.uint32(2**31 - 1)]


@dataclass(frozen=True)
class McOptions:
    """Options of a Monte Carlo run: ``n_runs`` runs seeded ``first_seed, first_seed + 1, ...``,
    on ``workers`` local processes or a Dask ``scheduler``; ``members`` as in :class:`RunOptions`.

    ``truth_sim``: every run's truth from the problem's truth simulator and its reconstruction
    through the full pipeline from telemetry files (entry: ``problems/entry/truth_mc.py``; meads:
    ``problems/meads/truth_mc.py``, the full error model; the drop test's Monte Carlo already
    synthesizes every run and ignores it); ``refine_rounds``: refinement
    rounds of the ensemble stage, if it has them (None: the study's default).

    ``stream``: a name of :data:`SEED_STREAMS` — the members' seeds come from that stream
    (:attr:`seeds`, :attr:`entropy`) instead of ``first_seed``, so a consistency number measured on
    the validation stream is on truths no setting was chosen on."""

    n_runs: int = 20
    first_seed: int = 1
    workers: int = 2
    scheduler: str | None = None
    members: int | None = None
    truth_sim: bool = False
    refine_rounds: int | None = None
    stream: str | None = None

    def __post_init__(self) -> None:
        if self.stream is not None and self.stream not in SEED_STREAMS:
            raise ValueError(f"unknown seed stream {self.stream!r}: one of {', '.join(SEED_STREAMS)}")

    @property
    def seeds(self) -> list[int]:
        """The run seeds: ``[first_seed, ..., first_seed + n_runs - 1]``, or with a ``stream`` its
        first ``n_runs`` seeds (:func:`stream_seeds`)."""
        if self.stream is not None:
            return stream_seeds(self.stream, self.n_runs)
        return list(range(self.first_seed, self.first_seed + self.n_runs))

    @property
    def entropy(self) -> int:
        """The root seed of a study that spawns its members from one seed (member k:
        ``SeedSequence(entropy, spawn_key=(k,))``): ``first_seed``, or with a ``stream`` that
        stream's first seed."""
        return stream_seeds(self.stream, 1)[0] if self.stream is not None else int(self.first_seed)

    def seed_record(self) -> dict:
        """How the members were seeded, for the study's JSON: the stream (None: ``first_seed``),
        the first seed or entropy, the rule."""
        return {
            "stream": self.stream,
            "first_seed": self.first_seed if self.stream is None else None,
            "entropy": self.entropy,
            "rule": "members seeded from first_seed (no named stream)"
            if self.stream is None
            else f"stream {self.stream!r}: SeedSequence({SEED_ENTROPY}, spawn_key=({SEED_STREAMS[self.stream]},))",
        }


@dataclass(frozen=True)
class Synthesized:
    """What :meth:`Problem.synthesize` wrote: ``telemetry`` {stream: file} exactly as a user would
    supply it (the input of :meth:`Problem.reconstruct`) and ``truth`` (the ``truth.npz`` file)."""

    telemetry: Mapping[str, Path]
    truth: Path


@dataclass(frozen=True)
class ExportTable:
    """Reconstructed histories for CSV export: ``time_s`` (n,) [s]; ``columns`` name ->
    ``(values (n,) in SI, unit string)`` (the :func:`workbench.io.results.export_csv` convention);
    ``frame``: the reference frame the columns are expressed in; ``sparse``: the columns that have no
    value at some times (NaN there; written as empty cells and declared ``# sparse:`` in the file)."""

    time_s: np.ndarray
    columns: Mapping[str, tuple[np.ndarray, str]]
    frame: str
    sparse: tuple[str, ...] = ()


@dataclass(frozen=True)
class McOutcome:
    """Result of :meth:`Problem.monte_carlo`: the JSON-ready ``summary`` (written by the runner to
    ``<name>.mc.json``), the ``recording`` it wrote and a one-line ``headline`` for the user."""

    summary: dict
    recording: Path
    headline: str
    details: Any = field(default=None, repr=False)


@runtime_checkable
class StageRecorder(Protocol):
    """Draws a run into an open recording, stage by stage."""

    def handle(self, stage: object) -> None:
        """Draw one stage yielded by :meth:`Problem.reconstruct`; a stage type the recorder does not
        know is an error (``TypeError``, see :class:`workbench.recording.dispatch.StageDispatch`)."""

    def finish(self, result: object, summary: dict) -> None:
        """After the last stage: draw what needs the whole result (scorecard, final layout) and
        log the run's key moments, ``summary["key_moments"]``, with
        :func:`workbench.recording.moments.log_key_moments` (bookmarks and the property that
        ``workbench open --at`` reads). ``summary`` is the run's summary including the key
        moments, the truth score, seed and wall time."""


@runtime_checkable
class Problem(Protocol):
    """A reconstruction problem (one scenario ``kind``).

    Attributes: ``kind`` (the ``[scenario] kind`` string it handles); ``title`` (what its truth
    simulation simulates, for progress lines, e.g. ``"drop"``); ``schema``: the configuration
    schema of its scenario tables, or None while it has none. A problem may also list
    ``file_schemas``, the :class:`~workbench.io.schema.Schema` of every other file kind it reads
    (assets, setup files, log metadata), for the generated documentation
    (:func:`workbench.problems.registry.schemas`), and ``telemetry_schemas`` {stream: schema} for
    telemetry streams that are TOML files (``workbench init`` marks their example values).
    """

    kind: str
    title: str
    schema: Any

    def settings(self, scenario: Scenario) -> Settings:
        """Validate ``scenario`` against :attr:`schema` and read every file it names (assets, setup
        files) against theirs; return the run's frozen :class:`Settings`. Raises ``ScenarioError``
        naming file, key (with the nearest valid key) or bound. Called once per run, first."""

    def telemetry_files(self, settings: Settings, folder: Path | None = None) -> dict[str, Path]:
        """The telemetry files of a run, {stream: path}: those named by the scenario's
        ``[telemetry]`` table, or (``folder`` given) the standard file names inside ``folder``
        (the layout :meth:`synthesize` writes).  Raises ``ScenarioError`` naming a missing key/file."""

    def synthesize(self, settings: Settings, out_dir: Path, seed: int) -> Synthesized:
        """Simulate the truth and write telemetry files (as a user supplies them) and
        ``truth.npz`` into ``out_dir``; ``seed`` drives the sensor errors."""

    def load_truth(self, path: Path) -> Any:
        """Read the ``truth.npz`` written by :meth:`synthesize` (for scoring and drawing only)."""

    def reconstruct(self, settings: Settings, telemetry: Mapping[str, Path], options: RunOptions) -> Iterator[object]:
        """Run the reconstruction on the ``telemetry`` files; yield typed stage results in order,
        the last one the final result (with a JSON-ready ``summary`` dict attribute)."""

    def summary(self, result: object) -> dict:
        """The JSON-ready key numbers of a final result (no truth involved), a new dict."""

    def key_moments(self, result: object) -> list[KeyMoment]:
        """The moments of the final ``result`` a reviewer jumps to (drop test: release, bungee cut,
        first contact, max stroke, rebound; entry: EIP, peak deceleration, PDD, FSR, first radar fix
        ...), each with its time [s] on the recording's ``time`` timeline, a one-line description and
        optionally a time window around it. From the reconstruction and the telemetry, never from
        the truth; moments that did not happen (no contact, no radar) are left out. The runner
        stores them in time order in ``summary["key_moments"]``."""

    def score(self, result: object, truth: Any) -> dict:
        """Errors of the final ``result`` against the ``truth`` (JSON-ready; under ``"truth"``)."""

    def scorecard(self, summary: dict) -> str:
        """The run's scorecard (markdown) from its summary (incl. ``"truth"`` when scored)."""

    def headline(self, summary: dict) -> str:
        """One line with the run's main result, for the user.

        A problem may also offer ``calibration_settings(settings, seed) -> Settings``, a health
        calibration member's settings with its truth dispersed (:func:`workbench.problems.runner.evaluate`).

        A problem may also offer ``estimator(settings) -> str``, the size of its filter computed from
        the code (e.g. ``"EKF: 42 error states (43 full)"``); ``workbench list`` prints it after the
        scenario's description, so no state count is typed into a description."""

    def open_recording(
        self, path: Path, settings: Settings, truth: Any, properties: dict
    ) -> AbstractContextManager[StageRecorder]:
        """Open the problem's recording at ``path`` (published only if the block succeeds), with
        its layout; yields the :class:`StageRecorder`.  ``truth``: loaded truth or None;
        ``properties``: recording properties (``{"run": {...}}``)."""

    def export_columns(self, result: object) -> ExportTable:
        """The reconstructed histories of a final result for CSV export."""

    def monte_carlo(self, settings: Settings, out_dir: Path, options: McOptions, progress: Progress) -> McOutcome:
        """The problem's Monte Carlo / consistency analysis of the run ``settings``; writes its recording
        under ``out_dir``, reports its phases to ``progress`` and returns the summary.  Raises
        ``NotImplementedError`` if the scenario does not allow one (e.g. not synthetic)."""


def require_synthetic(run: RunInfo, study: str = "the Monte Carlo against the truth") -> None:
    """Raise a ``ScenarioError`` naming the scenario file and ``[synthetic]`` unless the run
    ``run`` is synthetic: a study that needs the truth simulator (``study``) cannot run on user data."""
    if not run.synthetic:
        raise ScenarioError(run.path, "synthetic", f"{study} needs a synthetic scenario ([synthetic])")
