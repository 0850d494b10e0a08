"""The Huygens-like descent (post2 case 4): the Monte Carlo initial-state selection of the thesis
[R3] Ch. 5.1 and the planted-vs-recovered scorecard.

Monte Carlo initial state (Ch. 5.1): "The last JPL delivered initial state covariance was used to
generate 10000 dispersed states. Each of the 10000 cases was simulated and the sum of the
acceleration observation residual absolute value was accumulated ... The final value of this
metric (at parachute deploy) was then compared and the smallest value cases were used ... A time
adjustment at around 0.5 m/s² measured axial acceleration was determined to align each case with
the accelerometer."  Here (``[monte_carlo]`` of the problem file):

1. N members ``x_i = x̂ + L z_i`` (``L`` the Cholesky factor of ``covariance``, ``z_i`` standard
   normal from the run's seed), position/velocity only, the other model inputs nominal;
2. all members propagated TOGETHER (one (N, 6) array through the post2 :class:`TrajectoryModel`,
   RK4 of ``step_s``) over the entry phase, the model's axial acceleration stored on that grid;
3. the time alignment: member i's time ``t_i`` where |a| rises through ``align_level_m_s2`` minus
   the measured one ``t_meas`` is Δ_i (both from a line through ln|a| on the pulse's leading edge
   between half and twice the level: one noisy sample is not the crossing), refined to the
   smallest metric within ±1 s (0.1 s then 0.01 s steps); the member's acceleration at
   ``t_k + Δ_i`` is compared with sample k;
4. metric_i = Σ_k |z_k − a_i(t_k + Δ_i)| over the samples up to ``end_s``; the ``keep`` smallest
   are kept; the best member is moved along its own trajectory by Δ (so that its state belongs to
   the telemetry's t_start) and the spread of the kept members (each moved likewise) reported.
5. The EKF starts from the delivered state and its full covariance (:func:`start_from_delivered`),
   not from the best member: the metric is the NOMINAL model's residual, so the model's own errors
   (CA per regime, the atmosphere) move its minimum across the weakly observed directions, and the
   kept members' spread is the width of that minimum, not the state's uncertainty; the EKF then
   assimilates the same accelerometer samples again (counted twice).  The selection stays as the
   thesis' cross-check of the delivered state, with the chosen member's Mahalanobis distance from
   it (:meth:`McSelection.summary`).

With ``--scheduler`` the members run in chunks on Dask (``workbench.estimation.montecarlo``); a
per-member loop of the same maths (:func:`member_loop_metric`) is the benchmark's comparison.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from workbench.estimation.montecarlo import run_monte_carlo
from workbench.io.scenario import ScenarioError
from workbench.problems.post2 import build, kernels, pipeline
from workbench.problems.post2.config import Post2Settings, unit_factor
from workbench.problems.post2.model import POSITION, STATES, TRANSLATION, VELOCITY, TrajectoryModel

__all__ = [
    "McSelection",
    "dispersed_members",
    "entry_model",
    "delivered_covariance",
    "propagate_axial_acceleration",
    "member_metrics",
    "member_loop_metric",
    "select_initial_state",
    "reconstruct",
    "start_from",
    "start_from_delivered",
    "selection_note",
    "planted_table",
]


@dataclass(frozen=True)
class McSelection:
    """The Monte Carlo initial-state stage: ``members`` (N, 6) dispersed [p m, v m/s] at t_start,
    inertial; ``metric`` (N,) accumulated |residual| [m/s²·samples] (inf: never reached the
    alignment level); ``shift_s`` (N,) time alignment Δ [s]; ``kept`` (K,) member indices, best
    first; ``x0`` (6,) the chosen initial state (best member moved by its Δ) and ``sigma0`` (6,) the
    kept members' spread; ``nominal_metric`` of the delivered state itself; ``mean`` (6,) the
    delivered state; ``wall_s`` [s] of the member propagation; ``scheduler`` description;
    ``mahalanobis`` √(d' C⁻¹ d) of d = x0 − mean in the delivered covariance C."""

    members: np.ndarray
    metric: np.ndarray
    shift_s: np.ndarray
    kept: np.ndarray
    x0: np.ndarray
    sigma0: np.ndarray
    nominal_metric: float
    mean: np.ndarray
    wall_s: float
    scheduler: str
    mahalanobis: float = float("nan")

    def summary(self) -> dict:
        """JSON-ready numbers of the selection (km, m/s, s)."""
        d = self.x0 - self.mean
        return {
            "members": int(self.metric.size),
            "kept": int(self.kept.size),
            "best_member": int(self.kept[0]),
            "best_metric": float(self.metric[self.kept[0]]),
            "nominal_metric": float(self.nominal_metric),
            "best_shift_s": float(self.shift_s[self.kept[0]]),
            "chosen_minus_delivered_position_km": (d[POSITION] / 1e3).tolist(),
            "chosen_minus_delivered_velocity_m_s": d[VELOCITY].tolist(),
            "chosen_mahalanobis_from_delivered": float(self.mahalanobis),
            "used_as_start": False,
            "start": "the delivered state and its full covariance",
            "wall_s": float(self.wall_s),
            "scheduler": self.scheduler,
        }


def entry_model(cfg: Post2Settings) -> TrajectoryModel:
    """The estimator's 3-DOF model over [position, velocity] only (nominal model inputs, no events):
    the member propagation of the entry phase."""
    return TrajectoryModel(TRANSLATION, 3, build.environment(cfg), build.vehicle(cfg))


def delivered_covariance(cfg: Post2Settings) -> np.ndarray:
    """The ``[monte_carlo] covariance`` (6, 6) in SI (m², m²/s, m²/s², checked symmetric positive
    definite by the settings); without it the diagonal of the position/velocity states' 1σ."""
    if cfg.monte_carlo.covariance is None:
        pos, vel = cfg.state("position"), cfg.state("velocity")
        return np.diag(np.concatenate([pos.sigma, vel.sigma]) ** 2)
    return cfg.monte_carlo.covariance


def dispersed_members(mean: np.ndarray, cov: np.ndarray, n: int, seed: int) -> np.ndarray:
    """(n, 6) states ``mean + L z`` (L L' = cov, z ~ N(0, I) from ``seed``); member 0 is the mean."""
    z = np.random.default_rng(seed).standard_normal((n, 6))
    z[0] = 0.0
    return mean + z @ np.linalg.cholesky(cov).T


def propagate_axial_acceleration(
    model: TrajectoryModel, X: np.ndarray, t0: float, n_steps: int, h: float
) -> np.ndarray:
    """Axial acceleration [m/s²] (n, n_steps + 1) of members X (n, 6) [m, m/s, inertial] on the grid
    t0 + h k [s] (RK4 of step h, the entry phase: no events), by
    :meth:`~workbench.problems.post2.model.TrajectoryModel.axial_on_grid`."""
    times = [t0 + k * h for k in range(n_steps + 1)]  # the grid as the step-by-step loop has it
    return model.axial_on_grid(np.asarray(X, dtype=float), times, model.initial_phase(), h)


def _crossing(t: np.ndarray, a: np.ndarray, level: float) -> np.ndarray:
    """Time (n,) at which |a| (n, m) on times t (m,) rises through ``level`` on the pulse's leading
    edge: a least-squares line through ln|a| of the samples between level/2 and 2·level before |a|
    first exceeds 2·level (the edge grows exponentially with the density), solved for ``level``;
    robust to sensor noise where one noisy sample crossing the level is not (nan: no such edge)."""
    mag = np.abs(a)
    first_hi = np.where(np.any(mag > 2.0 * level, axis=-1), np.argmax(mag > 2.0 * level, axis=-1), mag.shape[-1])
    before = np.arange(mag.shape[-1])[None, :] < first_hi[:, None]
    w = (before & (mag >= 0.5 * level) & (mag <= 2.0 * level)).astype(float)
    nw = w.sum(axis=-1)
    y = np.log(np.maximum(mag, 1e-300))
    tb = (w * t).sum(axis=-1) / np.maximum(nw, 1.0)
    yb = (w * y).sum(axis=-1) / np.maximum(nw, 1.0)
    dt = t[None, :] - tb[:, None]
    slope = (w * dt * (y - yb[:, None])).sum(axis=-1) / np.maximum((w * dt * dt).sum(axis=-1), 1e-300)
    tc = tb + (math.log(level) - yb) / np.where(slope > 0, slope, np.nan)
    return np.where((nw >= 2) & (slope > 0), tc, np.nan)


def member_metrics(shared: tuple, start: int, stop: int, _seeds=None) -> tuple[np.ndarray, np.ndarray]:
    """Chunk task: metric and time shift Δ [s] of members ``start..stop`` (module docstring, steps
    2-4).  ``shared`` = (model, members (N, 6), t0, h, n_steps, obs t (m,), obs z (m,), level, end_s)."""
    model, X, t0, h, n_steps, tz, z, level, end = shared
    a = propagate_axial_acceleration(model, X[start:stop], t0, n_steps, h)
    return _metric(a, t0, h, tz, z, level, end, model.use_kernel)


def _metric(a, t0, h, tz, z, level, end, use_kernel: bool):
    tg = t0 + h * np.arange(a.shape[1])
    t_meas = _crossing(tz, z[None, :], level)[0]
    shift = _crossing(tg, a, level) - t_meas
    use = tz <= end + 1e-9
    tu, zu = tz[use], z[use]
    rows = np.arange(a.shape[0])[:, None]
    tu, zu = np.ascontiguousarray(tu, dtype=float), np.ascontiguousarray(zu, dtype=float)
    hi = a.shape[1] - 1.000001

    def total(sh):  # the numpy reference of the kernels' totals
        u = np.clip((tu[None, :] + sh[:, None] - t0) / h, 0.0, hi)
        k = np.floor(u).astype(int)
        f = u - k
        return np.sum(np.abs(zu[None, :] - (a[rows, k] * (1.0 - f) + a[rows, k + 1] * f)), axis=1)

    # the level crossing is the coarse alignment; refined to the smallest metric within ±1 s of it
    # (0.1 s, then 0.01 s): on the steep pulse 0.1 s of misalignment costs more than the noise
    shift = np.where(np.isfinite(shift), shift, np.nan)
    ok = np.isfinite(shift)
    base = np.where(ok, shift, 0.0)
    stages = [np.arange(-half, half + 0.5 * step, step) for half, step in ((1.0, 0.1), (0.1, 0.01))]
    if use_kernel:  # the same search in one compiled pass (tests/problems/post2/test_post2_kernels.py)
        ac = np.ascontiguousarray(a, dtype=float)
        order = np.argsort(-np.abs(zu), kind="stable")  # large residuals first: misfits stop early
        prune = np.all(np.isfinite(ac), axis=1) & bool(np.all(np.isfinite(zu)))
        start, metric, base = np.ascontiguousarray(base, dtype=float), np.empty(a.shape[0]), np.empty(a.shape[0])
        kernels.metric_search_kernel(ac, tu, zu, start, *stages, t0, h, hi, order, prune, metric, base)
    else:
        for offs in stages:
            m = np.stack([total(base + d) for d in offs], axis=1)
            base = base + offs[np.argmin(m, axis=1)]
        metric = total(base)
    return np.where(ok, metric, np.inf), np.where(ok, base, np.nan)


def member_loop_metric(model: TrajectoryModel, X: np.ndarray, t0, h, n_steps, tz, z, level, end):
    """The same maths one member at a time (the benchmark's per-member loop): (metric, shift) (n,)."""
    m = np.empty(X.shape[0])
    s = np.empty(X.shape[0])
    for i in range(X.shape[0]):
        a = propagate_axial_acceleration(model, X[i : i + 1], t0, n_steps, h)
        mi, si = _metric(a, t0, h, tz, z, level, end, model.use_kernel)
        m[i], s[i] = mi[0], si[0]
    return m, s


def _move(model: TrajectoryModel, X: np.ndarray, t0: float, dt: np.ndarray, h: float) -> np.ndarray:
    """Members X (n, 6) moved along their own trajectories by dt (n,) [s] (either sign; RK4 ≤ h)."""
    n = max(1, int(math.ceil(np.max(np.abs(dt)) / h))) if dt.size else 1
    y = np.array(X, dtype=float)
    phase = model.initial_phase()
    step = dt / n
    for _ in range(n):  # each member its own (signed) step: the classic RK4 with a per-row dt

        def f(z):
            return model.derivative(z, phase)

        k1 = f(y)
        k2 = f(y + 0.5 * step[:, None] * k1)
        k3 = f(y + 0.5 * step[:, None] * k2)
        k4 = f(y + step[:, None] * k3)
        y = y + step[:, None] / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return y


def select_initial_state(
    cfg: Post2Settings,
    channel,
    members: int,
    seed: int,
    scheduler: str | None = None,
    extra_members: np.ndarray | None = None,
) -> McSelection:
    """Run the selection (module docstring) on the observation ``channel`` (a
    :class:`~workbench.problems.post2.pipeline.Channel` of axial acceleration, its raw samples)
    with ``members`` dispersed states (plus ``extra_members`` (k, 6) appended, for tests);
    in-process and vectorised, or chunked on a Dask ``scheduler``."""
    mc = cfg.monte_carlo
    if channel.spec.quantity != "acceleration_axial":
        raise ScenarioError(cfg.run.path, "monte_carlo.observation", "must name an acceleration_axial observation")
    end = mc.end_s if mc.end_s is not None else float(channel.t[-1])
    h = float(mc.step_s)  # > 0 (the schema's bound)
    level = float(mc.align_level_m_s2)
    tz, z = np.asarray(channel.t, float), np.asarray(channel.z_raw[:, 0], float)
    if not np.any(np.abs(z[tz <= end]) >= level):
        raise ScenarioError(
            cfg.run.path, "monte_carlo.align_level_m_s2",
            f"the observation {channel.spec.name!r} never reaches {level:g} m/s² before end_s = {end:g} s",
        )  # fmt: skip
    mean = np.concatenate([cfg.state("position").value, cfg.state("velocity").value])
    X = dispersed_members(mean, delivered_covariance(cfg), members, seed)
    if extra_members is not None:
        X = np.vstack([X, extra_members])
    model = entry_model(cfg)
    margin = 60.0  # members cross the alignment level up to ~1 min before / after the measured one
    n_steps = int(math.ceil((end + margin - cfg.t_start) / h))
    shared = (model, X, cfg.t_start, h, n_steps, tz, z, level, end)
    t0 = time.perf_counter()
    if scheduler is None:
        metric, shift = member_metrics(shared, 0, X.shape[0])
        desc = "in-process, vectorised over members"
    else:
        run = run_monte_carlo(
            member_metrics, X.shape[0], shared=shared, chunk_size=max(1, X.shape[0] // 8), scheduler=scheduler,
            name="post2-mc-initial-state",
        )  # fmt: skip
        metric = np.concatenate([r[0] for r in run.results])
        shift = np.concatenate([r[1] for r in run.results])
        desc = f"{scheduler} (chunks of {max(1, X.shape[0] // 8)})"
    wall = time.perf_counter() - t0
    if not np.any(np.isfinite(metric)):
        raise ScenarioError(cfg.run.path, "monte_carlo", "no member reached the alignment level: widen end_s")
    keep = max(1, min(int(mc.keep), X.shape[0]))
    kept = np.argsort(metric, kind="stable")[:keep]
    moved = _move(model, X[kept], cfg.t_start, shift[kept], h)
    sigma0 = np.std(moved, axis=0, ddof=1) if keep > 1 else np.sqrt(np.diag(delivered_covariance(cfg)))
    floor = np.empty(sigma0.size)
    floor[POSITION], floor[VELOCITY] = 10.0, 0.01  # floors: 10 m, 1 cm/s
    sigma0 = np.maximum(sigma0, floor)
    d = moved[0] - mean
    maha = float(np.sqrt(d @ np.linalg.solve(delivered_covariance(cfg), d)))
    return McSelection(X, metric, shift, kept, moved[0], sigma0, float(metric[0]), mean, wall, desc, maha)


def reconstruct(cfg: Post2Settings, telemetry, options):
    """The post2 stages with, when ``[monte_carlo] members`` (or ``options.members``) > 0, the
    :class:`McSelection` stage first (reported, a health note); the EKF starts from the delivered
    state with the full ``[monte_carlo] covariance`` when one is given (:func:`start_from_delivered`)."""
    mc = cfg.monte_carlo
    n = options.members if getattr(options, "members", None) is not None else int(mc.members)
    start = start_from_delivered(cfg) if mc.covariance is not None else cfg
    if n > 0:
        if mc.observation is None or mc.observation not in {o.name for o in cfg.observations}:
            raise ScenarioError(
                cfg.run.path, "monte_carlo.observation",
                f"{mc.observation!r} is not one of the declared observations",
            )  # fmt: skip
        data = pipeline.read_observations(cfg, telemetry)
        seed = int(mc.seed) + (int(options.seed) if getattr(options, "seed", None) is not None else 0)
        sel = select_initial_state(cfg, data.channels[mc.observation], n, seed, getattr(options, "scheduler", None))
        yield sel
        for stage in pipeline.reconstruct(start, telemetry, options):
            if isinstance(stage, pipeline.Post2Result):
                stage.summary["mc_initial_state"] = sel.summary()
                stage.summary["health"]["notes"].append(selection_note(sel))
            yield stage
        return
    yield from pipeline.reconstruct(start, telemetry, options)


def selection_note(sel: McSelection) -> str:
    """The health note of the selection stage: what it found and why the EKF does not start from it."""
    s = sel.summary()
    return (
        f"Monte Carlo initial state: best of {s['members']} members metric {s['best_metric']:.4g} (delivered "
        f"state {s['nominal_metric']:.4g}), {sel.mahalanobis:.2f} σ (Mahalanobis) from the delivered state; not "
        "used as the EKF's start: its metric is the nominal model's residual (the model's CA and atmosphere "
        "errors move its minimum) and its kept members' spread is not the state's uncertainty; the EKF starts "
        "from the delivered state and covariance and assimilates the entry accelerometer once"
    )


def start_from_delivered(cfg: Post2Settings) -> Post2Settings:
    """The settings with the EKF's initial position and velocity the delivered state (the states'
    values) and their initial covariance the full delivered one (:func:`delivered_covariance`, SI):
    1σ its diagonal's root, its correlations added to ``[initial_correlation]`` (block-diagonal with
    any correlations the file already gives; position and velocity must not be among those)."""
    C = delivered_covariance(cfg)
    sd = np.sqrt(np.diag(C))
    corr = C / np.outer(sd, sd)
    out = cfg.with_state("position", sigma=sd[POSITION].copy()).with_state("velocity", sigma=sd[VELOCITY].copy())
    names, mat = ("position", "velocity"), corr
    if cfg.initial_correlation is not None:
        old_names, old = cfg.initial_correlation
        if set(old_names) & set(names):
            raise ScenarioError(
                cfg.run.path, "initial_correlation.states",
                "position/velocity correlations come from [monte_carlo] covariance; do not list them here",
            )  # fmt: skip
        n0 = old.shape[0]
        mat = np.eye(n0 + 6)
        mat[:n0, :n0] = old
        mat[n0:, n0:] = corr
        names = (*old_names, *names)
    return dataclasses.replace(out, initial_correlation=(tuple(names), mat))


def start_from(cfg: Post2Settings, sel: McSelection) -> Post2Settings:
    """The settings with the EKF's initial position and velocity (and their 1σ) from the selection
    ``sel`` (SI, inertial): :func:`dataclasses.replace` of the two states."""
    out = cfg.with_state("position", value=sel.x0[POSITION].copy(), sigma=sel.sigma0[POSITION].copy())
    return out.with_state("velocity", value=sel.x0[VELOCITY].copy(), sigma=sel.sigma0[VELOCITY].copy())


# ------------------------------------------------------------------ scorecard
def planted_table(result, truth: dict) -> list[dict]:
    """Planted vs recovered, one row per estimated parameter with a planted truth value: the final
    smoothed value and 3σ, the error, the tolerance (``[truth.tolerances]``, if any), and
    ``inside_3sigma``, ``within_tolerance``, ``informed`` (final posterior σ below
    :data:`~workbench.problems.post2.pipeline.INFORMED_RATIO` × the prior's, ``sigma_ratio``), ``pass``
    (all three: a row the data did not inform never passes); values in the state's unit (deg for tilt)."""
    rows = []
    hist = result.history["smoothed"]
    for name in result.smap.blocks:
        d = STATES[name]
        if d.dynamic or f"param_{name}" not in truth:
            continue
        k = 1.0 / unit_factor(d.unit)
        tv = np.atleast_1d(truth[f"param_{name}"]).astype(float)
        v, s = hist[name]["value"][-1], hist[name]["sigma"][-1]
        i = 0  # scalar parameters; the bias: its axial (x) component
        err = float(v[i] - tv[i])
        tol = truth.get(f"tol_{name}")
        inside = abs(err) <= 3.0 * float(s[i])
        within = None if tol is None else abs(err) <= float(np.atleast_1d(tol)[0])
        st = result.summary["states"][name]
        ratio = float(st["posterior_over_prior_sigma"][i])
        informed = bool(st["informed_by_data"][i])
        rows.append(
            {
                "parameter": name + ("_x" if d.size > 1 else ""),
                "unit": d.unit,
                "planted": float(tv[i] * k),
                "recovered": float(v[i] * k),
                "error": err * k,
                "three_sigma": float(3.0 * s[i] * k),
                "tolerance": None if tol is None else float(np.atleast_1d(tol)[0] * k),
                "inside_3sigma": bool(inside),
                "within_tolerance": within,
                "sigma_ratio": ratio,
                "informed": informed,
                "pass": bool(inside and (within is None or within) and informed),
            }
        )
    return rows


def planted_markdown(rows: list[dict]) -> str:
    """The planted-vs-recovered table in Markdown: per row PASS, FAIL (why) or "not informed by the
    data" (posterior σ not below INFORMED_RATIO × the prior's: the row reports the prior)."""
    md = "\n## Planted vs recovered\n\n| parameter | planted | recovered | error | 3σ | tolerance |"
    md += " posterior/prior σ | verdict |\n|---|---|---|---|---|---|---|---|\n"
    for r in rows:
        tol = "—" if r["tolerance"] is None else f"{r['tolerance']:.4g}"
        why = [] if r["inside_3sigma"] else ["outside 3σ"]
        if r["within_tolerance"] is False:
            why.append("outside tolerance")
        if why:
            verdict = "**FAIL** (" + ", ".join(why) + ")"
        elif not r["informed"]:
            verdict = f"not informed by the data (posterior σ ≥ {pipeline.INFORMED_RATIO:g} × prior)"
        else:
            verdict = "PASS"
        md += (
            f"| {r['parameter']} [{r['unit']}] | {r['planted']:.5g} | {r['recovered']:.5g} | {r['error']:+.3g} |"
            f" {r['three_sigma']:.3g} | {tol} | {r['sigma_ratio']:.2f} | {verdict} |\n"
        )
    return md
