"""The heat-shield view's port names: apart from each other as the view's camera sees them (fast)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from workbench.io.assets import assets_dir
from workbench.models.flush_airdata import load_fads_vehicle
from workbench.problems.meads.recording import LABEL_RING_M, SCENE_EYE, SCENE_LOOK, port_label_points


def _ports_B():
    v = load_fads_vehicle(assets_dir() / "vehicles" / "msl_meads.toml")
    r, c = v.radius(), v.clock()
    x = -v.surface_axial(r)
    return v, np.stack([x, r * np.sin(c), r * np.cos(c)], 1)


def _screen(points_ENU: np.ndarray) -> np.ndarray:
    """(…, 3) ENU points -> (…, 2) in the camera's image plane (perspective, focal length 1)."""
    eye, look = np.asarray(SCENE_EYE), np.asarray(SCENE_LOOK)
    fwd = (look - eye) / np.linalg.norm(look - eye)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    d = points_ENU - eye
    return np.stack([d @ right, d @ up], -1) / (d @ fwd)[..., None]


def test_port_names_are_apart_on_screen_at_every_attitude():
    """0.3 m in front of their ports, P3/P4/P5 (around the nose) and P1/P2/P3 (one clock ray) were
    written over each other; now every pair is at least the circle's chord apart on screen, outside
    the shield, and each name is on its port's side of the nose."""
    v, P = _ports_B()
    m = len(v.ports)
    rng = np.random.default_rng(28)
    # random attitudes, then a slow continuous turn (the hysteresis path)
    quats = np.concatenate(
        [
            Rotation.random(200, random_state=rng).as_quat(),
            Rotation.from_rotvec(np.linspace(0, 3, 300)[:, None] * [0.3, 0.8, 0.5]).as_quat(),
        ]
    )
    lab_B = port_label_points(P, quats)
    assert lab_B.shape == (len(quats), m, 3)
    rot = Rotation.from_quat(np.repeat(quats, m, axis=0))
    lab = rot.apply(lab_B.reshape(-1, 3)).reshape(-1, m, 3)
    ports = rot.apply(np.tile(P, (len(quats), 1))).reshape(-1, m, 3)
    s = _screen(lab)
    depth = np.linalg.norm(np.asarray(SCENE_EYE) - np.asarray(SCENE_LOOK))
    chord = 2 * LABEL_RING_M * math.sin(math.pi / m) / depth
    gaps = np.linalg.norm(s[:, :, None] - s[:, None, :], axis=-1) + np.eye(m) * 1e9
    assert gaps.min() > 0.95 * chord
    # the names sit on the circle, outside the shield's outline (radius 2.25 m, depth 0.7 m)
    np.testing.assert_allclose(np.linalg.norm(lab, axis=-1), LABEL_RING_M, rtol=1e-9)
    # each name on its port's side of the nose, as seen, for ports seen > 1 m from the nose
    fwd = (np.asarray(SCENE_LOOK) - np.asarray(SCENE_EYE)) / depth
    perp = ports - (ports @ fwd)[..., None] * fwd
    far = np.linalg.norm(perp, axis=-1) > 1.0
    cos = np.sum(perp[far] * lab[far], -1) / np.linalg.norm(perp[far], axis=-1) / LABEL_RING_M
    assert far.sum() > 300 and np.all(cos > 0.0)
