"""One-page summary image of a run's key plots: ``workbench replay REC.rrd --png OUT.png``.

The key time series of the run (the problem's :attr:`~workbench.recording.replay.Presentation.plots`,
or the first six bounded series under ``/plots`` for a problem without a presentation) are read
back from the recording and drawn with matplotlib (Agg backend, no display needed) in a 2×3 grid:
each estimate with its ±nσ band filled, the truth dashed when the recording has it, other leaves
(forward pass, measured, ...) thin; the key events as dotted vertical lines; units on every
y axis; the drop test's stroke zoomed on the impact (first contact to rebound). The title carries the
run's name and scenario description, kind, seed and date, and the headline.
The figure is 1800×1050 pixels.
"""

from __future__ import annotations

import os
import re
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workbench.recording import layout  # noqa: E402
from workbench.recording.reader import RecordingData, read_recording  # noqa: E402
from workbench.recording.replay import PRESENTATIONS, replay_titles  # noqa: E402

__all__ = ["SIZE_PX", "render_png"]

#: size of the summary image [px] (width, height)
SIZE_PX = (1800, 1050)
_DPI = 150
_BOUND = re.compile(r"^(plus|minus)_(\d+(?:\.\d+)?)sigma$")
_FILE_MESSAGE = re.compile(r"\.(csv|toml|npz|json)\b")
_MAX_POINTS = 4000


