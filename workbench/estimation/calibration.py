"""Health thresholds calibrated on a problem's own truth Monte Carlo.

A filter statistic has no universal "good" value: a ZUPT whose R is conservative by design has a
mean NIS of 0.13 where χ² says 3.  A verdict built on χ² alone therefore says WARNING on every honest
run and carries no information.  Here every statistic check (a :class:`~workbench.estimation.health.Check`
with a ``stat``) is judged against the spread of the *same* statistic over honest members of the
problem's truth Monte Carlo (truth simulator → telemetry files → full reconstruction, on a seed
stream disjoint from the shipped scenarios' and from any tuning seeds):

* :func:`fit_band` — the honest band of a statistic: a normal fit (of the logarithm for a positive
  statistic) over the members, ± z standard deviations, widened to cover every member; z is chosen
  for the whole table (:func:`family_z`) so that an honest run leaves *any* of the problem's k bands
  with probability :data:`FAMILY_ALPHA` (Bonferroni), not each band; the table also stores the
  members' percentiles, so each threshold is traced to a stored number;
* a check's ``stat`` may name a ``"pool"``: the band it is judged against, shared by the checks of one
  kind whose honest values are exchangeable (the per-port NIS of seven pressure ports; a rare draw —
  one port's 2.6σ transducer bias — then sits in the band of the other ports' members too, where a
  band per port from 30 members misses it) or one band per sensor configuration (a drop test's
  first-contact clearance with and without ranging: the pose σ differs 30-fold).  Without a pool the
  band is the check's name;
* :func:`calibrate_checks` — re-judge the checks of one run: inside the band OK, outside WARNING,
  a NIS above the band by the factor :func:`nis_error_factor` or by the band's width, and a
  two-sided statistic beyond the band by its half-width (twice as far from the band's middle as its
  edge) ERROR; an ERROR of the check's own
  (physics) logic is never softened; a filter conservative by design is said once, as a note;
* :func:`truth_check` — a synthetic run judged against its truth: a headline quantity outside its
  reported 3σ is an ERROR.

The tables live with their problems (``workbench/problems/<kind>/health_calibration.json``),
written by ``python -m workbench.problems.calibration <kind> --write``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.estimation.consistency import chi2_ppf
from workbench.estimation.health import ERROR, OK, WARNING, Check

__all__ = [
    "FAMILY_ALPHA",
    "NIS_BEYOND_HALF_WIDTHS",
    "PERCENTILES",
    "Z_BAND",
    "band_key",
    "calibrate_checks",
    "family_z",
    "finish_health",
    "fit_band",
    "load_table",
    "nis_error_factor",
    "truth_check",
]

#: half-width of the honest band in standard deviations of the fitted normal: 3.29 is the two-sided
#: 99.9 % interval, so a check of an honest run leaves its band about once in a thousand runs
Z_BAND = 3.29

#: probability that an honest run leaves at least one of its problem's calibrated bands (a WARNING)
FAMILY_ALPHA = 0.01

#: a mean NIS above its honest band by this many of the band's half-widths (its whole width: the top
#: times top/bottom on the log scale) is an ERROR (:func:`calibrate_checks`)
NIS_BEYOND_HALF_WIDTHS = 2.0

#: the percentiles of each statistic over the members stored beside its band [%]
PERCENTILES = (0.5, 1.0, 50.0, 99.0, 99.5)


def family_z(k: int, alpha: float = FAMILY_ALPHA) -> float:
    """Half-width of each of ``k`` bands in standard deviations [-] such that an honest run leaves at
    least one of them with probability ≤ ``alpha`` (two-sided Bonferroni: Φ⁻¹(1 − α/2k)); never
    below :data:`Z_BAND`."""
    from scipy.stats import norm

    return max(Z_BAND, float(norm.ppf(1.0 - alpha / (2.0 * max(int(k), 1)))))


def fit_band(values: Sequence[float], kind: str, z: float = Z_BAND) -> dict:
    """The honest band of one statistic from its ``values`` over truth-MC members (n,) (units of the
    statistic): ``{"n", "scale", "center", "spread", "z", "band": [lo, hi], "percentiles", "min",
    "max"}``. ``scale`` is ``"log"`` (fit of ln value) when every value is > 0, else ``"linear"``;
    the band is center ± ``z``·spread (back-transformed), widened to contain every member."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    if v.size < 2:
        raise ValueError(f"a calibration band needs at least 2 finite members, got {v.size}")
    log = bool(np.all(v > 0.0))
    w = np.log(v) if log else v
    c, s = float(np.mean(w)), float(np.std(w, ddof=1))
    lo, hi = c - z * s, c + z * s
    if log:
        lo, hi = float(np.exp(lo)), float(np.exp(hi))
    lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
    return {
        "n": int(v.size),
        "scale": "log" if log else "linear",
        "center": _g(c),
        "spread": _g(s),
        "z": _g(z),
        "band": [_g(lo), _g(hi)],
        "percentiles": {f"{p:g}": _g(np.percentile(v, p)) for p in PERCENTILES},
        "min": _g(v.min()),
        "max": _g(v.max()),
    }


