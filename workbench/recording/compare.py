"""Compare two runs of the same kind of scenario: ``workbench compare A.rrd B.rrd [--out C.rrd]``.

Two seeds, two tunings or two code versions of one scenario are read back from their recordings
(:mod:`workbench.recording.reader`) and their sibling summaries (``<name>.summary.json`` beside
each ``.rrd``, when present), and compared:

* every *bounded series* under ``/plots`` present in both runs (a root with an estimate leaf,
  ``value`` or ``smoothed``, and ``plus_<n>sigma`` / ``minus_<n>sigma`` bounds): the difference
  A − B against time with the combined 1σ ``sqrt(σ_A² + σ_B²)`` (σ = (plus − estimate)/n), on A's
  time tags (B linearly interpolated where its tags differ; identical tags are used as they are,
  so two identical runs differ by exactly zero);
* the vehicle position (``/world/vehicle``, rotated into the world frame through its parent
  pose) with the combined σ from the two runs' ``/world/vehicle/uncertainty`` 3σ ellipsoids;
* the summaries: every number and verdict (boolean) that changed.

:func:`compare_runs` returns a :class:`Comparison` (numbers only); :func:`write_comparison`
writes the comparison recording (both trajectories and vehicles overlaid in 3D, the differences
with ±3 combined σ, the two scorecards side by side, the table of changes); :func:`changes_markdown`
renders the table the command line prints. Runs of different scenario kinds are refused with a
:class:`ComparisonError`. Units: those of the compared recordings (SI unless a series says so).
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.core.rotation import quat_to_dcm
from workbench.recording import layout
from workbench.recording.reader import RecordingData, read_recording
from workbench.recording.writer import open_recording

__all__ = [
    "Comparison",
    "ComparisonError",
    "SeriesDiff",
    "changes_markdown",
    "ranked_changes",
    "change_text",
    "sigma_of",
    "compare_runs",
    "flatten_summary",
    "mesh_edges",
    "write_comparison",
]

#: summary keys that differ between any two runs and say nothing about the result
IGNORED_KEYS = ("wall_time_s", "stage_times_s", "recording", "recording_bytes", "headline")
_BOUND = re.compile(r"^plus_(\d+(?:\.\d+)?)sigma$")
_A_COLOUR = (31, 119, 180, 255)
_B_COLOUR = (255, 127, 14, 255)
_AXIS_COLOURS = ((214, 39, 40, 255), (44, 160, 44, 255), (31, 119, 180, 255))  # x red, y green, z blue (the 3D axes)
_NORM_COLOUR = (20, 20, 20, 255)


class ComparisonError(ValueError):
    """The two recordings cannot be compared (different scenario kinds, not workbench runs)."""


@dataclass(frozen=True)
class SeriesDiff:
    """Difference A − B of one bounded series: ``root`` (below ``/plots``), ``names`` of its k
    components, ``t`` (n,) [s] (A's tags inside B's span), ``a``/``b``/``diff``/``sigma`` (n, k)
    (``sigma`` the combined 1σ), ``max_abs`` and ``max_over_sigma`` (k,) (NaN where σ is 0)."""

    root: str
    names: tuple[str, ...]
    t: np.ndarray
    a: np.ndarray
    b: np.ndarray
    diff: np.ndarray
    sigma: np.ndarray

    @property
    def max_abs(self) -> np.ndarray:
        return np.max(np.abs(self.diff), axis=0) if len(self.t) else np.zeros(self.diff.shape[1])

    @property
    def max_over_sigma(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(self.sigma > 0, np.abs(self.diff) / self.sigma, np.where(self.diff == 0, 0.0, np.inf))
        return np.max(r, axis=0) if len(self.t) else np.zeros(self.diff.shape[1])


@dataclass
class Comparison:
    """Everything :func:`compare_runs` found: the two recordings, their ``kind`` and ``names``
    (scenario names), ``series`` (bounded-series differences), ``position`` (the vehicle-position
    difference as a :class:`SeriesDiff` with components x, y, z [m] in the scene frame, or None),
    ``numbers`` [(key, A, B)] of the summary leaves that changed, ``verdicts`` [(key, A, B)] of
    every boolean leaf, and the two scorecards ``reports`` (markdown, '' if absent)."""

    a: RecordingData
    b: RecordingData
    kind: str
    names: tuple[str, str]
    series: list[SeriesDiff] = field(default_factory=list)
    position: SeriesDiff | None = None
    numbers: list[tuple[str, Any, Any]] = field(default_factory=list)
    verdicts: list[tuple[str, Any, Any]] = field(default_factory=list)
    reports: tuple[str, str] = ("", "")
    summaries: tuple[dict | None, dict | None] = (None, None)

    @property
    def identical(self) -> bool:
        """True if every compared series, the position and every summary number are equal."""
        diffs = [*self.series, *([self.position] if self.position is not None else [])]
        return not self.numbers and all(np.all(d.diff == 0) for d in diffs)


# ------------------------------------------------------------------------------------- reading
def _summary_path(rrd: Path) -> Path:
    return rrd.with_name(rrd.stem + ".summary.json")


def _load_summary(rrd: Path) -> dict | None:
    p = _summary_path(rrd)
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise ComparisonError(f"{p}: cannot read the summary: {e}") from e


def _kind(data: RecordingData) -> str:
    run = data.properties().get("run", {})
    kind = run.get("kind")
    if not kind:
        raise ComparisonError(
            f"{data.path}: no run kind in the recording properties (not a `workbench run` recording?)"
        )
    return str(kind)


def flatten_summary(summary: dict, prefix: str = "") -> dict[str, Any]:
    """Nested summary -> ``{"a.b.c": leaf}`` for numbers, booleans and strings (lists of numbers
    are split into ``key[i]``); the run-bookkeeping keys :data:`IGNORED_KEYS` are left out."""
    out: dict[str, Any] = {}
    for k, v in summary.items():
        key = f"{prefix}{k}"
        if not prefix and k in IGNORED_KEYS:
            continue
        if isinstance(v, dict):
            out.update(flatten_summary(v, key + "."))
        elif isinstance(v, list | tuple):
            if all(isinstance(x, int | float | bool) or x is None for x in v) and len(v) <= 12:
                for i, x in enumerate(v):
                    out[f"{key}[{i}]"] = x
            elif all(isinstance(x, dict) for x in v) and len(v) <= 12:
                for i, x in enumerate(v):
                    out.update(flatten_summary(x, f"{key}[{i}]."))
            else:
                out[key] = json.dumps(v, default=str)
        else:
            out[key] = v
    return out


def _same(x: Any, y: Any) -> bool:
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return True
    return x == y


def _bounded_roots(data: RecordingData) -> dict[str, tuple[str, str, float]]:
    """{root: (estimate leaf entity, plus-bound entity, n)} of the bounded series under /plots."""
    ents = set(data.entities())
    out: dict[str, tuple[str, str, float]] = {}
    for e in sorted(ents):
        if not e.startswith(layout.PLOTS + "/"):
            continue
        root, _, leaf = e.rpartition("/")
        m = _BOUND.match(leaf)
        if not m or layout.join(root, layout.bound_names(float(m.group(1)))[1]) not in ents:
            continue
        leaves = (layout.join(root, x) for x in (layout.VALUE, layout.SMOOTHED_SERIES))
        est = next((x for x in leaves if x in ents), None)
        if est is None:
            continue
        n = float(m.group(1))
        if root not in out or n < out[root][2]:  # prefer the tightest (1σ) bound
            out[root] = (est, e, n)
    return out


def _series_names(data: RecordingData, entity: str, k: int) -> tuple[str, ...]:
    try:
        names = data.static_component(entity, "SeriesLines:names")
        if len(names) == k:
            return tuple(str(x) for x in names)
    except KeyError:
        pass
    return tuple(str(i) for i in range(k)) if k > 1 else (entity.rsplit("/", 2)[-2],)


def _on_a_times(ta: np.ndarray, tb: np.ndarray, vb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mask of A's tags inside B's span, B's values on those tags), exact where the tags agree."""
    if len(ta) == len(tb) and np.array_equal(ta, tb):
        return np.ones(len(ta), bool), vb
    if len(tb) < 2:
        return np.zeros(len(ta), bool), np.zeros((0, vb.shape[1]))
    keep = (ta >= tb[0]) & (ta <= tb[-1])
    tq = ta[keep]
    out = np.empty((len(tq), vb.shape[1]))
    for j in range(vb.shape[1]):
        out[:, j] = np.interp(tq, tb, vb[:, j])
    return keep, out


