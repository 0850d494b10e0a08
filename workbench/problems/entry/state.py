"""The entry error-state layout, named once: ``[δv_M, δθ_G, δp_M]`` (9,), the order of every
covariance the entry package produces (strapdown, dispersion, smoother, validation).

``δv_M`` [m/s] inertial velocity error (MMED), ``δθ_G`` [rad] body-frame small angle
(``q_true = q ⊗ exp(δθ)``), ``δp_M`` [m] position error (MMED); AMELIA Sects. 5-8.
"""

from __future__ import annotations

__all__ = ["EntryStateLayout", "STATE", "DV", "DTH", "DP", "N_ERR"]


class EntryStateLayout:
    """Slices of the 9-element entry error state (read-only class attributes): ``v`` velocity,
    ``theta`` attitude, ``p`` position (3 each, in that order); ``n`` its length."""

    __slots__ = ()
    v = slice(0, 3)
    theta = slice(3, 6)
    p = slice(6, 9)
    n = 9


#: The layout of every entry covariance.
STATE = EntryStateLayout()
#: Shorthands of :data:`STATE`'s slices (velocity, attitude, position) and its length.
DV, DTH, DP, N_ERR = STATE.v, STATE.theta, STATE.p, STATE.n
