"""Entity paths and timeline names of a workbench recording (docs/RECORDING.md).

Every pipeline and the reader name entities through this module, so the layout lives in one
place. Paths are absolute Rerun entity paths (leading ``/``). Names of path parts given by callers
(quantities, sensors, channels) must be plain words: letters, digits, ``_``, ``-`` and ``.``; a
``/`` inside ``quantity`` nests the plot (``"velocity/north"`` → ``/plots/velocity/north``).

Timelines:

* ``time`` (duration): float seconds from the scenario's reference event (release, entry interface),
  stored as integer nanoseconds;
* ``step`` (sequence): filter sample index;
* ``iteration`` (sequence): iteration of an iterative solver (Gauss-Newton, drag-coefficient loop);
* ``sample`` (sequence): Monte Carlo member.

This module does not import rerun; it is plain strings.
"""

from __future__ import annotations

import re

__all__ = [
    "APPLICATION_ID",
    "TIME",
    "STEP",
    "ITERATION",
    "SAMPLE",
    "WORLD",
    "SURFACE",
    "VEHICLE",
    "VEHICLE_BODY",
    "AIRBAGS",
    "RADAR",
    "UNCERTAINTY",
    "ESTIMATE",
    "ESTIMATE_FORWARD",
    "ESTIMATE_SMOOTHED",
    "TRUTH",
    "STROKE",
    "DISPERSION",
    "PLOTS",
    "RESIDUALS",
    "SENSORS",
    "EVENTS",
    "REPORT",
    "VALUE",
    "TRUTH_SERIES",
    "join",
    "part",
    "bound_names",
    "radar_beam_path",
    "truth_path",
    "plot_path",
    "residual_path",
    "sensor_path",
]

APPLICATION_ID = "edl-workbench"
"""Application id of every recording; a blueprint only applies to recordings with the same id."""

# timelines
TIME = "time"
STEP = "step"
ITERATION = "iteration"
SAMPLE = "sample"

# 3D scene
WORLD = "/world"
SURFACE = "/world/surface"
VEHICLE = "/world/vehicle"
VEHICLE_BODY = "/world/vehicle/body"
AIRBAGS = "/world/vehicle/airbags"
RADAR = "/world/vehicle/radar"
UNCERTAINTY = "/world/vehicle/uncertainty"
ESTIMATE = "/world/estimate"
ESTIMATE_FORWARD = "/world/estimate/forward"
ESTIMATE_SMOOTHED = "/world/estimate/smoothed"
TRUTH = "/world/truth"
STROKE = "/world/stroke"
DISPERSION = "/world/dispersion"

# plots and text
PLOTS = "/plots"
RESIDUALS = "/residuals"
SENSORS = "/sensors"
EVENTS = "/events"
REPORT = "/report"

# leaf names under a plot / residual root
VALUE = "value"
TRUTH_SERIES = "truth"

_PART = re.compile(r"^[\w.\-]+$")


def part(name: str) -> str:
    """Check one entity-path part (no ``/``) and return it; raise ``ValueError`` if it needs escaping."""
    if not isinstance(name, str) or not _PART.match(name):
        raise ValueError(f"entity path part {name!r} must be non-empty letters, digits, '_', '-' or '.'")
    return name


def join(root: str, *parts: str) -> str:
    """Join ``root`` (an absolute path) and checked parts; each part may contain ``/`` to nest."""
    out = root.rstrip("/")
    for p in parts:
        for q in str(p).split("/"):
            out += "/" + part(q)
    return out


def bound_names(nsigma: float = 3.0) -> tuple[str, str]:
    """Leaf names of the upper and lower bound series, e.g. ``("plus_3sigma", "minus_3sigma")``."""
    return f"plus_{nsigma:g}sigma", f"minus_{nsigma:g}sigma"


def radar_beam_path(beam: int | str) -> str:
    """``/world/vehicle/radar/B<beam>`` for an integer beam index, or ``/world/vehicle/radar/<beam>``."""
    return join(RADAR, f"B{beam}" if isinstance(beam, int) else beam)


def truth_path(sub: str) -> str:
    """``/world/truth/<sub>``: the truth counterpart of a scene entity (synthetic scenarios only)."""
    return join(TRUTH, sub)


def plot_path(quantity: str) -> str:
    """``/plots/<quantity>``: root of one plotted quantity (children value, plus_3sigma, ...)."""
    return join(PLOTS, quantity)


def residual_path(sensor: str, channel: str) -> str:
    """``/residuals/<sensor>/<channel>``: root of one measurement residual and its ±nσ bounds."""
    return join(RESIDUALS, sensor, channel)


def sensor_path(sensor: str, channel: str) -> str:
    """``/sensors/<sensor>/<channel>``: raw telemetry of one channel, as read."""
    return join(SENSORS, sensor, channel)
