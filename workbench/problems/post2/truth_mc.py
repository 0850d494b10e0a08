"""POST2 Monte Carlo against the truth simulator: NEES of the parameters and the trajectory over seeded truths.

Member i of a study (``workbench mc <post2 scenario> --truth-sim``; thesis [R3] Ch. 4–5 for the
Huygens-like case) draws from ``np.random.SeedSequence(entropy, spawn_key=(k, i))`` — k = 1 the
tuning stream, k = 2 the validation stream (:data:`STREAMS`; disjoint by construction) — three
integer seeds (:func:`member_seeds`): its sensor noise, its truth's initial position and velocity
(from the delivered covariance, :func:`~workbench.problems.post2.huygens.delivered_covariance`: what
the EKF's initial covariance says) and the parameters of ``[truth] monte_carlo_draw_from_prior``
(from the estimator's prior, :func:`draw_parameters`; the other planted values kept).  The truth is
simulated with the truth's own atmosphere and aerodynamics, its telemetry files written as a user
supplies them, and reconstructed exactly as ``workbench run`` does; the truth reaches only the
scoring (:func:`score_member`).

Scored per member: the NEES of the estimated parameters' final smoothed values (their full
covariance block, in the estimated coordinate), the end position and velocity NEES with their per
axis z, and the smoothed position NEES along the grid; over the members (:func:`aggregate`) each
mean against the two-sided 95 % band of a mean of N χ²(d) values, and the verdict
(consistent / conservative / overconfident).  Results are gathered by member index, so they do not
depend on the executor.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from workbench.io.telemetry import TelemetryError
from workbench.problems.base import SEED_STREAMS, RunOptions
from workbench.problems.members import run_members
from workbench.problems.post2 import huygens
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import STATES, scurve, scurve_inverse, scurve_slope
from workbench.problems.post2.scoring import trajectory_nees, truth_on_grid
from workbench.problems.runner import judge_health

__all__ = [
    "STREAMS",
    "McJob",
    "member_seeds",
    "parameter_names",
    "draw_parameters",
    "member_settings",
    "score_member",
    "run_member",
    "mean_band",
    "verdict",
    "aggregate",
    "TruthMcResult",
    "run_truth_monte_carlo",
]

#: Seed streams: ``SeedSequence(entropy, spawn_key=(STREAMS[stream], member))``; ``tests`` is the
#: slow tests' own (neither tuned on nor reported).
STREAMS = SEED_STREAMS
_TRAJ = ("position", "velocity")


@dataclass(frozen=True)
class McJob:
    """What every member needs (picklable): the post2 ``problem`` object (its synthesis,
    reconstruction, scoring), the run's ``settings``, the seed ``entropy``, the
    ``stream`` name (:data:`STREAMS`), the index of the ``first`` member, the parameter names
    ``draw`` drawn from the prior and the initial-state selection's ``members`` (None: the scenario's)."""

    problem: Any
    settings: Post2Settings
    entropy: int
    stream: str = "validation"
    first: int = 0
    draw: tuple[str, ...] = ()
    members: int | None = None


def member_seeds(entropy: int, stream: str, i: int) -> dict:
    """The integer seeds of member ``i`` of ``stream``: ``noise`` (sensor noise and the run's seed),
    ``state`` (the truth's initial state), ``params`` (its drawn parameters), from
    ``np.random.SeedSequence(entropy, spawn_key=(STREAMS[stream], i)).generate_state(3)``."""
    a, b, c = np.random.SeedSequence(int(entropy), spawn_key=(STREAMS[stream], int(i))).generate_state(3)
    return {"noise": int(a), "state": int(b), "params": int(c)}


def parameter_names(cfg: Post2Settings) -> tuple[str, ...]:
    """The scored parameters: the estimated states that are not trajectory states and have a
    ``[truth.states]`` value, in the order of the scenario's ``[states]``."""
    return tuple(s.name for s in cfg.states if not STATES[s.name].dynamic and s.name in cfg.truth.states)


def draw_parameters(cfg: Post2Settings, seed: int, names) -> dict[str, np.ndarray]:
    """One draw of the parameters ``names`` from the estimator's prior, ``{name: value (size,) SI}``:
    N(value, σ²) in the estimated coordinate, through the S-curve for a bounded state (the
    distribution the filter's P0 describes); parameter j of :func:`parameter_names` from its own
    stream ``default_rng([seed, j])`` (the same draw whatever else is drawn)."""
    out = {}
    for j, name in enumerate(parameter_names(cfg)):
        if name not in names:
            continue
        rng = np.random.default_rng([int(seed), j])
        s = cfg.state(name)
        v, sd = np.asarray(s.value, float), np.asarray(s.sigma, float)
        if s.bounds is not None:
            raw = scurve_inverse(v, *s.bounds)
            v = scurve(raw + sd / scurve_slope(raw, *s.bounds) * rng.standard_normal(v.shape), *s.bounds)
        else:
            v = v + sd * rng.standard_normal(v.shape)
        out[name] = np.atleast_1d(v)
    return out


def member_settings(cfg: Post2Settings, seeds: dict, draw=()) -> Post2Settings:
    """The settings of one member: ``[truth.states]`` position and velocity a draw (seed
    ``seeds["state"]``) from the delivered covariance about the estimator's initial state, and the
    parameters ``draw`` from the prior (:func:`draw_parameters`, seed ``seeds["params"]``)."""
    mean = np.concatenate([cfg.state("position").value, cfg.state("velocity").value])
    x = huygens.dispersed_members(mean, huygens.delivered_covariance(cfg), 2, seed=seeds["state"])[1]
    states = {**cfg.truth.states, "position": x[:3].copy(), "velocity": x[3:].copy()}
    states.update(draw_parameters(cfg, seeds["params"], draw))
    return replace(cfg, truth=replace(cfg.truth, states=states))


def score_member(result, truth: dict, params) -> dict:
    """Errors of one reconstruction ``result`` (a :class:`~workbench.problems.post2.pipeline.Post2Result`)
    against its ``truth`` (:meth:`Post2Problem.load_truth` arrays): ``nees`` of the ``params``' final
    smoothed values (x component of a vector) with their covariance block, ``z`` each one's error / σ,
    per trajectory state the end NEES, error and σ [m, m/s] and the smoothed NEES along the grid
    (``grid_nees``, (n,)), the start position error [m]."""
    sm = result.smap
    idx, err = [], []
    for name in params:
        b = sm.blocks[name]
        h = result.history["smoothed"][name]
        tv = np.atleast_1d(truth[f"param_{name}"]).astype(float)
        e0 = b.se.start
        idx.append(e0)
        v_phys, s_phys = h["value"][-1][0], h["sigma"][-1][0]
        raw_sigma = np.sqrt(result.P[-1][e0, e0])  # the covariance lives in the estimated coordinate
        err.append((v_phys - tv[0]) * raw_sigma / max(s_phys, 1e-300))
    P = result.P[-1][np.ix_(idx, idx)]
    err = np.asarray(err)
    tg = truth_on_grid(truth, result.t)
    traj = {}
    for name in _TRAJ:
        ii = np.arange(sm.blocks[name].se.start, sm.blocks[name].se.stop)
        e = sm.raw(result.x[-1], name) - tg[name][-1]
        Pe = result.P[-1][np.ix_(ii, ii)]
        grid = np.asarray(trajectory_nees(result, truth, (name,))["smoothed"], float)
        traj[name] = {
            "end_nees": float(e @ np.linalg.solve(Pe, e)),
            "end_error": e.tolist(),
            "end_sigma": np.sqrt(np.diag(Pe)).tolist(),
            "grid_mean_nees_smoothed": float(np.mean(grid)),
            "grid_nees": grid,
        }
    return {
        "start_error_m": float(np.linalg.norm(sm.raw(result.x[0], "position") - tg["position"][0])),
        "nees": float(err @ np.linalg.solve(P, err)),
        "z": (err / np.sqrt(np.diag(P))).tolist(),
        "trajectory": traj,
        "t": np.asarray(result.t, float),
    }


def run_member(job: McJob, k: int, _ss=None) -> dict:
    """Member ``job.first + k`` (module docstring): its truth simulated and its telemetry written
    into a temporary folder, reconstructed, scored; a task of
    :func:`~workbench.estimation.montecarlo.run_monte_carlo` (its seed sequence unused: the seeds
    come from the stream).  ``failed`` holds the message when the member could not be reconstructed."""
    t0 = time.perf_counter()
    i = job.first + int(k)
    seeds = member_seeds(job.entropy, job.stream, i)
    out = {"member": i, "seeds": seeds, "failed": ""}
    prob = job.problem
    cfg = member_settings(job.settings, seeds, job.draw)
    with tempfile.TemporaryDirectory(prefix=f"post2_truth_mc_{i}_") as tmp:
        try:
            syn = prob.synthesize(cfg, Path(tmp) / "telemetry", seeds["noise"])
        except (RuntimeError, ValueError, ArithmeticError) as err:
            return {**out, "failed": f"member {i}: truth simulation: {err}", "wall_s": time.perf_counter() - t0}
        truth = prob.load_truth(syn.truth)  # scoring only
        res = None
        try:
            with np.errstate(all="ignore"):
                for stage in prob.reconstruct(cfg, syn.telemetry, RunOptions(seed=seeds["noise"], members=job.members)):
                    res = stage
        except (ValueError, TelemetryError, ArithmeticError, np.linalg.LinAlgError) as err:
            return {**out, "failed": f"member {i}: reconstruction: {err}", "wall_s": time.perf_counter() - t0}
    out.update(score_member(res, truth, parameter_names(cfg)))
    s = prob.summary(res)
    s["truth"] = prob.score(res, truth)
    judge_health(prob, s)  # as `workbench run` judges it: calibrated statistics, the truth headline
    out["health"] = s["health"]["verdict"]
    out["health_not_ok"] = [c["name"] for c in s["health"]["checks"] if c["status"] != "OK"]
    out["mc_initial_state"] = s.get("mc_initial_state")
    out["truth_event_times_s"] = np.asarray(truth["event_times"], float).tolist()
    out["events_s"] = {e["event"]: e["t_s"] for e in s.get("events", [])}
    out["wall_s"] = time.perf_counter() - t0
    return out


def mean_band(n: int, d: int) -> list[float]:
    """Two-sided 95 % band of the mean of ``n`` independent χ²(d) values."""
    return (chi2.ppf([0.025, 0.975], n * d) / n).tolist()


def verdict(mean: float, band) -> str:
    """consistent inside ``band``, conservative below, overconfident above."""
    lo, hi = band
    return "consistent" if lo <= mean <= hi else ("conservative" if mean < lo else "overconfident")


def aggregate(runs: list[dict], params) -> dict:
    """Over the scored ``runs`` (:func:`run_member` outputs without ``failed``): the parameters' mean
    NEES and band, per parameter mean z, z² and the fraction inside 3σ; per trajectory state the
    end mean NEES, band and verdict, per axis mean z² and inside-3σ fraction, and the mean smoothed
    grid NEES (JSON-ready)."""
    n, d = len(runs), len(params)
    z = np.array([x["z"] for x in runs])
    mean = float(np.mean([x["nees"] for x in runs]))
    traj = {}
    for name in _TRAJ:
        tr = [x["trajectory"][name] for x in runs]
        m_end = float(np.mean([q["end_nees"] for q in tr]))
        ze = np.array([np.divide(q["end_error"], q["end_sigma"]) for q in tr])
        traj[name] = {
            "end_mean_nees": m_end,
            "end_band_95": mean_band(n, 3),
            "end_verdict": verdict(m_end, mean_band(n, 3)),
            "end_per_axis_mean_z2": np.mean(ze**2, axis=0).tolist(),
            "end_per_axis_inside_3sigma": np.mean(np.abs(ze) <= 3.0, axis=0).tolist(),
            "grid_mean_nees_smoothed": float(np.mean([q["grid_mean_nees_smoothed"] for q in tr])),
        }
    return {
        "runs_completed": n,
        "dimension": d,
        "parameters": list(params),
        "mean_nees": mean,
        "band_95": mean_band(n, d),
        "verdict": verdict(mean, mean_band(n, d)),
        "trajectory": traj,
        "start_error_m_mean": float(np.mean([x["start_error_m"] for x in runs])),
        "per_parameter_mean_z": dict(zip(params, np.mean(z, axis=0).tolist(), strict=True)),
        "per_parameter_mean_z2": dict(zip(params, np.mean(z**2, axis=0).tolist(), strict=True)),
        "per_parameter_inside_3sigma": dict(zip(params, np.mean(np.abs(z) <= 3.0, axis=0).tolist(), strict=True)),
    }


@dataclass(frozen=True)
class TruthMcResult:
    """Outcome of :func:`run_truth_monte_carlo`: every member's score in member order (failed ones
    with ``failed`` set), the JSON-ready ``summary``, and ``t`` (n,) [s] with ``grid_nees`` (K, n, 2)
    the scored members' smoothed position and velocity NEES along the first member's grid (each
    member's interpolated onto it; NaN outside a member's span)."""

    members: tuple[dict, ...]
    summary: dict
    t: np.ndarray
    grid_nees: np.ndarray


def run_truth_monte_carlo(
    problem,
    settings: Post2Settings,
    *,
    n_runs: int,
    entropy: int,
    stream: str = "validation",
    first: int = 0,
    workers: int = 1,
    scheduler: str | None = None,
    draw: tuple[str, ...] | None = None,
    members: int | None = None,
) -> TruthMcResult:
    """The study of the module docstring for a synthetic post2 scenario (``problem`` the
    :class:`~workbench.problems.post2.problem.Post2Problem`, ``settings`` its run's): members ``first`` …
    ``first + n_runs − 1`` of ``stream`` with seed ``entropy`` on
    :func:`~workbench.estimation.montecarlo.run_monte_carlo` (``workers``, ``scheduler`` as there);
    ``draw`` the parameters drawn from the prior (default ``[truth] monte_carlo_draw_from_prior``);
    ``members`` the initial-state selection's (None: ``[monte_carlo] members``).
    Raises ``RuntimeError`` when no member could be reconstructed."""
    if int(n_runs) < 1:
        raise ValueError("run_truth_monte_carlo: n_runs must be ≥ 1")
    if stream not in STREAMS:
        raise ValueError(f"run_truth_monte_carlo: stream must be one of {tuple(STREAMS)}, got {stream!r}")
    wall0 = time.perf_counter()
    draw = settings.truth.monte_carlo_draw_from_prior if draw is None else tuple(draw)
    job = McJob(problem, settings, int(entropy), stream, int(first), draw, members)
    run = run_members(
        run_member, n_runs, shared=job, seed=entropy, workers=workers, scheduler=scheduler,
        name=f"post2-truth-mc-{entropy}-{stream}",
    )  # fmt: skip
    members = list(run.results)
    ok = [m for m in members if not m["failed"]]
    if not ok:
        raise RuntimeError("no Monte Carlo member could be reconstructed: " + "; ".join(m["failed"] for m in members))
    params = parameter_names(settings)
    t = ok[0]["t"]
    grid = np.full((len(ok), t.size, 2), np.nan)
    for j, m in enumerate(ok):  # each member's grid has its own event times: onto the first member's
        inside = (t >= m["t"][0]) & (t <= m["t"][-1])
        for c, q in enumerate(_TRAJ):
            grid[j, inside, c] = np.interp(t[inside], m["t"], m["trajectory"][q]["grid_nees"])
    walls = np.array([m["wall_s"] for m in members])
    summary = {
        "kind": "post2_truth_mc",
        "scenario": settings.run.name,
        "seed_stream": {
            "stream": stream,
            "spawn_key": [STREAMS[stream], "member"],
            "entropy": int(entropy),
            "members": [m["member"] for m in members],
            "rule": "SeedSequence(entropy, spawn_key=(1, i)) tuning, (2, i) validation",
        },
        "runs_requested": int(n_runs),
        "parameters_drawn_from_prior": list(draw),
        **aggregate(ok, params),
        "failed_members": [m["failed"] for m in members if m["failed"]],
        "member_health": {str(m["member"]): m["health"] for m in ok},
        "member_health_counts": {v: sum(m["health"] == v for m in ok) for v in ("OK", "WARNING", "ERROR")},
        "member_health_not_ok": {str(m["member"]): m["health_not_ok"] for m in ok if m["health_not_ok"]},
        "member_wall_s": {"median": float(np.median(walls)), "max": float(np.max(walls))},
        "executor": run.executor,
        "workers": run.workers,
        "wall_s": time.perf_counter() - wall0,
        "runs": [_json_member(m) for m in members],
    }
    return TruthMcResult(tuple(members), summary, t, grid)


def _json_member(m: dict) -> dict:
    """A member's score without its arrays (the grid and its NEES histories)."""
    out = {k: v for k, v in m.items() if k != "t"}
    if "trajectory" in m:
        out["trajectory"] = {n: {k: v for k, v in q.items() if k != "grid_nees"} for n, q in m["trajectory"].items()}
    return out
