"""Health verdict of a reconstruction: is the answer trustworthy, or silently wrong?

One home for the checks every problem composes (``problems/<p>/health.py`` or its pipeline):

* :func:`nis_check` — innovation statistics of one sensor against χ² bounds (Bar-Shalom, Li &
  Kirubarajan 2001, Sect. 5.4, the normalised innovation squared): a mean NIS far above its
  dimension means the filter is inconsistent with that sensor (wrong unit, wrong noise, wrong
  model) → ERROR; a mean NIS off by more than a factor 2 in variance → WARNING;
* :func:`covariance_check` — covariance history symmetric and positive definite (the per-step
  numbers from :func:`covariance_stats`);
* :func:`interval_check` — a physical quantity inside its plausible interval (stroke within the
  bag geometry, restitution up to its energy bound, altitude and speed inside the scenario's envelope, ...);
* :func:`gap_check` — data gaps across the events that matter (contact, parachute deployment);
* :func:`notes_check` — warnings the input readers reported.

:func:`health_report` turns the checks into the summary's ``"health"`` entry::

    {"verdict": "OK" | "WARNING" | "ERROR",
     "checks": [{"name", "status", "value", "bound", "message"}, ...]}

The verdict is the worst status.  The runner refuses to publish an ERROR run
(:class:`UnhealthyError`, exit code 6) unless asked to (``--allow-unhealthy``), and then marks it.
A new problem adopts it in a few lines: build its list of :class:`Check` with these functions and
put ``health_report(checks)`` into its summary under ``"health"``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from workbench.estimation.consistency import chi2_ppf

__all__ = [
    "finite_steps",
    "short_paths",
    "OK",
    "WARNING",
    "ERROR",
    "Check",
    "UnhealthyError",
    "covariance_check",
    "exact_components",
    "covariance_stats",
    "gap_check",
    "health_markdown",
    "health_report",
    "interval_check",
    "nis_check",
    "notes_check",
    "verdict",
]

OK, WARNING, ERROR = "OK", "WARNING", "ERROR"
_RANK = {OK: 0, WARNING: 1, ERROR: 2}


@dataclass(frozen=True)
class Check:
    """One health check: ``name`` (e.g. ``"nis.BP"``), ``status`` (OK/WARNING/ERROR), the measured
    ``value`` (a number, SI, or None), the ``bound`` it was held against (a number, a
    ``[lo, hi]`` pair, or None) and a human ``message`` that says what it means.  ``stat``: how a
    truth-Monte-Carlo calibration re-judges the value (:mod:`workbench.estimation.calibration`):
    ``{"kind": "nis", "dof": k}``, ``{"kind": "upper"}`` (large is bad) or ``{"kind": "two_sided"}``;
    None for a check whose bound is physics, not a statistic of the filter."""

    name: str
    status: str
    value: Any
    bound: Any
    message: str
    stat: Any = None

    def __post_init__(self) -> None:
        if self.status not in _RANK:
            raise ValueError(f"check {self.name!r}: status must be OK, WARNING or ERROR, got {self.status!r}")


class UnhealthyError(RuntimeError):
    """A reconstruction whose health verdict is ERROR (nothing was published).  ``health`` is the
    summary's ``"health"`` dict, ``where`` the scenario."""

    def __init__(self, where: str, health: dict):
        self.where = str(where)
        self.health = health
        bad = [c for c in health.get("checks", []) if c["status"] == ERROR]
        lines = "\n".join(f"  - {c['name']}: {c['message']}" for c in bad)
        super().__init__(
            f"{self.where}: health verdict ERROR — the reconstruction is not trustworthy:\n{lines}\n"
            "nothing was written; rerun with --allow-unhealthy to write the outputs anyway (marked UNHEALTHY)"
        )

    def __reduce__(self):
        return (type(self), (self.where, self.health))


def _f(x: float) -> float:
    return float(f"{float(x):.6g}")


def _banded(name: str, status: str, value: float, lo: float, hi: float, message: str, stat: Any = None) -> Check:
    """A :class:`Check` of ``value`` against the interval [``lo``, ``hi``] (all three rounded to
    6 significant digits for the summary), with ``status``, ``message`` and ``stat``."""
    return Check(name, status, _f(value), [_f(lo), _f(hi)], message, stat)


