"""The entry health's physics cross-checks on small arrays: the drag along the declared axis, the
radar's first lock against the inertial prediction, the telemetry gaps against the key events.
The same checks on the shipped run (clean) and on mutated telemetry: ``test_pipeline.py``."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.problems.entry.health import (
    DRAG_AXIS_MIN_COS,
    drag_axis_check,
    gap_checks,
    radar_first_lock_check,
)
from workbench.problems.entry.telemetry import StreamGap


def _drag(n: int = 400, tilt_deg: float = 5.0, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A drag pulse along +Z_G with the aerodynamic force tilted by up to ``tilt_deg`` in a
    spinning direction, plus mm/s² noise: (t (n,), f_G (n, 3))."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 200.0, n)
    mag = 80.0 * np.exp(-(((t - 80.0) / 40.0) ** 2)) + 1.0
    a = np.radians(tilt_deg) * np.sin(t)
    phi = np.radians(16.0) * t
    f = mag[:, None] * np.column_stack([np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi), np.cos(a)])
    return t, f + 1e-3 * rng.standard_normal(f.shape)


def test_drag_along_the_declared_axis_is_ok():
    t, f = _drag()
    c = drag_axis_check(t, f)
    assert c.status == "OK" and c.value > 0.99


@pytest.mark.parametrize(
    ("M", "along"),
    [
        (np.diag([1.0, -1.0, -1.0]), "−Z_G"),  # body frame turned 180° about X
        (np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]), "+X_G"),  # X and Z swapped
        (np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]), "−Y_G"),  # 90° about X
    ],
    ids=["flip_x", "swap_xz", "rot90_x"],
)
def test_drag_along_another_axis_is_an_error_naming_it(M, along):
    t, f = _drag()
    c = drag_axis_check(t, f @ M.T, "gnc.csv")
    assert c.status == "ERROR" and c.value < DRAG_AXIS_MIN_COS
    assert f"lies along {along}" in c.message and "gnc.csv" in c.message and "declares +Z_G" in c.message


def test_drag_check_needs_drag():
    t, f = _drag()
    assert drag_axis_check(t, 1e-3 * f).status == "WARNING"


class _Innov:
    def __init__(self, z, zp, s):
        self.t = np.array([225.5, 225.6])
        self.z = np.array([[z], [z]])
        self.z_pred = np.array([[zp], [zp]])
        self.S = np.full((2, 1, 1), s**2)


@pytest.mark.parametrize(
    ("z", "status", "unit"),
    [(7642.0, "OK", None), (7642.0 / 0.3048, "ERROR", "ft"), (7.642, "ERROR", "km"), (30000.0, "ERROR", None)],
    ids=["clean", "feet", "km", "factor4"],
)
def test_radar_first_lock(z, status, unit):
    c = radar_first_lock_check(_Innov(z, 9069.0, 4200.0), "rda_out.csv")
    assert c.status == status, c.message
    if unit:
        assert f"look like [{unit}], not [m]" in c.message
    elif status == "ERROR":
        assert "rda_out.csv" in c.message


def test_gaps_away_from_key_events_are_notes_and_across_them_warnings():
    win = {"PDD": (179.98, 180.98), "peak deceleration": (33.7, 91.0), "radar lock": (225.0, 226.0)}
    gaps = [
        StreamGap("/x/gnc.csv", 22.9, 24.3, 381),
        StreamGap("/x/gnc.csv", 33.7, 90.9, 427),
        StreamGap("/x/gnc_nav.csv", 33.0, 91.0, 43),
    ]
    checks, notes = gap_checks(gaps, win)
    c = {k.name: k for k in checks}
    assert all(k.status == "OK" for k in checks)
    assert "undefined" in c["gaps.peak_deceleration"].message
    assert sum("away from the key events" in n for n in notes) == 2 and any("undefined" in n for n in notes)
    # a GNC gap across PDD and a radar gap across the lock: WARNINGs naming the file and the event
    checks, _ = gap_checks(
        [StreamGap("/x/gnc.csv", 180.0, 181.5, 1500), StreamGap("/x/rda_out.csv", 225.2, 226.4, 2)], win
    )
    c = {k.name: k for k in checks}
    assert c["gaps.PDD"].status == "WARNING" and "gnc.csv" in c["gaps.PDD"].message
    assert "outputs are undefined" in c["gaps.PDD"].message
    assert c["gaps.radar_lock"].status == "WARNING" and "rda_out.csv" in c["gaps.radar_lock"].message