def _series_diff(root: str, names: tuple[str, ...], ta, va, sa, tb, vb, sb) -> SeriesDiff:
    keep, vb_a = _on_a_times(ta, tb, vb)
    _, sb_a = _on_a_times(ta, tb, sb)
    a, s_a = va[keep], sa[keep]
    return SeriesDiff(root, names, ta[keep], a, vb_a, a - vb_a, np.sqrt(s_a**2 + sb_a**2))


def _bounded(data: RecordingData, est: str, plus: str, n: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t, v = data.scalars(est)
    tp, p = data.scalars(plus)
    if not np.array_equal(t, tp) or p.shape != v.shape:
        _, p = _on_a_times(t, tp, p)
        if p.shape != v.shape:
            raise ComparisonError(f"{data.path}: {plus} does not match {est}")
    return t, v, np.abs(p - v) / n


def _vehicle_track(data: RecordingData) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """(t, position (n, 3) [m], rotation (n, 3, 3) of /world/vehicle or None) or None if absent."""
    try:
        t, p = data.translations(layout.VEHICLE)
    except KeyError:
        return None
    rot = None
    if data.has_temporal(layout.VEHICLE, "Transform3D:quaternion"):
        tq, _, q = data.transforms(layout.VEHICLE)
        if np.array_equal(tq, t):
            rot = quat_to_dcm(q)
    return t, p, rot


def _position_sigma(data: RecordingData, t: np.ndarray, rot: np.ndarray | None) -> np.ndarray:
    """1σ (n, 3) of the vehicle position along the scene axes from the 3σ uncertainty ellipsoids
    (zeros where the recording has none)."""
    try:
        te, _, h, q = data.ellipsoids(layout.UNCERTAINTY)
    except KeyError:
        return np.zeros((len(t), 3))
    r_e = quat_to_dcm(q[:, 0])
    cov = np.einsum("nij,nj,nkj->nik", r_e, (h[:, 0] / 3.0) ** 2, r_e)
    if rot is not None and len(te) == len(t) and np.array_equal(te, t):
        cov = np.einsum("nij,njk,nlk->nil", rot, cov, rot)
    sig = np.sqrt(np.clip(np.einsum("nii->ni", cov), 0, None))
    if len(te) == len(t) and np.array_equal(te, t):
        return sig
    _, s = _on_a_times(t, te, sig)
    full = np.zeros((len(t), 3))
    keep = (t >= te[0]) & (t <= te[-1]) if len(te) > 1 else np.zeros(len(t), bool)
    full[keep] = s
    return full


def compare_runs(a_path: str | os.PathLike[str], b_path: str | os.PathLike[str]) -> Comparison:
    """Read two run recordings (and their summaries) and compute every difference A − B.

    Raises ``FileNotFoundError`` / :class:`~workbench.recording.reader.RecordingError` for a
    missing or incomplete file and :class:`ComparisonError` when the runs are of different
    scenario kinds (e.g. a drop test against an entry) or not run recordings at all.
    """
    a, b = read_recording(a_path), read_recording(b_path)
    ka, kb = _kind(a), _kind(b)
    if ka != kb:
        raise ComparisonError(
            f"cannot compare {a.path} (kind {ka!r}) with {b.path} (kind {kb!r}): the scenarios differ in kind; "
            "compare two seeds, two tunings or two code versions of the same kind of scenario"
        )
    cmp = Comparison(a=a, b=b, kind=ka, names=(a.recording_name or a.path.stem, b.recording_name or b.path.stem))
    ra, rb = _bounded_roots(a), _bounded_roots(b)
    for root in sorted(set(ra) & set(rb)):
        ta, va, sa = _bounded(a, *ra[root])
        tb, vb, sb = _bounded(b, *rb[root])
        if va.shape[1] != vb.shape[1]:
            continue
        rel = root[len(layout.PLOTS) + 1 :]
        cmp.series.append(_series_diff(rel, _series_names(a, ra[root][0], va.shape[1]), ta, va, sa, tb, vb, sb))
    tra, trb = _vehicle_track(a), _vehicle_track(b)
    if tra is not None and trb is not None:
        sa = _position_sigma(a, tra[0], tra[2])
        sb = _position_sigma(b, trb[0], trb[2])
        cmp.position = _series_diff("position", ("x", "y", "z"), tra[0], tra[1], sa, trb[0], trb[1], sb)
    sum_a, sum_b = _load_summary(a.path), _load_summary(b.path)
    cmp.summaries = (sum_a, sum_b)
    if sum_a is not None and sum_b is not None:
        fa, fb = flatten_summary(sum_a), flatten_summary(sum_b)
        for key in [*fa, *(k for k in fb if k not in fa)]:
            x, y = fa.get(key), fb.get(key)
            if isinstance(x, bool) or isinstance(y, bool):
                cmp.verdicts.append((key, x, y))
            elif not _same(x, y):
                cmp.numbers.append((key, x, y))
    reports = []
    for d in (a, b):
        try:
            reports.append(d.text_document(layout.REPORT))
        except KeyError:
            reports.append("")
    cmp.reports = (reports[0], reports[1])
    return cmp


# ------------------------------------------------------------------------------------ markdown
def _fmt(x: Any) -> str:
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        if math.isnan(x):
            return "not defined"
        return f"{x:.4g}"
    s = str(x)
    return s if len(s) <= 40 else s[:37] + "…"


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(float(x))


def change_text(x: Any, y: Any) -> str:
    """B − A, with the relative change only where it means something: both of one sign and the
    change smaller than A itself (a near-zero coordinate's "+298 %" says nothing)."""
    if _number(x) and _number(y):
        d = float(y) - float(x)
        rel = f" ({100.0 * d / abs(x):+.1f} %)" if x != 0 and x * y > 0 and abs(d) < abs(x) else ""
        return f"{d:+.4g}{rel}"
    return "changed"


#: sibling keys that hold a summary number's 1σ (``max_stroke.distance_m`` → ``max_stroke.sigma_m``)
_SIGMA_SUFFIXES = ("sigma_m", "sigma", "sigma_deg", "sigma_mps", "sigma_pa")


def sigma_of(key: str, flat: dict[str, Any]) -> float | None:
    """The 1σ of the summary number ``key`` in the flattened summary ``flat``, when the summary
    carries one beside it (``<key>_sigma``, ``<key>_sigma_<unit>``, or a sibling ``sigma*`` leaf
    of a group with a single value); None otherwise."""
    base, _, leaf = key.rpartition(".")
    cands = [f"{key}_sigma"]
    if "[" not in leaf:  # a vector component has no sibling σ of its own
        stem = leaf.rsplit("_", 1)[0] if "_" in leaf else leaf
        cands += [f"{base}.{stem}_sigma" if base else f"{stem}_sigma"]
        cands += [f"{base}.{suf}" if base else suf for suf in _SIGMA_SUFFIXES]
    for c in cands:
        v = flat.get(c)
        if c != key and _number(v) and float(v) > 0:
            return float(v)
    return None


def ranked_changes(cmp: Comparison) -> list[tuple[str, Any, Any, float | None]]:
    """The changed summary numbers ``(key, A, B, |B − A| / σ)``, largest first: by |B − A| over
    the combined σ where the summaries give one (σ from :func:`sigma_of`), then the rest by their
    relative change (None: no σ)."""
    fa = flatten_summary(cmp.summaries[0] or {})
    fb = flatten_summary(cmp.summaries[1] or {})
    rows = []
    for k, x, y in cmp.numbers:
        if "sigma" in k.split(".")[-1] or k == "seed":
            continue  # a σ moves with its value; the seeds are named above
        sa, sb = sigma_of(k, fa), sigma_of(k, fb)
        z = None
        if _number(x) and _number(y) and sa is not None and sb is not None:
            z = abs(float(y) - float(x)) / math.hypot(sa, sb)
        rows.append((k, x, y, z))

    def weight(r):
        k, x, y, z = r
        if z is not None:
            return (0, -z)
        if _number(x) and _number(y):
            return (1, -abs(float(y) - float(x)) / max(abs(float(x)), abs(float(y)), 1e-300))
        return (2, 0.0)

    return sorted(rows, key=weight)


def changes_markdown(cmp: Comparison, max_rows: int = 12) -> str:
    """The markdown report of what changed from A to B: the runs (and whether their truths
    differ), the verdicts that flipped (and how many held), the ``max_rows`` largest changes of the
    key numbers (:func:`ranked_changes`) and the series differences with their largest |A − B| and
    |A − B| / combined σ."""
    na, nb = cmp.names
    lines = [
        f"## Comparison of two `{cmp.kind}` runs",
        "",
        f"- **A**: `{cmp.a.path}` ({na}, seed {cmp.a.properties().get('run', {}).get('seed', '?')})",
        f"- **B**: `{cmp.b.path}` ({nb}, seed {cmp.b.properties().get('run', {}).get('seed', '?')})",
        "",
    ]
    ra, rb = (d.properties().get("run", {}) for d in (cmp.a, cmp.b))
    if ra.get("synthetic", True) and rb.get("synthetic", True) and ra.get("seed") != rb.get("seed"):
        lines += [
            f"**Different truths**: synthetic runs with seeds {ra.get('seed', '?')} and {rb.get('seed', '?')} fly "
            "different truths with different sensor errors — A − B is not an error of either; each run's own "
            "truth score is in its scorecard.",
            "",
        ]
    if cmp.summaries[0] is None or cmp.summaries[1] is None:
        lines += ["(no summary beside one of the recordings: key numbers not compared)", ""]
    else:
        flipped = [v for v in cmp.verdicts if v[1] != v[2]]
        lines += [f"### Verdicts: {len(flipped)} changed, {len(cmp.verdicts) - len(flipped)} the same", ""]
        if flipped:
            lines += ["| verdict | A | B |", "|---|---|---|"]
            lines += [f"| `{k}` | {_fmt(x)} | {_fmt(y)} |" for k, x, y in flipped]
            lines.append("")
        ranked = ranked_changes(cmp)
        lines += [f"### Key numbers: {len(ranked)} changed — the largest first (by |B − A| / σ where known)", ""]
        if ranked:
            lines += ["| quantity | A | B | B − A | abs(B − A) / σ |", "|---|---|---|---|---|"]
            for k, x, y, z in ranked[:max_rows]:
                lines.append(
                    f"| `{k}` | {_fmt(x)} | {_fmt(y)} | {change_text(x, y)} | {'—' if z is None else f'{z:.2f}'} |"
                )
            if len(ranked) > max_rows:
                lines.append(f"| … {len(ranked) - max_rows} smaller changes | | | | |")
            lines.append("")
    diffs = [*([cmp.position] if cmp.position is not None else []), *cmp.series]
    lines += [f"### Time histories: {len(diffs)} compared (A − B on A's time tags)", ""]
    if diffs:
        lines += ["| series | component | max abs(A − B) | max abs(A − B) / σ | samples |", "|---|---|---|---|---|"]
        for d in diffs:
            for j, name in enumerate(d.names):
                ratio = d.max_over_sigma[j]
                lines.append(
                    f"| `{d.root}` | {name} | {d.max_abs[j]:.4g} | "
                    f"{'σ = 0' if not np.isfinite(ratio) else f'{ratio:.3g}'} | {len(d.t)} |"
                )
        lines.append("")
    lines.append(
        "σ is the combined 1σ sqrt(σ_A² + σ_B²); identical runs differ by exactly 0."
        if not cmp.identical
        else "The two runs are identical: every difference is exactly 0."
    )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- comparison recording
def mesh_edges(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The unique edges of a triangle mesh as segments (m, 2, 3) in the vertices' frame and unit:
    ``verts`` (n, 3), ``faces`` (f, 3) vertex indices; for drawing a body as a wireframe."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return np.asarray(verts, dtype=np.float64)[e]


def _copy_vehicle(
    rec: Any, src: RecordingData, run: str, colour: tuple[int, int, int, int], *, wireframe: bool = False
) -> None:
    """The run's vehicle (pose, body pose, meshes, 3σ ellipsoid) and track under ``/world/run_<run>``;
    ``wireframe``: the meshes as their edges (B's, so that A's translucent bodies stay visible inside:
    two translucent bodies at nearly one pose showed only the one drawn last)."""
    track = _vehicle_track(src)
    if track is None:
        return
    t, p, _ = track
    if src.has_temporal(layout.VEHICLE, "Transform3D:quaternion"):
        _, p, q = src.transforms(layout.VEHICLE)
    else:
        q = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    veh = layout.compare_run_path(run, "vehicle")
    rec.poses(veh, t, p, q)
    rec.line_strip(layout.compare_run_path(run, "track"), p, color=colour, radius=-1.5)
    prefix = layout.VEHICLE + "/"
    for e in src.entities():
        if not e.startswith(prefix) or e.startswith(layout.RADAR):
            continue
        sub = layout.join(veh, e[len(prefix) :])
        if src.has_temporal(e, "Transform3D:quaternion"):
            te, pe, qe = src.transforms(e)
            rec.poses(sub, te, pe, qe)
        for tm, verts, faces, _ in src.meshes(e):
            if tm is None and wireframe:
                rec.line_strip(sub, mesh_edges(verts, faces), color=colour, radius=-0.6)
            elif tm is None:
                rec.stream.log(sub, _mesh3d(verts, faces, colour), static=True)
    try:
        te, c, h, qe = src.ellipsoids(layout.UNCERTAINTY)
        rec.stream.send_columns(
            layout.join(veh, "uncertainty"),
            indexes=[rr.TimeColumn(layout.TIME, duration=np.round(te * 1e9).astype("timedelta64[ns]"))],
            columns=rr.Ellipsoids3D.columns(centers=c[:, 0], half_sizes=h[:, 0], quaternions=qe[:, 0]),
        )
        rec.stream.log(
            layout.join(veh, "uncertainty"),
            rr.Ellipsoids3D.from_fields(colors=[colour[:3] + (90,)], fill_mode=rr.components.FillMode.MajorWireframe),
            static=True,
        )
    except KeyError:
        pass


def _mesh3d(verts: np.ndarray, faces: np.ndarray, colour: tuple[int, int, int, int]) -> Any:
    return rr.Mesh3D(
        vertex_positions=verts.astype(np.float32),
        triangle_indices=faces.astype(np.uint32),
        albedo_factor=[colour[0], colour[1], colour[2], 160],
    )


def write_comparison(cmp: Comparison, out: str | os.PathLike[str], *, max_views: int = 16) -> Path:
    """Write the comparison recording to ``out`` (atomically) and return its path.

    Scene: the surface of run A, both vehicles (A blue translucent bodies, B an orange wireframe) and tracks under
    ``/world/run_a`` / ``/world/run_b``. Plots: ``/compare/position/<axis>`` and
    ``/compare/diff/<quantity>`` (A − B with ±3 combined σ), ``/compare/overlay/<quantity>/{a,b}``;
    text: the two scorecards ``/compare/report_a``, ``/compare/report_b`` and the table of changes
    ``/compare/changes``. The blueprint shows the scene, up to ``max_views`` difference views
    (position first, then the largest |A − B| / σ), the changes and the two scorecards side by side.
    """
    out = Path(out)
    diffs = [*([cmp.position] if cmp.position is not None else []), *cmp.series]

    def weight(d: SeriesDiff) -> float:
        r = d.max_over_sigma
        return float(np.max(np.where(np.isfinite(r), r, 1e9))) if len(r) else 0.0

    shown = ([cmp.position] if cmp.position is not None else []) + sorted(cmp.series, key=weight, reverse=True)
    shown = shown[:max_views]
    views = []
    for d in shown:
        root = layout.COMPARE_POSITION if d is cmp.position else layout.compare_diff_path(d.root)
        if d is cmp.position:  # the colours named in the title: a legend would cover the curves
            name = "Δ position A − B [m]: x red, y green, z blue, |Δ| black; ±3σ combined grey"
            views.append(rrb.TimeSeriesView(name=name, origin=root, plot_legend=rrb.PlotLegend(visible=False)))
        else:
            views.append(rrb.TimeSeriesView(name=f"Δ {d.root} A − B", origin=root))
    for d in shown:
        if d is cmp.position:
            continue
        views.append(rrb.TimeSeriesView(name=f"A, B {d.root}", origin=layout.join(layout.COMPARE_OVERLAY, d.root)))
    right = [
        rrb.Tabs(*views, active_tab=0) if views else rrb.TextDocumentView(origin=layout.COMPARE_CHANGES),
        rrb.TextDocumentView(name="What changed", origin=layout.COMPARE_CHANGES),
        rrb.Horizontal(
            rrb.TextDocumentView(name=f"A: {cmp.names[0]}", origin=layout.COMPARE_REPORT_A),
            rrb.TextDocumentView(name=f"B: {cmp.names[1]}", origin=layout.COMPARE_REPORT_B),
        ),
    ]
    scene = rrb.Spatial3DView(name="A blue bodies, B orange wireframe", origin=layout.WORLD)
    bp = rrb.Blueprint(
        rrb.Horizontal(scene, rrb.Vertical(*right, row_shares=[3, 1.5, 2]), column_shares=[2, 3]),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
    )
    properties = {
        "compare": {
            "kind": cmp.kind,
            "a": str(cmp.a.path),
            "b": str(cmp.b.path),
            "identical": bool(cmp.identical),
        }
    }
    with open_recording(out, f"compare {cmp.names[0]} vs {cmp.names[1]}", bp, properties=properties) as rec:
        rec.view_coordinates()
        for tm, verts, faces, col in cmp.a.meshes(layout.SURFACE):
            if tm is None:
                c = ((col >> 24) & 255, (col >> 16) & 255, (col >> 8) & 255, 255)
                rec.stream.log(layout.SURFACE, _mesh3d(verts, faces, c), static=True)
        _copy_vehicle(rec, cmp.a, "a", _A_COLOUR)
        _copy_vehicle(rec, cmp.b, "b", _B_COLOUR, wireframe=True)
        for d in diffs:
            root = layout.COMPARE_POSITION if d is cmp.position else layout.compare_diff_path(d.root)
            names = [f"{n} A − B" for n in d.names]
            for j, comp in enumerate(d.names):
                sub = layout.compare_position_path(comp) if d is cmp.position else None
                if sub is not None:
                    rec.series_with_bounds(
                        sub, d.t, d.diff[:, j], d.sigma[:, j], names=f"Δ{comp} [m]", color=[_AXIS_COLOURS[j % 3]]
                    )
            if d is cmp.position:
                rec.scalars(
                    layout.COMPARE_POSITION_NORM,
                    d.t,
                    np.linalg.norm(d.diff, axis=1),
                    names="|Δ position| [m]",
                    colors=[_NORM_COLOUR],
                )
                continue
            rec.series_with_bounds(root, d.t, d.diff, d.sigma, names=names)
            rec.scalars(
                layout.compare_overlay_path(d.root, "a"), d.t, d.a, names=[f"{n} A" for n in d.names], colors=_A_COLOUR
            )
            rec.scalars(
                layout.compare_overlay_path(d.root, "b"), d.t, d.b, names=[f"{n} B" for n in d.names], colors=_B_COLOUR
            )
        rec.report(changes_markdown(cmp), layout.COMPARE_CHANGES)
        rec.report(cmp.reports[0] or "(no scorecard in A)", layout.COMPARE_REPORT_A)
        rec.report(cmp.reports[1] or "(no scorecard in B)", layout.COMPARE_REPORT_B)
    return out