def nis_check(sensor: str, nis: np.ndarray, dof: int, *, error_quantile: float = 0.999) -> Check:
    """Mean NIS of one sensor's innovations ``nis`` (n,) of dimension ``dof`` against χ² bounds.

    ERROR when the mean exceeds both the ``error_quantile`` of a *single* χ²(dof) sample (for
    dof = 3 and 0.999: 16.3, i.e. the average innovation as large as a 3.3σ outlier) and the 99 %
    band of the mean of n independent samples; WARNING when the mean lies outside
    [min(0.5·dof, band_lo), max(2·dof, band_hi)] (a factor 2 in variance; innovations of a smoothed
    physical process are correlated, so the band of independent samples alone would be too strict).
    """
    nis = np.asarray(nis, float)
    nis = nis[np.isfinite(nis)]
    name = f"nis.{sensor}"
    stat = {"kind": "nis", "dof": int(dof)}
    if nis.size == 0:
        return Check(name, WARNING, None, None, f"sensor {sensor}: no innovation was processed")
    n, mean = nis.size, float(np.mean(nis))
    band = (float(chi2_ppf(0.005, n * dof) / n), float(chi2_ppf(0.995, n * dof) / n))
    err_hi = max(float(chi2_ppf(error_quantile, dof)), band[1])
    lo, hi = min(0.5 * dof, band[0]), max(2.0 * dof, band[1])
    if mean > err_hi:
        return Check(
            name,
            ERROR,
            _f(mean),
            _f(err_hi),
            f"filter inconsistent with sensor {sensor}: mean NIS {mean:.3g} over {n} samples against {dof} "
            f"expected (bound {err_hi:.3g}) — a wrong unit, noise level or model for this sensor?",
            stat,
        )
    if not lo <= mean <= hi:
        side = "conservative (R or Q too large)" if mean < lo else "optimistic (R or Q too small)"
        message = f"sensor {sensor}: mean NIS {mean:.3g} over {n} samples, expected {dof} — the filter is {side}"
        return _banded(name, WARNING, mean, lo, hi, message, stat)
    return _banded(name, OK, mean, lo, hi, f"sensor {sensor}: mean NIS {mean:.3g} (expected {dof})", stat)


#: covariance steps examined at once by :func:`covariance_stats` (bounds its temporaries)
_CHUNK_STEPS = 256


def finite_steps(A: np.ndarray) -> np.ndarray:
    """(n,) bool: True where every entry of step k of a history ``A`` (n, ...) — a state (n, n_x) or
    a covariance (n, k, k) — is finite. Computed over chunks of steps, so that a long covariance
    history needs no (n, k, k) boolean temporary."""
    A = np.asarray(A)
    out = np.empty(A.shape[0], bool)
    axes = tuple(range(1, A.ndim))
    for a in range(0, A.shape[0], _CHUNK_STEPS):
        out[a : a + _CHUNK_STEPS] = np.all(np.isfinite(A[a : a + _CHUNK_STEPS]), axis=axes)
    return out


