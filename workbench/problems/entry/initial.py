"""The initial state of the radar-aided smoother (AMELIA Sects. 5–7): the navigation prior of
Table 3 ("Reconstruction" column) and the start chosen by ``[reconstruction] initial``.

Shared by the reconstruction (:mod:`workbench.problems.entry.pipeline`) and the smoother
validation (:mod:`workbench.problems.entry.montecarlo`), so both start the smoother the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from workbench.problems.entry.dispersion import fuse_with_prior

if TYPE_CHECKING:
    from workbench.problems.entry.config import ReconstructionSettings

__all__ = ["SmootherStart", "reconstruction_P0", "initial_for_smoother"]


@dataclass(frozen=True)
class SmootherStart:
    """Initial state of the radar-aided smoother: ``mode`` ("fused", "dispersion" or "nominal"), state
    ``v0`` [m/s], ``q0`` (``q_M_G``), ``p0`` [m] (MMED), covariance ``P0`` (9, 9), and a note."""

    mode: str
    v0: np.ndarray
    q0: np.ndarray
    p0: np.ndarray
    P0: np.ndarray
    note: str


def reconstruction_P0(config: ReconstructionSettings) -> np.ndarray:
    """Navigation prior covariance (9, 9) from the ``[reconstruction]`` velocity [m/s], attitude
    [deg → rad], position [m] 1σ (AMELIA Table 3, "Reconstruction" column); order v, δθ, p."""
    s_v = config.sigma_velocity_mps
    s_a = np.radians(config.sigma_attitude_deg)
    s_p = config.sigma_position_m
    return np.diag(np.r_[np.full(3, s_v**2), np.full(3, s_a**2), np.full(3, s_p**2)])


def initial_for_smoother(config: ReconstructionSettings, disp, nom, P_nav: np.ndarray) -> SmootherStart:
    """The smoother's initial state from ``config.initial`` (``[reconstruction] initial``).

    ``disp`` the :class:`~workbench.problems.entry.dispersion.DispersionResult`; ``nom`` the nominal
    state (attributes ``v_M``, ``q_M_G``, ``p_M``); ``P_nav`` (9, 9) the navigation prior.
    "dispersion": the paper's refined state (mean and spread of the accepted members);
    "fused": that constraint combined with the navigation prior ``P_nav`` about the nominal
    (:func:`~workbench.problems.entry.dispersion.fuse_with_prior`);
    "nominal": the nominal state with ``P_nav``.  Falls back to "nominal" (with a note) when fewer
    than 10 members were accepted.
    """
    mode = config.initial
    n_acc = int(np.sum(disp.accepted))
    if mode != "nominal" and n_acc < 10:
        return SmootherStart("nominal", nom.v_M, nom.q_M_G, nom.p_M, P_nav, f"only {n_acc} accepted: nominal used")
    if mode == "dispersion":
        return SmootherStart(mode, disp.refined_v0, disp.refined_q0, disp.refined_p0, disp.refined_P0, "")
    if mode == "nominal":
        return SmootherStart(mode, nom.v_M, nom.q_M_G, nom.p_M, P_nav, "")
    f = fuse_with_prior(disp, nom.v_M, nom.q_M_G, nom.p_M, P_nav)
    return SmootherStart(mode, f.v0, f.q0, f.p0, f.P0, f"rules constrain {f.constrained_dims} of 9 directions")