def _thin(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if len(t) <= _MAX_POINTS:
        return t, v
    i = np.unique(np.linspace(0, len(t) - 1, _MAX_POINTS).astype(int))
    return t[i], v[i]


def _names(data: RecordingData, entity: str, k: int) -> list[str]:
    try:
        n = data.static_component(entity, "SeriesLines:names")
        if len(n) == k:
            return [str(x) for x in n]
    except KeyError:
        pass
    base = entity.rsplit("/", 1)[-1]
    return [base] if k == 1 else [f"{base}[{i}]" for i in range(k)]


#: y labels (with units) of the generic panels that have one
_YLABEL = {
    layout.POST2_ROCKET_ALTITUDE: "altitude above the pad [m]",
    layout.POST2_ROCKET_VERTICAL_SPEED: "vertical speed, up + [m/s]",
    layout.POST2_ROCKET_SPEED: "speed, planet-relative [m/s]",
    layout.POST2_ROCKET_DOWNRANGE: "downrange from the pad [m]",
    layout.POST2_ROCKET_EAST: "east of the pad [m]",
    layout.POST2_ROCKET_NORTH: "north of the pad [m]",
}


def _plot_root(ax, data: RecordingData, root: str, ents: set[str]) -> int:
    """Draw every scalar series at or below ``root`` on ``ax``; returns how many were drawn."""
    below = sorted(e for e in ents if e == root or e.startswith(root + "/"))
    below = [e for e in below if "Scalars:scalars" in data.components(e)]
    groups: dict[str, list[str]] = {}
    for e in below:
        parent, _, leaf = e.rpartition("/")
        groups.setdefault(parent if e != root else root, []).append(e)
    drawn = 0
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    ci = 0
    for members in groups.values():
        leaves = {m.rpartition("/")[2]: m for m in members}
        est_leaf = next((x for x in (layout.VALUE, layout.SMOOTHED_SERIES) if x in leaves), None)
        bounds = sorted(
            (float(m.group(2)), leaf) for leaf in leaves if (m := _BOUND.match(leaf)) and m.group(1) == "plus"
        )
        band = None
        if est_leaf is not None and bounds:
            n, plus = bounds[-1]  # the widest band (3σ where both are logged)
            minus = layout.bound_names(n)[1]
            if minus in leaves:
                band = (leaves[plus], leaves[minus], n)
        for leaf, e in leaves.items():
            if _BOUND.match(leaf):
                continue
            try:
                t, v = data.scalars(e)
            except (KeyError, ValueError):
                continue
            if not len(t):
                continue
            names = _names(data, e, v.shape[1])
            for j in range(v.shape[1]):
                tt, vv = _thin(t, v[:, j])
                c = colours[(ci + j) % len(colours)]
                if leaf == est_leaf:
                    ax.plot(tt, vv, color=c, lw=1.4, label=names[j])
                elif leaf == layout.TRUTH_SERIES:
                    ax.plot(tt, vv, color=c, lw=1.0, ls="--", alpha=0.8, label=names[j])
                else:
                    ax.plot(tt, vv, lw=0.8, alpha=0.7, label=names[j])
                drawn += 1
            if leaf == est_leaf and band is not None:
                tp, p = data.scalars(band[0])
                tm, m = data.scalars(band[1])
                if np.array_equal(tp, tm) and p.shape == m.shape:
                    for j in range(p.shape[1]):
                        tt, pp = _thin(tp, p[:, j])
                        _, mm = _thin(tm, m[:, j])
                        ax.fill_between(
                            tt,
                            mm,
                            pp,
                            color=colours[(ci + j) % len(colours)],
                            alpha=0.18,
                            lw=0,
                            label=f"±{band[2]:g}σ" if j == 0 else None,
                        )
            if leaf == est_leaf:
                ci += v.shape[1]
    return drawn


def _zoom_window(data: RecordingData, names: tuple[str, str]) -> tuple[float, float] | None:
    """The span [s] between two key moments of the recording, with 0.1 s before and 0.2 s after
    (the drop test's impact); None when either is missing."""
    from workbench.recording.moments import read_key_moments

    try:
        t = {m.name: m.t_s for m in read_key_moments(data)}
    except Exception:  # noqa: BLE001 - a recording without moments: no zoom
        return None
    if names[0] not in t or names[1] not in t or not t[names[1]] > t[names[0]]:
        return None
    return t[names[0]] - 0.1, t[names[1]] + 0.2


def _zoom(ax, t0: float, t1: float) -> None:
    """Limit ``ax`` to [t0, t1] [s] and its y range to the lines drawn there."""
    ys = []
    for line in ax.get_lines():
        x, y = (np.asarray(v, float) for v in line.get_data())
        if x.size == y.size and x.size:
            m = (x >= t0) & (x <= t1) & np.isfinite(y)
            ys.append(y[m])
    for coll in ax.collections:  # the ±nσ bands
        for path in coll.get_paths():
            v = path.vertices
            m = (v[:, 0] >= t0) & (v[:, 0] <= t1) & np.isfinite(v[:, 1])
            ys.append(v[m, 1])
    y = np.concatenate(ys) if ys else np.array([])
    ax.set_xlim(t0, t1)
    if y.size:
        pad = 0.05 * max(float(np.ptp(y)), 1e-9)
        ax.set_ylim(float(y.min()) - pad, float(y.max()) + pad)


def render_png(
    recording: str | os.PathLike[str] | RecordingData,
    out: str | os.PathLike[str],
    *,
    kind: str | None = None,
    headline: str | None = None,
) -> Path:
    """Write the one-page summary image of a run recording to ``out`` (PNG, :data:`SIZE_PX`).

    ``kind``: whose key plots (default: the recording's ``run`` property); ``headline``: the
    run's one-line result for the title (default: the scorecard's first line). Panels whose
    series the recording lacks say so instead of staying blank. Returns the path.
    """
    data = recording if isinstance(recording, RecordingData) else read_recording(recording)
    kind = kind or str(data.properties().get("run", {}).get("kind", ""))
    ents = set(data.entities())
    pres = PRESENTATIONS.get(kind)
    if pres is not None and pres.plots:
        panels = [(title, root, ylabel) for title, root, ylabel, _ in pres.plots]
    else:
        roots = []
        for e in sorted(ents):
            if e.startswith(layout.PLOTS + "/") and _BOUND.match(e.rpartition("/")[2]):
                r = e.rpartition("/")[0]
                if r not in roots:
                    roots.append(r)
        # a rocket flight's pad-frame plots first, in their reading order (altitude, speeds, position)
        first = [r for r in layout.POST2_ROCKET_PLOTS if r in roots]
        roots = first + [r for r in roots if r not in first]
        panels = [(r[len(layout.PLOTS) + 1 :], r, _YLABEL.get(r, r.rsplit("/", 1)[-1])) for r in roots[:6]]
    try:
        events = [
            (float(te), s)
            for te, s, lv in data.text_log()
            if (lv or "INFO") in ("INFO", "WARN") and not _FILE_MESSAGE.search(s)
        ]
    except KeyError:
        events = []
    fig, axes = plt.subplots(2, 3, figsize=(SIZE_PX[0] / _DPI, SIZE_PX[1] / _DPI), dpi=_DPI)
    zoom = _zoom_window(data, pres.zoom) if pres is not None and pres.zoom else None
    for k, (ax, (title, root, ylabel)) in enumerate(zip(axes.flat, panels, strict=False)):
        n = _plot_root(ax, data, root, ents)
        if k == 0 and zoom is not None and n:
            _zoom(ax, *zoom)
        ax.set_title(title, fontsize=10)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.set_xlabel("time [s]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if n == 0:
            ax.text(0.5, 0.5, f"not in this recording:\n{root}", ha="center", va="center", transform=ax.transAxes)
            continue
        lo, hi = ax.get_xlim()
        for te, _ in events:
            if lo <= te <= hi:
                ax.axvline(te, color="0.5", lw=0.6, ls=":")
        handles, labels = ax.get_legend_handles_labels()
        keep = [(h, lab) for h, lab in zip(handles, labels, strict=True) if not lab.endswith("truth")]
        bands = [(h, lab) for h, lab in keep if lab.startswith("±")]
        keep = [(h, lab) for h, lab in keep if not lab.startswith("±")] + bands[:1]
        if len(keep) < len(labels):
            keep.append((plt.Line2D([], [], color="0.3", ls="--", lw=1.0), "truth (dashed)"))
        if keep and len(keep) <= 9:
            ax.legend(*zip(*keep, strict=True), fontsize=6, loc="best", framealpha=0.6)
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    head = headline or ""
    if not head:
        try:
            report = data.text_document(layout.REPORT)
            lines = [ln.strip("# *").rstrip(" \\").strip() for ln in report.splitlines() if ln.strip()]
            # the scorecard opens with the verdict block: "Health: …", then the headline
            head = lines[1] if len(lines) > 1 and lines[0].startswith("Health:") else (lines[0] if lines else "")
        except KeyError:
            pass
    title, subtitle = replay_titles(data, kind)
    names = ", ".join(" ".join(s.split(" (")[0].split()[:3]) for _, s in events[:10])
    text = [textwrap.shorten(title, 150, placeholder=" …"), textwrap.shorten(subtitle, 170, placeholder=" …")]
    text += textwrap.wrap(head, 160, max_lines=2, placeholder=" …")
    if names:
        text.append(textwrap.shorten(f"dotted lines: events ({names})", 170, placeholder=" …"))
    fig.suptitle("\n".join(text), fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.022 * len(text)))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=_DPI)
    plt.close(fig)
    return out