def _g(x: float) -> float:
    return float(f"{float(x):.6g}")


def nis_error_factor(dof: int) -> float:
    """How far above its honest band a mean NIS of dimension ``dof`` must lie to be an ERROR [-]:
    the 99.9 % quantile of one χ²(dof) sample over its mean (5.4 for dof 3, 10.8 for dof 1) — the
    average innovation as large, relative to the honest one, as a 3.3σ outlier."""
    return float(chi2_ppf(0.999, int(dof)) / int(dof))


def load_table(path: Path | None) -> dict | None:
    """The calibration table at ``path`` (``health_calibration.json``), or None when there is none."""
    if path is None or not Path(path).is_file():
        return None
    return json.loads(Path(path).read_text(encoding="utf-8"))


def calibrate_checks(checks: Sequence[Mapping], table: Mapping | None) -> tuple[list[dict], list[str]]:
    """The checks of one run (summary dicts, :func:`dataclasses.asdict` of
    :class:`~workbench.estimation.health.Check`) re-judged against the calibration ``table``, and the
    notes it adds.  A check with a ``stat`` and an entry in ``table["checks"]`` gets the band's
    status (see the module docstring); without an entry it keeps its own status and its message says
    it is uncalibrated; other checks are unchanged.  The entry is ``stat["pool"]`` when the stat
    names one, else the check's name.  A NIS whose honest median is below half its dimension adds
    the note that the filter is conservative by design, with the factor."""
    entries = (table or {}).get("checks", {})
    source = (table or {}).get("source", "the truth Monte Carlo")
    out, notes = [], []
    for c in checks:
        stat = c.get("stat")
        if not stat:
            out.append(dict(c))
            continue
        e = entries.get(band_key(c["name"], stat))
        if e is None:
            out.append({**c, "message": c["message"] + " (threshold uncalibrated: no truth-MC band for this check)"})
            continue
        judged, note = _judge(Check(**c), e, source)
        out.append(judged)
        if note:
            notes.append(note)
    return out, notes


def band_key(name: str, stat: Mapping | None) -> str:
    """The calibration-table entry that judges the check ``name`` with ``stat``: its ``"pool"``
    when it names one (a band shared by exchangeable checks, or one per sensor configuration), else
    ``name``."""
    return str((stat or {}).get("pool") or name)


def _judge(c: Check, e: Mapping, source: str) -> tuple[dict, str | None]:
    """One calibrated check (a dict) and its note, from the check ``c`` and its table entry ``e``."""
    lo, hi = (float(b) for b in e["band"])
    n = int(e["n"])
    kind = c.stat.get("kind")
    pool = c.stat.get("pool")
    what = f"{n} truth-MC values of the pool {pool}" if pool else f"{n} truth-MC members"
    origin = f"honest band [{lo:.3g}, {hi:.3g}] over {what} ({source})"
    note = None
    if kind == "nis":
        dof = int(c.stat["dof"])
        median = float(e["percentiles"]["50"])
        if median < 0.5 * dof:
            note = (
                f"{c.name}: conservative by design — honest mean NIS {median:.3g} against {dof} expected "
                f"(R/Q larger than the errors by a factor ~{dof / median:.3g} in variance; {n} truth-MC members)"
            )
    if c.status == ERROR or c.value is None or not np.isfinite(float(c.value)):
        return _dict(c, bound=[lo, hi] if c.status != ERROR else c.bound), note
    v = float(c.value)
    if kind == "nis":
        err = hi * nis_error_factor(int(c.stat["dof"]))
        # too large a NIS only (a NIS far below its band is a filter more conservative than its honest
        # runs: its σ too large, no wrong answer hidden behind a small σ); above the band by its whole
        # width (≈ 4z honest spreads): a margin for real data that a truth simulator does not mimic
        if v > err or (v > hi and _far_beyond(v, lo, hi, e, NIS_BEYOND_HALF_WIDTHS)):
            msg = (
                f"{c.name}: mean NIS {v:.3g} is {v / hi:.3g}× the top of its {origin} (beyond it by more than the "
                "band's width, or the χ² factor); the filter is inconsistent with this sensor — a wrong unit, "
                "axis, noise level or timing of this stream, or an initial state or model that its data contradict?"
            )
            return _dict(c, status=ERROR, bound=[lo, hi], message=msg), note
    if kind == "two_sided" and not lo <= v <= hi and _far_beyond(v, lo, hi, e):
        # the check's own message says what is likely wrong
        msg = f"{c.name}: {v:.4g} lies beyond its {origin} by more than the band's half-width — " + c.message
        return _dict(c, status=ERROR, bound=[lo, hi], message=msg), note
    if lo <= v <= hi:
        return _dict(c, status=OK, bound=[lo, hi], message=f"{c.name}: {v:.4g} inside its {origin}"), note
    if kind == "upper" and v < lo:
        return _dict(c, status=OK, bound=[lo, hi], message=f"{c.name}: {v:.4g} below its {origin}"), note
    side = "above" if v > hi else "below"
    msg = f"{c.name}: {v:.4g} {side} its {origin} — " + c.message
    return _dict(c, status=WARNING, bound=[lo, hi], message=msg), note


