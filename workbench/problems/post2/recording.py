"""The post2 recording: observations as read, residuals with ±3σ, every estimated state with ±3σ (and
the truth when synthetic), the vehicle track in 3-D, the scorecard.

Drawn through :class:`workbench.recording.writer` and the entity paths of
:mod:`workbench.recording.layout`; a :class:`~workbench.recording.dispatch.StageDispatch` maps each
stage type to its handler (an unknown stage is a ``TypeError``).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from workbench.problems.post2.model import OBSERVATIONS, STATES
from workbench.problems.post2.pipeline import ForwardStage, ObservationData, Post2Result
from workbench.problems.post2.scoring import truth_on_grid
from workbench.recording import layout
from workbench.recording.blueprint import standard_blueprint
from workbench.recording.dispatch import StageDispatch
from workbench.recording.writer import open_recording

__all__ = ["Post2Drawer", "open_post2_recording", "COMPONENTS"]

#: component names of the state blocks in the plots
COMPONENTS = {
    "position": ("x", "y", "z"),
    "velocity": ("x", "y", "z"),
    "attitude": ("alpha", "beta", "bank"),
    "body_rates": ("p", "q", "r"),
    "accel_bias": ("x", "y", "z"),
}


class Post2Drawer:
    """Draws the post2 stages; ``truth`` (the loaded truth.npz dict) or None."""

    def __init__(self, rec, truth, scorecard):
        self.rec, self.truth, self.scorecard = rec, truth, scorecard
        self.handle = StageDispatch(
            {ObservationData: self._data, ForwardStage: self._forward, Post2Result: self._result}
        )

    def _data(self, stage: ObservationData) -> None:
        for name, ch in stage.channels.items():
            comps = OBSERVATIONS[ch.spec.quantity].components
            for i, c in enumerate(comps):
                self.rec.scalars(layout.join(layout.sensor_path(name, c), layout.MEASURED_SERIES), ch.t, ch.z[:, i])

    def _forward(self, stage: ForwardStage) -> None:
        fp = stage.forward
        for name, ih in fp.innovations.items():
            comps = OBSERVATIONS[stage.quantities[name]].residual_names
            for i, c in enumerate(comps):
                sd = np.sqrt(np.maximum(ih.S[:, i, i], 0.0))
                self.rec.series_with_bounds(layout.residual_path(name, c), ih.t, ih.y[:, i], sd)
        if stage.events:
            self.rec.events([(t, name, "INFO") for t, name in stage.events])

    def _result(self, res: Post2Result) -> None:
        tg = truth_on_grid(self.truth, res.t) if self.truth is not None else {}
        for name, h in res.history["smoothed"].items():
            k = 180.0 / np.pi if STATES[name].unit in ("deg", "deg/s") else 1.0
            comps = COMPONENTS.get(name, ("value",))
            v, s = h["value"] * k, h["sigma"] * k
            truth = None
            if name in tg:
                truth = tg[name] * k
            elif self.truth is not None and f"param_{name}" in self.truth:
                truth = np.broadcast_to(np.atleast_1d(self.truth[f"param_{name}"]) * k, v.shape)
            if name in ("position", "velocity") and truth is not None:  # errors: values are too large to read
                v, truth = v - truth, np.zeros_like(v)
                name = f"{name}_error"
            for i, c in enumerate(comps):
                self.rec.series_with_bounds(
                    layout.plot_path(f"{name}/{c}"),
                    res.t,
                    v[:, i],
                    s[:, i],
                    truth=None if truth is None else truth[:, i],
                )
        p = res.smap.raw(res.x, "position")
        self.rec.line_strip(layout.join(layout.ESTIMATE_SMOOTHED, "track"), p, color=(60, 140, 255, 255))
        pf = res.smap.raw(res.forward.x_post, "position")
        self.rec.line_strip(layout.join(layout.ESTIMATE_FORWARD, "track"), pf, color=(255, 160, 40, 255))
        if self.truth is not None and "position" in self.truth:
            self.rec.line_strip(layout.truth_path("track"), self.truth["position"], color=(120, 220, 120, 255))

    def finish(self, result: object, summary: dict) -> None:
        """Write the scorecard."""
        self.rec.report(self.scorecard(summary))


def post2_blueprint(state_names: list[str], observation_names: list[str], has_truth: bool):
    """The default layout: the 3D tracks; one plot tab per estimated state (value with ±3σ and the
    truth; position and velocity as errors against the truth when it is known) and one residual tab
    per observation (residual with ±3σ); the scorecard and the event log."""
    plots = []
    for n in state_names:
        shown = f"{n}_error" if has_truth and n in ("position", "velocity") else n
        plots.append((shown, layout.plot_path(shown)))
    residuals = [(n, layout.residual_path(n)) for n in observation_names]
    return standard_blueprint(plots=plots, residuals=residuals)


@contextlib.contextmanager
def open_post2_recording(path: Path, name: str, truth, properties: dict, scorecard, *, states=(), observations=()):
    """Open the recording (published atomically) and yield its :class:`Post2Drawer`.

    ``states`` / ``observations``: the problem file's estimated-state and observation names, for the
    default layout (:func:`post2_blueprint`)."""
    bp = post2_blueprint(list(states), list(observations), truth is not None)
    with open_recording(path, name, blueprint=bp, properties=properties) as rec:
        yield Post2Drawer(rec, truth, scorecard)
