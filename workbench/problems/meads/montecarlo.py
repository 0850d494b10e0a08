"""The MEADS total-system trade study (paper Sect. IV.B.1, Fig. 6), vectorised over runs.

As the paper: surface pressures from the **Newtonian** model at the true flight condition of the
reference trajectory (here the truth simulator's ``msl_meads`` entry), a random multiplicative
error of 0.5, 1, 2.5 and 5 % of reading (N(0, level) per port and sample), and the least-squares
estimator with a **fixed pressure ratio R = 0.001** (q∞, α, β; q∞ from the limit of R M²).  Mach
is not part of that estimator; its 3σ comes from the (q∞, α, β, M) fit of the same pressures
(the paper's Fig. 6 shows it is not observable at high Mach).

Every run k draws ε ~ N(0, 1) (samples × ports) from ``SeedSequence(seed, spawn_key=(k,))``; all
levels scale the same ε (common random numbers).  Runs are fitted in chunks of
:data:`CHUNK` — each chunk one stacked WLS problem of ``runs × samples`` rows — on the shared
executor (:func:`workbench.estimation.montecarlo.run_monte_carlo`: loop, processes or Dask);
chunks return per-sample sums of the error and its square, reduced in run order, so the result
does not depend on the executor.  Mach on every :data:`MACH_EVERY`-th sample only (the
4-state fit is the expensive one).  3σ = 3 × the standard deviation over the runs (the bias from R
≠ 0.001 is reported apart).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.estimation.montecarlo import run_monte_carlo
from workbench.models.flush_airdata import FadsVehicle
from workbench.problems.meads.airdata import fit_air_data, pressure_model
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.pipeline import sensor_sigma
from workbench.problems.meads.truth import simulate_entry

__all__ = [
    "CHUNK",
    "OBJECTIVES",
    "TradeShared",
    "TradeStudy",
    "prepare_trade_study",
    "run_trade_study",
    "level_name",
]

CHUNK = 100
#: The Mach-set fit is done on every MACH_EVERY-th trade-study sample.
MACH_EVERY = 4
#: The MEADS science objectives (3σ): α, β [deg], q∞ [%], Mach (paper Sect. I).
OBJECTIVES = {"alpha_deg": 0.5, "beta_deg": 0.5, "qbar_pct": 2.0, "mach": 0.1}
QUANTITIES = ("alpha_deg", "beta_deg", "qbar_pct", "mach")


@dataclass(frozen=True)
class TradeShared:
    """What every chunk needs: sample times ``t`` (n,), the true state (n,) ``qbar``, ``alpha``,
    ``beta``, ``mach``, the Newtonian pressures ``p_true`` (n, m), the vehicle, γ, ``levels``,
    ``fixed_r`` and ``mach_fit`` (also fit the Mach set)."""

    t: np.ndarray
    qbar: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    mach: np.ndarray
    p_true: np.ndarray
    vehicle: FadsVehicle
    gamma: float
    levels: tuple[float, ...]
    fixed_r: float
    mach_fit: bool = True


def _errors(sh: TradeShared, eps: np.ndarray, level: float) -> np.ndarray:
    """Errors (runs, n, 4) of α [deg], β [deg], q∞ [%], Mach for stacked draws ``eps`` (runs, n, m)."""
    r, n, m = eps.shape
    p = (sh.p_true[None] * (1.0 + level * eps)).reshape(r * n, m)
    sig = sensor_sigma(p, sh.vehicle, level, bits=30)  # the estimator weights by the error level
    tile = np.tile
    f = fit_air_data(
        p,
        sig,
        sh.vehicle,
        model="newtonian",
        solution="fixed_r",
        gamma=sh.gamma,
        mach_guess=tile(sh.mach, r),
        fixed_r=sh.fixed_r,
        iterations=8,
    )
    e = np.empty((r, n, 4))
    e[..., 0] = np.degrees(f.alpha.reshape(r, n) - sh.alpha)
    e[..., 1] = np.degrees(f.beta.reshape(r, n) - sh.beta)
    e[..., 2] = 100.0 * (f.qbar.reshape(r, n) / sh.qbar - 1.0)
    e[..., 3] = np.nan
    if sh.mach_fit:  # on every MACH_EVERY-th sample only (it is the expensive, 4-state fit)
        k = np.arange(0, n, MACH_EVERY)
        pk = p.reshape(r, n, m)[:, k].reshape(-1, m)
        sk = sig.reshape(r, n, m)[:, k].reshape(-1, m)
        g = fit_air_data(
            pk,
            sk,
            sh.vehicle,
            model="newtonian",
            solution="mach",
            gamma=sh.gamma,
            mach_guess=tile(sh.mach[k], r),
            fixed_r=0.0,  # not used by the Mach set
            iterations=8,
        )
        e[:, k, 3] = g.mach.reshape(r, k.size) - sh.mach[k]
    return e


def _task(sh: TradeShared, a: int, b: int, seeds) -> dict:
    """One chunk of runs a..b−1: per level the sums over the runs of e and e² (n, 4)."""
    n, m = sh.p_true.shape
    eps = np.stack([np.random.default_rng(s).standard_normal((n, m)) for s in seeds])
    out = {}
    for lv in sh.levels:
        e = _errors(sh, eps, lv)
        out[lv] = (np.nansum(e, axis=0), np.nansum(e * e, axis=0), np.sum(np.isfinite(e), axis=0))
    return out


@dataclass(frozen=True)
class TradeStudy:
    """Result: ``t`` (n,), ``mach`` (n,) true Mach, ``qbar`` (n,) true q∞, per level ``three_sigma``
    and ``bias`` (n, 4) (α deg, β deg, q∞ %, Mach), the ``summary`` (JSON-ready), ``wall_s``."""

    t: np.ndarray
    mach: np.ndarray
    qbar: np.ndarray
    levels: tuple[float, ...]
    three_sigma: dict
    bias: dict
    summary: dict
    wall_s: float


#: The trade study's samples: true q∞ at least this [Pa] (below the objectives' 850 Pa, to draw the curves).
TRADE_MIN_QBAR_PA = 400.0


def prepare_trade_study(settings: MeadsSettings) -> TradeShared:
    """The reference trajectory (truth simulator of ``settings.truth``, no sensor errors) sampled
    every ``settings.mc.stride``-th pressure time where the true q∞ ≥ :data:`TRADE_MIN_QBAR_PA`,
    before the parachute (vary the stride with ``dataclasses.replace`` on ``settings.mc``)."""
    cfg = settings
    vehicle = cfg.vehicle
    truth = simulate_entry(vehicle, cfg.truth)
    stride, min_qbar = cfg.mc.stride, TRADE_MIN_QBAR_PA
    t = np.arange(0.0, truth.t[-1], stride / cfg.pressure.rate_hz)
    f = {k: np.interp(t, truth.t, getattr(truth, k)) for k in ("qbar", "alpha", "beta", "mach")}
    sel = (f["qbar"] >= min_qbar) & (t < truth.t_chute)
    f = {k: v[sel] for k, v in f.items()}
    x = np.stack([f["qbar"], f["alpha"], f["beta"], f["mach"]], 1)
    gamma = cfg.estimator.gamma
    p_true = pressure_model(vehicle, "newtonian", "mach", gamma)(x)
    return TradeShared(
        t[sel], f["qbar"], f["alpha"], f["beta"], f["mach"], p_true, vehicle, gamma, cfg.mc.levels, cfg.mc.fixed_r
    )


def run_trade_study(
    sh: TradeShared, runs: int, seed: int, *, workers: int = 1, scheduler: str | None = None, progress=None
) -> TradeStudy:
    """``runs`` runs per level on the executor; 3σ and bias per sample and the objectives' table."""
    mc = run_monte_carlo(
        _task,
        runs,
        shared=sh,
        seed=seed,
        chunk_size=CHUNK,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        name="meads-trade",
    )
    n = sh.t.size
    three, bias, table = {}, {}, {}
    above = sh.qbar >= 850.0
    for lv in sh.levels:
        s1 = np.zeros((n, 4))
        s2 = np.zeros((n, 4))
        cnt = np.zeros((n, 4))
        for res in mc.results:  # run order: independent of the executor
            a, b, c = res[lv]
            s1 += a
            s2 += b
            cnt += c
        mean = s1 / np.maximum(cnt, 1)
        var = np.maximum(s2 / np.maximum(cnt, 1) - mean**2, 0.0) * cnt / np.maximum(cnt - 1, 1)
        none = cnt == 0  # Mach: samples without the 4-state fit
        three[lv] = np.where(none, np.nan, 3.0 * np.sqrt(var))
        bias[lv] = np.where(none, np.nan, mean)
        row = {}
        for j, q in enumerate(QUANTITIES):
            v = three[lv][above, j]
            fin = np.isfinite(v)
            v, b_ = v[fin], mean[above, j][fin]
            row[q] = {
                "max_3sigma": float(np.max(v)),
                "median_3sigma": float(np.median(v)),
                "max_abs_bias": float(np.max(np.abs(b_))),
                "objective": OBJECTIVES[q],
                "met": bool(np.max(v) <= OBJECTIVES[q]),
                "fraction_of_samples_met": float(np.mean(v <= OBJECTIVES[q])),
                "samples": int(v.size),
            }
        # Mach at Mach < 5 (where the paper's Fig. 6 shows it observable)
        lo = above & (sh.mach < 5.0)
        if lo.any():
            row["mach"]["max_3sigma_below_mach5"] = float(np.nanmax(three[lv][lo, 3]))
        table[f"{100 * lv:g}%"] = row
    summary = {
        "runs_per_level": runs,
        "levels_pct": [100 * lv for lv in sh.levels],
        "fixed_r": sh.fixed_r,
        "samples": int(n),
        "samples_above_850pa": int(above.sum()),
        "executor": mc.executor,
        "workers": mc.workers,
        "wall_s": mc.wall_s,
        "objectives_3sigma": OBJECTIVES,
        "table": table,
    }
    return TradeStudy(sh.t, sh.mach, sh.qbar, sh.levels, three, bias, summary, mc.wall_s)


def level_name(level: float) -> str:
    """Entity-safe name of an error level: 0.005 -> '0.5pct'."""
    return f"{100 * level:g}pct"
