"""The entry state layouts, named once (AMELIA Sects. 5-8).

Error state ``e = [δv_M, δθ_G, δp_M]`` (9,), the order of every covariance the entry package
produces (strapdown, dispersion, smoother, validation): ``δv_M`` [m/s] inertial velocity error
(MMED), ``δθ_G`` [rad] body-frame small angle (``q_true = q ⊗ exp(δθ)``), ``δp_M`` [m] position
error (MMED).  Full filter state ``x = [v_M, q_M_G, p_M]`` (10,), the quaternion scalar-last.
"""

from __future__ import annotations

__all__ = ["EntryStateLayout", "STATE", "DV", "DTH", "DP", "N_ERR", "XV", "XQ", "XP", "N_X"]


class EntryStateLayout:
    """Slices of the entry states (read-only class attributes).  Error state (9,): ``v``
    velocity, ``theta`` attitude, ``p`` position (3 each), ``n`` its length; full state (10,):
    ``x_v`` velocity, ``x_q`` quaternion (4), ``x_p`` position, ``n_x`` its length."""

    __slots__ = ()
    v = slice(0, 3)
    theta = slice(3, 6)
    p = slice(6, 9)
    n = 9
    x_v = slice(0, 3)
    x_q = slice(3, 7)
    x_p = slice(7, 10)
    n_x = 10


#: The layout of every entry state and covariance.
STATE = EntryStateLayout()
#: Shorthands of :data:`STATE`: error-state slices (velocity, attitude, position) and length ...
DV, DTH, DP, N_ERR = STATE.v, STATE.theta, STATE.p, STATE.n
#: ... and full-state slices (velocity, quaternion, position) and length.
XV, XQ, XP, N_X = STATE.x_v, STATE.x_q, STATE.x_p, STATE.n_x