def covariance_stats(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per step of a finite covariance history ``P`` (n, k, k): the largest absolute asymmetry
    ``max|P − Pᵀ|`` (units of P), the same relative to the largest diagonal entry, and the smallest
    eigenvalue of the symmetric part; three (n,) arrays.  Computed over chunks of steps so that a
    long history needs no (n, k, k) temporaries."""
    n = P.shape[0]
    asym_abs, asym_rel, emin = np.empty(n), np.empty(n), np.empty(n)
    for a in range(0, n, _CHUNK_STEPS):
        Pc = P[a : a + _CHUNK_STEPS]
        Pt = np.swapaxes(Pc, 1, 2)
        scale = np.maximum(np.max(np.abs(np.einsum("nii->ni", Pc)), axis=1), 1e-300)
        asym_abs[a : a + _CHUNK_STEPS] = np.max(np.abs(Pc - Pt), axis=(1, 2))
        asym_rel[a : a + _CHUNK_STEPS] = asym_abs[a : a + _CHUNK_STEPS] / scale
        emin[a : a + _CHUNK_STEPS] = np.min(np.linalg.eigvalsh(0.5 * (Pc + Pt)), axis=1)
    return asym_abs, asym_rel, emin


#: every this many steps :func:`_smallest_eigenvalues_screened` computes the eigenvalues outright
_SCREEN_STRIDE = 8


def _relative_asymmetry(P: np.ndarray) -> np.ndarray:
    """``max|P − Pᵀ|`` / the largest |diagonal entry| per step of ``P`` (n, k, k): the second
    output of :func:`covariance_stats`, over the same chunks."""
    n = P.shape[0]
    out = np.empty(n)
    for a in range(0, n, _CHUNK_STEPS):
        Pc = P[a : a + _CHUNK_STEPS]
        scale = np.maximum(np.max(np.abs(np.einsum("nii->ni", Pc)), axis=1), 1e-300)
        out[a : a + _CHUNK_STEPS] = np.max(np.abs(Pc - np.swapaxes(Pc, 1, 2)), axis=(1, 2)) / scale
    return out


def _not_positive_definite(S: np.ndarray) -> np.ndarray:
    """(m,) True where the Cholesky factorisation of the symmetric ``S`` (m, k, k) fails: one
    batched factorisation, halved recursively around the failures (they are few)."""
    try:
        np.linalg.cholesky(S)
        return np.zeros(S.shape[0], bool)
    except np.linalg.LinAlgError:
        if S.shape[0] == 1:
            return np.ones(1, bool)
    h = S.shape[0] // 2
    return np.concatenate([_not_positive_definite(S[:h]), _not_positive_definite(S[h:])])


def _smallest_eigenvalues_screened(P: np.ndarray) -> np.ndarray:
    """Per step of ``P`` (n, k, k) the smallest eigenvalue of its symmetric part exactly as
    :func:`covariance_stats` computes it wherever it can decide :func:`covariance_check` (the
    minimum, its step, the steps ≤ 0), +inf at the other steps.  The eigenvalues of every
    :data:`_SCREEN_STRIDE`-th step give a candidate minimum μ > 0; a step whose symmetric part
    minus (μ + δ) I has a Cholesky factor has its smallest eigenvalue above μ (δ = 1e-10 k
    max|diag| exceeds the factorisation's backward error), the others are computed outright.
    Every step is computed when the screen cannot pay: small matrices (k < 10), μ ≤ 0, or δ ≥ μ
    (states of very different scales: the smallest eigenvalue is at the round-off of the largest)."""
    n, k = P.shape[0], P.shape[1]
    if n <= _SCREEN_STRIDE or k < 10:
        return covariance_stats(P)[2]
    out = np.full(n, np.inf)
    sample = np.arange(0, n, _SCREEN_STRIDE)
    for a in range(0, sample.size, _CHUNK_STEPS):
        Pc = P[sample[a : a + _CHUNK_STEPS]]
        out[sample[a : a + _CHUNK_STEPS]] = np.min(np.linalg.eigvalsh(0.5 * (Pc + np.swapaxes(Pc, 1, 2))), axis=1)
    mu = float(np.min(out[sample]))
    delta = 1e-10 * k * float(np.max(np.abs(np.einsum("nii->ni", P))))
    if not (mu > 0.0 and delta < mu):
        return covariance_stats(P)[2]
    tau = mu + delta
    rest = np.setdiff1d(np.arange(n), sample)
    for a in range(0, rest.size, _CHUNK_STEPS):
        idx = rest[a : a + _CHUNK_STEPS]
        Pc = P[idx]
        S = 0.5 * (Pc + np.swapaxes(Pc, 1, 2))
        low = _not_positive_definite(S - tau * np.eye(k))
        if low.any():
            out[idx[low]] = np.min(np.linalg.eigvalsh(S[low]), axis=1)
    return out


def covariance_check(
    P: np.ndarray,
    name: str = "covariance",
    *,
    rtol: float = 1e-6,
    stats: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    labels: Sequence[str] | None = None,
) -> Check:
    """Covariance history ``P`` (n, k, k) (or one (k, k)): symmetric to ``rtol`` relative to its
    largest diagonal entry and positive definite at every step; ERROR otherwise (value: the smallest
    eigenvalue over the history). Where the smallest eigenvalue is ≤ 0 the correlation matrices of
    those steps decide (their eigenvalues do not depend on the states' units): all > 0 is OK (value:
    their smallest), within :data:`ROUNDOFF_CORRELATION_EIGENVALUE` of 0 a WARNING (semi-definite to
    round-off), below that an ERROR.  Components known exactly at every step (an all-zero row and
    column, :func:`exact_components`: an error declared absent) are left out and named (by
    ``labels``, one per component — e.g. the setting behind it — when given).  ``stats``:
    :func:`covariance_stats` of ``P`` when the caller has them already (not computed again); without
    them the eigenvalues are computed only at the steps that can decide the check (the same check)."""
    P = np.asarray(P, float)
    if P.ndim == 2:
        P = P[None]
    fin = finite_steps(P)
    if not np.all(fin):
        bad = int(np.flatnonzero(~fin)[0])
        return Check(name, ERROR, None, None, f"{name}: not finite (first at step {bad})")
    exact = exact_components(P)
    if exact.size and exact.size < P.shape[1]:  # errors declared absent (σ = 0): checked on the others
        keep = np.setdiff1d(np.arange(P.shape[1]), exact)
        c = covariance_check(P[:, keep][:, :, keep], name, rtol=rtol)
        named = [str(int(i)) for i in exact] if labels is None else list(dict.fromkeys(labels[i] for i in exact))
        note = (
            f" ({exact.size} component(s) known exactly at every step — an error declared absent, σ = 0 and no "
            f"process noise — carried with zero variance: {', '.join(named)})"
        )
        return Check(c.name, c.status, c.value, c.bound, c.message + note)
    if stats is None:
        asym = float(np.max(_relative_asymmetry(P)))
        if asym > rtol:
            return Check(name, ERROR, _f(asym), rtol, f"{name}: not symmetric (relative asymmetry {asym:.2g})")
        emin_k = _smallest_eigenvalues_screened(P)
    else:
        _, asym_k, emin_k = stats
        asym = float(np.max(asym_k))
        if asym > rtol:
            return Check(name, ERROR, _f(asym), rtol, f"{name}: not symmetric (relative asymmetry {asym:.2g})")
    emin = float(np.min(emin_k))
    if emin <= 0.0:
        step = int(np.argmin(emin_k))
        bad = np.flatnonzero(emin_k <= 0.0)
        cmin = _correlation_min_eigenvalue(P[bad])
        if cmin > 0.0:  # the states' scales (e.g. m² beside 1e-8) made eigvalsh's round-off negative
            return Check(
                name,
                OK,
                _f(cmin),
                0.0,
                f"{name}: symmetric, positive definite over {P.shape[0]} steps (at {bad.size} step(s) only its "
                f"correlation matrix shows it, smallest eigenvalue {cmin:.2g}: the unscaled {emin:.3g} at step "
                f"{step} is round-off of the states' different scales)",
            )
        if cmin >= -ROUNDOFF_CORRELATION_EIGENVALUE:
            return Check(
                name,
                WARNING,
                _f(emin),
                0.0,
                f"{name}: positive semi-definite only to round-off at {bad.size} step(s) (eigenvalue {emin:.3g} at "
                f"step {step}; smallest eigenvalue of the correlation matrix {cmin:.2g}): a combination of the "
                "states is known to numerical precision (no process noise on it?)",
            )
        return Check(
            name, ERROR, _f(emin), 0.0, f"{name}: not positive definite (eigenvalue {emin:.3g} at step {step})"
        )
    return Check(name, OK, _f(emin), 0.0, f"{name}: symmetric, positive definite over {P.shape[0]} steps")


ROUNDOFF_CORRELATION_EIGENVALUE = 1e-9
"""A covariance whose smallest eigenvalue is ≤ 0 but whose correlation matrix D^-1/2 P D^-1/2 (unit
diagonal, so eigenvalues are free of the states' units) has its smallest eigenvalue within this of
zero is semi-definite to round-off (WARNING in :func:`covariance_check`); below −this it is
indefinite (ERROR)."""


def exact_components(P: np.ndarray) -> np.ndarray:
    """Indices of the components of a covariance history ``P`` (n, k, k) whose row and column are
    exactly zero at every step: errors declared absent (σ = 0, no process noise) that a filter
    carries as known; no estimated component has an exactly zero row."""
    zero = np.all(P == 0.0, axis=(0, 2)) & np.all(P == 0.0, axis=(0, 1))
    return np.flatnonzero(zero)


def _correlation_min_eigenvalue(P: np.ndarray) -> float:
    """Smallest eigenvalue [-] of the correlation matrices of the covariances ``P`` (m, k, k); −inf
    when a diagonal entry is ≤ 0 (no correlation matrix: not a covariance)."""
    d = np.einsum("nii->ni", P)
    if np.any(d <= 0.0) or P.shape[0] == 0:
        return -np.inf
    s = 1.0 / np.sqrt(d)
    C = P * s[:, :, None] * s[:, None, :]
    return float(np.min(np.linalg.eigvalsh(0.5 * (C + np.swapaxes(C, 1, 2)))))


def interval_check(
    name: str,
    value: float,
    lo: float,
    hi: float,
    what: str,
    unit: str = "",
    *,
    status: str = ERROR,
) -> Check:
    """``value`` of quantity ``what`` inside the plausible interval [``lo``, ``hi``] (SI, ``unit``
    for the message); ``status`` (default ERROR) otherwise, also for a non-finite value."""
    u = f" {unit}" if unit else ""
    v = float(value)
    if not np.isfinite(v):
        return Check(name, status, None, [lo, hi], f"{what}: not finite")
    if lo <= v <= hi:
        return _banded(name, OK, v, lo, hi, f"{what} {v:.4g}{u} within [{lo:.4g}, {hi:.4g}]{u}")
    return _banded(
        name, status, v, lo, hi, f"{what} {v:.4g}{u} is physically implausible (outside [{lo:.4g}, {hi:.4g}]{u})"
    )


def gap_check(
    name: str,
    gaps: Iterable[tuple[float, float]],
    windows: Mapping[str, tuple[float, float]],
    *,
    status: str = ERROR,
) -> Check:
    """Data gaps ``(start_s, end_s)`` against the time ``windows`` that matter ``{event: (t0, t1)}``
    (s): a gap overlapping a window gets ``status`` (the event is not observed); value: the longest
    such gap [s]."""
    hits = []
    for a, b in gaps:
        for ev, (t0, t1) in windows.items():
            if a < t1 and b > t0:
                hits.append((b - a, a, b, ev))
    if not hits:
        return Check(name, OK, 0.0, None, f"no data gap across {', '.join(windows) or 'any event'}")
    d, a, b, ev = max(hits)
    return Check(
        name,
        status,
        _f(d),
        0.0,
        f"a {d:.3g} s data gap ({a:.4f}–{b:.4f} s) lies across the {ev}: the reconstruction there is not observed",
    )


def notes_check(name: str, notes: Sequence[str]) -> Check:
    """WARNING when the input readers reported anything (``notes``, one line each), else OK."""
    if not notes:
        return Check(name, OK, 0, None, "no warning from the input readers")
    more = f" (and {len(notes) - 3} more)" if len(notes) > 3 else ""
    return Check(name, WARNING, len(notes), None, "; ".join(notes[:3]) + more)


def verdict(checks: Iterable[Check]) -> str:
    """The worst status of ``checks`` (OK when there are none)."""
    worst = OK
    for c in checks:
        if _RANK[c.status] > _RANK[worst]:
            worst = c.status
    return worst


def health_report(checks: Sequence[Check], notes: Sequence[str] = ()) -> dict:
    """``{"verdict": ..., "checks": [...], "notes": [...]}`` (JSON-ready) of ``checks``; ``notes``:
    facts a reviewer reads once, not anomalies (e.g. a filter conservative by design, with its
    measured factor)."""
    return {"verdict": verdict(checks), "checks": [asdict(c) for c in checks], "notes": list(notes)}


_ABS_PATH = re.compile(r"(?<![\w.])/(?:[\w.+@-]+/)+[\w.+@-]+")


def short_paths(text: str, cwd: str | None = None) -> str:
    """``text`` with every absolute path shortened for reading on screen: relative to ``cwd``
    (default the working directory) when below it, else its last two components after "…/"."""
    base = os.path.abspath(cwd or os.getcwd())

    def one(m: re.Match) -> str:
        p = m.group(0)
        if p == base or p.startswith(base + os.sep):
            return os.path.relpath(p, base)
        parts = p.split("/")
        return "…/" + "/".join(parts[-2:]) if len(parts) > 3 else p

    return _ABS_PATH.sub(one, text)


def health_markdown(health: Mapping) -> str:
    """A markdown section for a scorecard: the verdict, every check that is not OK, the notes and
    where the statistic thresholds came from (the truth-Monte-Carlo calibration table, or χ² alone)."""
    v = health.get("verdict", "?")
    lines = ["## Health", ""]
    if health.get("written_anyway"):
        lines += ["**UNHEALTHY — written with --allow-unhealthy; do not use these numbers.**", ""]
    lines.append(f"verdict: **{v}** ({len(health.get('checks', []))} checks)")
    bad = [c for c in health.get("checks", []) if c["status"] != OK]
    if bad:
        # a list, not a table: a table cell does not wrap, and the messages are sentences
        lines += [""] + [f"- **{c['name']}** {c['status']}: {short_paths(c['message'])}" for c in bad]
    if health.get("notes"):
        lines += ["", "Notes:", ""] + [f"- {short_paths(n)}" for n in health["notes"]]
    cal = health.get("calibration")
    if cal:
        lines += [
            "",
            f"Statistic thresholds: {cal.get('members')} members of {cal.get('source')} (`{cal.get('command')}`).",
        ]
    elif "calibration" in health:
        lines += ["", "Statistic thresholds: χ² bounds (no truth-Monte-Carlo calibration for this problem)."]
    return "\n".join(lines) + "\n"