def _far_beyond(v: float, lo: float, hi: float, e: Mapping, half_widths: float = 1.0) -> bool:
    """True when ``v`` lies beyond the band [``lo``, ``hi``] (table entry ``e``; on the log scale when
    the band was fitted there) by more than ``half_widths`` × the band's half-width (1: twice as far
    from its middle as its edge, ≈ 2z spreads of the honest members, where no honest run gets)."""
    log = e.get("scale") == "log" and v > 0.0 and lo > 0.0
    f = np.log if log else (lambda x: x)
    mid, half = 0.5 * (f(hi) + f(lo)), 0.5 * (f(hi) - f(lo))
    return bool(abs(f(v) - mid) > (1.0 + half_widths) * half)


def _dict(c: Check, **changes: Any) -> dict:
    from dataclasses import asdict

    return asdict(replace(c, **changes))


def truth_check(name: str, what: str, error: Any, sigma: Any, unit: str = "", *, z_max: float = 3.0) -> Check:
    """A synthetic run's headline quantity ``what`` judged against its truth: ``error`` (estimate −
    truth, a scalar or a vector of components, SI) against the run's own 1σ ``sigma`` (same shape).
    ERROR when any component lies outside ±``z_max``σ (the reported uncertainty does not cover the
    truth: over-confident or biased); value: the largest |z|."""
    e = np.atleast_1d(np.asarray(error, float))
    s = np.atleast_1d(np.asarray(sigma, float))
    u = f" {unit}" if unit else ""
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(s)) and np.all(s > 0.0)):
        return Check(name, ERROR, None, z_max, f"{what}: error or σ against the truth not finite or σ ≤ 0")
    z = e / s
    zmax = float(np.max(np.abs(z)))
    zs = ", ".join(f"{x:+.2g}" for x in z)
    if zmax > z_max:
        mag = float(np.linalg.norm(e))
        return Check(
            name,
            ERROR,
            _g(zmax),
            z_max,
            f"{what}: error against the truth {mag:.4g}{u} lies outside its reported {z_max:g}σ (z = {zs}): the "
            "reported uncertainty is over-confident or the estimate biased",
        )
    return Check(name, OK, _g(zmax), z_max, f"{what}: error against the truth within {z_max:g}σ (z = {zs})")


_RANK = {OK: 0, WARNING: 1, ERROR: 2}


def finish_health(health: Mapping, table: Mapping | None, truth_score: Mapping | None = None) -> dict:
    """The run's final ``summary["health"]``: its checks re-judged by :func:`calibrate_checks`
    against ``table``, plus one :func:`truth_check` per entry of ``truth_score["headline"]``
    (synthetic runs: ``[{"name", "what", "error", "sigma", "unit"}]``, SI), the verdict recomputed
    and ``"calibration"`` naming the table (None: uncalibrated)."""
    checks, notes = calibrate_checks(health.get("checks", []), table)
    for h in (truth_score or {}).get("headline", []):
        c = truth_check(f"truth.{h['name']}", h["what"], h["error"], h["sigma"], h.get("unit", ""))
        checks.append(_dict(c))
    worst = max((c["status"] for c in checks), key=_RANK.__getitem__, default=OK)
    info = None
    if table:
        info = {k: table.get(k) for k in ("source", "command", "members", "seeds", "scenarios")}
    return {
        **health,
        "verdict": worst,
        "checks": checks,
        "notes": list(health.get("notes", [])) + notes,
        "calibration": info,
    }
