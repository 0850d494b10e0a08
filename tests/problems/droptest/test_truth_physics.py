"""Physical sanity of the drop-test truth simulator itself: what every reconstruction is judged against."""

from __future__ import annotations

import numpy as np

from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems.droptest import truth, truth_fast
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.surface import ramp_surface
from workbench.problems.droptest.synthetic import truth_for

RAMP = ramp_surface(angle_deg=60.0, nail_depth=0.3)  # the SPF ramp
N_RAMP = np.asarray(RAMP.normal, float)
T1, T2 = (np.asarray(v, float) for v in RAMP.tangent_basis())


def _lens(d: float, r1: float, r2: float) -> float:
    """Overlap area [m²] of two disks of radii r1, r2 [m] with centres d [m] apart (closed form)."""
    if d <= abs(r1 - r2):
        return np.pi * min(r1, r2) ** 2
    if d >= r1 + r2:
        return 0.0
    c1 = (d * d + r1 * r1 - r2 * r2) / (2 * d * r1)
    c2 = (d * d + r2 * r2 - r1 * r1) / (2 * d * r2)
    k = (-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2)
    return r1 * r1 * np.arccos(c1) + r2 * r2 * np.arccos(c2) - 0.5 * np.sqrt(k)


def _in_plane(xy: np.ndarray) -> np.ndarray:
    """Points (k, 3) [m] of the ramp plane through 0.3 n from plane coordinates xy (k, 2) [m]."""
    return xy[:, :1] * T1 + xy[:, 1:] * T2 + 0.3 * N_RAMP


def test_two_footprints_share_their_lens_equally():
    """Two overlapping footprints: each is its disk minus half the lens, to 1.5 % of the disk."""
    worst = 0.0
    for d in np.linspace(0.0, 2.0, 41):
        for r2 in (0.2, 0.6, 1.0):
            a = np.array([0.8, r2])
            out = np.empty(2)
            truth_fast.footprint_areas(_in_plane(np.array([[0.0, 0.0], [d, 0.0]])), a, T1, T2, out)
            exact = np.pi * a**2 - 0.5 * _lens(d, 0.8, r2)
            worst = max(worst, float(np.max(np.abs(out - exact) / (np.pi * a**2))))
    assert worst < 0.015


def test_stacked_footprints_share_their_union():
    """Nine nearly coincident footprints (lobes of several bags pressed at one place): every area is
    positive and the areas sum to the union's area (a 400 000-point Monte Carlo of it, ±1 %)."""
    rng = np.random.default_rng(7)
    xy = rng.normal(0.0, 0.15, (9, 2))
    a = rng.uniform(0.7, 1.0, 9)
    out = np.empty(9)
    truth_fast.footprint_areas(_in_plane(xy), a, T1, T2, out)
    pts = rng.uniform(-1.6, 1.6, (400_000, 2))
    covered = (np.linalg.norm(pts[:, None, :] - xy[None], axis=-1) < a).any(1)
    union = covered.mean() * 3.2**2
    assert np.all(out > 0.05 * np.pi * a**2)
    assert abs(out.sum() - union) < 0.01 * union


def test_footprint_areas_match_reference():
    """The compiled footprint shares and the numpy reference agree to rounding (random layouts)."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        k = int(rng.integers(1, 12))
        xy = rng.normal(0.0, 0.5, (k, 2))
        a = rng.uniform(0.05, 1.0, k)
        out = np.empty(k)
        truth_fast.footprint_areas(_in_plane(xy), a, T1, T2, out)
        np.testing.assert_allclose(out, truth.footprint_areas(_in_plane(xy), a, T1, T2), rtol=0, atol=1e-12)


def test_pressed_bags_always_push():
    """Regression of the half-lens rule: it subtracted half of every pairwise overlap, so where lobes
    of several bags pressed at nearly the same place every area clipped to zero (droptest's own drop
    had 25 ms with 9 lobes pressed up to a full radius and no bag force)."""
    settings = DropTestProblem().settings(resolve_scenario("droptest", assets_dir()))
    tr, _, _ = truth_for(settings)
    pressed = tr.lobe_penetration.max(axis=1) > 0.1  # some lobe more than 10 cm into the ramp [m]
    assert pressed.any()
    # a gas bag pressed into the ramp pushes with its gauge pressure over its footprint, never zero
    assert np.all(tr.contact_force[pressed] > 0.0)
