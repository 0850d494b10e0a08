"""Error-state extended Kalman filter: layout of the error state, predict, update, forward driver.

Plain functions over numpy arrays (pyins 1.0 style); every intermediate of a step is exposed under
the filterpy names ``x_prior``, ``P_prior``, ``y``, ``S``, ``K``, ``x_post``, ``P_post``. The full
state ``x`` (n_x,) may hold unit quaternions; the covariance ``P`` (n_e, n_e) lives in the error
state, each quaternion a **body-frame** small angle δθ [rad] with ``q_true = q_est ⊗ exp(δθ)``
(:class:`ErrorStateLayout`; ``⊞``/``⊟``). The step follows the POST2 EKF thesis, Sect. 3.1.1:
nonlinear prediction, ``P`` propagated with the transition matrix plus ``Q``, residual observed
minus computed, gain ``K = P Hᵀ (H P Hᵀ + R)⁻¹``, covariance in Joseph form (Gelb 1974);
sensitivities not supplied are central differences of size ``eps`` per error-state entry. After an
update the error state is reset keeping ``P`` (``G ≈ I``, Markley & Crassidis 2014, Sect. 6.2.4).

:func:`update` / :class:`Measurement` / :func:`run_filter` also give χ² gating, the iterated update
(Bell & Cathey, IEEE TAC 38(2), 1993), gain projection for constrained directions (Simon 2006),
measurements carrying some components (``slots``) of a channel, a transition returning its own
process noise and the ``adapt_q`` hook (REDLand: Q raised on rapid acceleration changes).
Companions: :func:`workbench.estimation.grid.merge_time_tags`, :mod:`workbench.estimation.smoother`
and the compiled update :mod:`workbench.estimation.kernels`. References: Gelb, *Applied Optimal
Estimation*, 1974; POST2 EKF thesis, Ch. 3.1; Solà, "Quaternion kinematics for the error-state
Kalman filter", 2017; Bell & Cathey 1993.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from workbench.core.rotation import attitude_error, attitude_error_one, quat_boxplus, quat_boxplus_one, quat_normalize
from workbench.estimation.consistency import chi2_gate

__all__ = [
    "ErrorStateLayout",
    "Prediction",
    "UpdateResult",
    "Measurement",
    "InnovationHistory",
    "ForwardPass",
    "numeric_transition_jacobian",
    "numeric_measurement_jacobian",
    "numeric_jacobian_batched",
    "derived_with_sigma",
    "predict",
    "update",
    "run_filter",
    "apply_measurements",
]

_potrf = lapack.dpotrf
_potrs = lapack.dpotrs


# ---------------------------------------------------------------------------------------------
# layout
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ErrorStateLayout:
    """Where the unit quaternions sit in the full state and in the error state.

    ``n_x``: length of the full state ``x``.  ``quat_blocks``: pairs ``(i_x, i_e)``; each says that
    ``x[i_x:i_x+4]`` is a unit quaternion ``q_ref_body`` (scalar-last ``[x, y, z, w]``, Hamilton)
    whose error is ``e[i_e:i_e+3]``, a **body-frame** small angle δθ [rad] with
    ``q_true = q ⊗ exp(δθ)``.  All other entries are additive and map one-to-one, in increasing
    order, onto the remaining error-state entries (with the usual layout, the error index of an
    additive entry is its x index minus one per quaternion before it).  ``n_e = n_x − #quats``.

    Example (position, velocity, attitude, gyro bias): ``ErrorStateLayout(13, ((6, 6),))`` —
    ``x = [p(3), v(3), q(4), b(3)]``, ``e = [δp(3), δv(3), δθ(3), δb(3)]``.
    """

    n_x: int
    quat_blocks: tuple[tuple[int, int], ...] = ()
    _add_runs: tuple[tuple[slice, slice], ...] = field(init=False, repr=False, compare=False)
    _eye: np.ndarray = field(init=False, repr=False, compare=False)
    _plain: bool = field(init=False, repr=False, compare=False)
    _steps: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        blocks = tuple((int(a), int(b)) for a, b in self.quat_blocks)
        n_x = int(self.n_x)
        n_e = n_x - len(blocks)
        x_used = np.zeros(n_x, dtype=bool)
        e_used = np.zeros(max(n_e, 0), dtype=bool)
        for i_x, i_e in blocks:
            if i_x < 0 or i_x + 4 > n_x or x_used[i_x : i_x + 4].any():
                raise ValueError(f"quaternion block x[{i_x}:{i_x + 4}] is out of range or overlaps")
            if i_e < 0 or i_e + 3 > n_e or e_used[i_e : i_e + 3].any():
                raise ValueError(f"quaternion error block e[{i_e}:{i_e + 3}] is out of range or overlaps")
            x_used[i_x : i_x + 4] = True
            e_used[i_e : i_e + 3] = True
        xa = np.flatnonzero(~x_used)
        ea = np.flatnonzero(~e_used)
        if xa.size != ea.size:  # pragma: no cover - impossible by construction
            raise ValueError("inconsistent layout")
        runs: list[tuple[slice, slice]] = []
        i = 0
        while i < xa.size:
            j = i
            while j + 1 < xa.size and xa[j + 1] == xa[j] + 1 and ea[j + 1] == ea[j] + 1:
                j += 1
            runs.append((slice(int(xa[i]), int(xa[j]) + 1), slice(int(ea[i]), int(ea[j]) + 1)))
            i = j + 1
        object.__setattr__(self, "n_x", n_x)
        object.__setattr__(self, "quat_blocks", blocks)
        object.__setattr__(self, "_add_runs", tuple(runs))
        object.__setattr__(self, "_plain", not blocks)  # all additive: ⊞ is +, ⊟ is −
        object.__setattr__(self, "_steps", {})  # numeric_jacobian_batched's [diag(ε); −diag(ε)] per ε
        eye = np.eye(n_e)
        eye.flags.writeable = False
        object.__setattr__(self, "_eye", eye)

    @property
    def n_e(self) -> int:
        """Length of the error state (n_x minus one per quaternion)."""
        return self.n_x - len(self.quat_blocks)

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``x ⊞ dx``: x (..., n_x), dx (..., n_e) -> (..., n_x), broadcasting over leading dims.

        Additive entries: ``x + dx``; quaternions: ``q ⊗ exp(δθ)`` (body-frame δθ [rad]),
        renormalised.
        """
        x = np.asarray(x, dtype=float)
        dx = np.asarray(dx, dtype=float)
        if x.shape[-1] != self.n_x or dx.shape[-1] != self.n_e:
            raise ValueError(
                f"boxplus: expected x (..., {self.n_x}) and dx (..., {self.n_e}), got {x.shape} and {dx.shape}"
            )
        if self._plain:  # the additive entries' x + dx, broadcast (a new array)
            return x + dx
        if x.ndim == 1 and dx.ndim == 1:
            out = x.copy()
            for xs, es in self._add_runs:
                out[xs] += dx[es]
            for i_x, i_e in self.quat_blocks:
                out[i_x : i_x + 4] = quat_boxplus_one(x[i_x : i_x + 4], dx[i_e : i_e + 3])
            return out
        shape = np.broadcast_shapes(x.shape[:-1], dx.shape[:-1])
        out = np.array(np.broadcast_to(x, (*shape, self.n_x)), dtype=float)
        for xs, es in self._add_runs:
            out[..., xs] += dx[..., es]
        for i_x, i_e in self.quat_blocks:
            out[..., i_x : i_x + 4] = quat_boxplus(x[..., i_x : i_x + 4], dx[..., i_e : i_e + 3])
        return out

    def boxminus(self, x: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
        """``x ⊟ x_ref`` (..., n_e) such that ``x_ref ⊞ (x ⊟ x_ref) == x``; broadcasting.

        Additive entries: ``x − x_ref``; quaternions: ``attitude_error(q_ref, q)``, the body-frame
        small angle δθ [rad] with ``q = q_ref ⊗ exp(δθ)`` (shortest rotation, |δθ| ≤ π).
        """
        x = np.asarray(x, dtype=float)
        x_ref = np.asarray(x_ref, dtype=float)
        if x.shape[-1] != self.n_x or x_ref.shape[-1] != self.n_x:
            raise ValueError(f"boxminus: expected (..., {self.n_x}) arrays, got {x.shape} and {x_ref.shape}")
        if self._plain:
            return x - x_ref
        if x.ndim == 1 and x_ref.ndim == 1:
            out = np.empty(self.n_e)
            for xs, es in self._add_runs:
                out[es] = x[xs] - x_ref[xs]
            for i_x, i_e in self.quat_blocks:
                out[i_e : i_e + 3] = attitude_error_one(x_ref[i_x : i_x + 4], x[i_x : i_x + 4])
            return out
        shape = np.broadcast_shapes(x.shape[:-1], x_ref.shape[:-1])
        out = np.empty((*shape, self.n_e))
        for xs, es in self._add_runs:
            out[..., es] = x[..., xs] - x_ref[..., xs]
        for i_x, i_e in self.quat_blocks:
            out[..., i_e : i_e + 3] = attitude_error(x_ref[..., i_x : i_x + 4], x[..., i_x : i_x + 4])
        return out

    def normalize(self, x: np.ndarray) -> np.ndarray:
        """Copy of x (..., n_x) with every quaternion block scaled to unit norm."""
        out = np.array(x, dtype=float)
        for i_x, _ in self.quat_blocks:
            out[..., i_x : i_x + 4] = quat_normalize(out[..., i_x : i_x + 4])
        return out


# ---------------------------------------------------------------------------------------------
# stage results
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Prediction:
    """Result of :func:`predict`: ``x_prior`` (n_x,), ``P_prior`` (n_e, n_e), error-state ``F`` (n_e, n_e)."""

    x_prior: np.ndarray
    P_prior: np.ndarray
    F: np.ndarray


@dataclass(frozen=True)
class UpdateResult:
    """Result of :func:`update` (one measurement of size m).

    ``x_post`` (n_x,), ``P_post`` (n_e, n_e); ``y`` (m,) innovation ``residual(z, h(x_prior))``;
    ``S`` (m, m) its covariance ``H P Hᵀ + R``; ``K`` (n_e, m) gain; ``H`` (m, n_e) Jacobian w.r.t.
    the error state; ``nis = yᵀ S⁻¹ y`` (dimensionless); ``accepted`` False when the χ² gate
    rejected the measurement (then ``x_post is x`` and ``P_post is P``).  For an iterated update
    ``y``, ``S``, ``nis`` belong to the prior linearisation (the gate statistic), ``H`` and ``K``
    to the last iterate (the ones used in the Joseph covariance).  ``z_pred`` (m,) = ``h(x_prior)``.
    """

    x_post: np.ndarray
    P_post: np.ndarray
    y: np.ndarray
    S: np.ndarray
    K: np.ndarray
    H: np.ndarray
    nis: float
    accepted: bool
    z_pred: np.ndarray | None = None


@dataclass(frozen=True)
class Measurement:
    """One measurement offered to :func:`run_filter` at a step.

    ``name``: key of its :class:`InnovationHistory` (one size m per name); ``z`` (m,) observed
    value in SI units; ``R`` (m, m) noise covariance (the inverse of POST2's observation weight);
    ``h(x) -> z_pred`` (m,); ``H`` (m, n_e) array, callable ``H(x)``, or None for central
    differences; ``residual(z, z_pred) -> y`` (default ``z − z_pred``, give one for angles);
    ``gate_probability`` e.g. 0.9973 for a χ² gate, None for no gate; ``iterations`` > 1 for an
    iterated update; ``eps`` perturbation of the numeric H (scalar or (n_e,), error-state units);
    ``gain_projector``, ``step_tol``, ``gate_threshold``: the options of :func:`update`.
    ``slots`` (m,) int and ``size``: the measurement carries components ``slots`` of a channel of
    ``size`` components (e.g. the beams of a radar that returned); its record in the
    :class:`InnovationHistory` is NaN in the other components.  None: all components.
    """

    name: str
    z: np.ndarray
    R: np.ndarray
    h: Callable[[np.ndarray], np.ndarray]
    H: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None
    residual: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    gate_probability: float | None = None
    iterations: int = 1
    eps: float | np.ndarray = 1e-6
    gain_projector: Callable[[np.ndarray], np.ndarray] | None = None
    step_tol: np.ndarray | None = None
    gate_threshold: float | None = None
    slots: np.ndarray | None = None
    size: int | None = None


@dataclass(frozen=True)
class InnovationHistory:
    """Innovations of one named measurement channel at its k processed samples (m = its size).

    The one record type of both problems' filters (forward innovations and smoothed residuals).
    ``t`` (k,) [s] sample times; ``step`` (k,) int index of the grid step it was applied at (for
    a sample between grid steps, the step at or before it); ``z`` (k, m) measured, ``z_pred``
    (k, m) predicted ``h(x)`` (prior for a forward pass); ``y`` (k, m) innovation/residual
    ``residual(z, z_pred)``; ``S`` (k, m, m) its covariance ``H P Hᵀ + R``; ``nis`` (k,)
    ``yᵀ S⁻¹ y`` over the used components; ``accepted`` (k,) bool (False: gated out or not
    usable); ``K`` (k, n_e, m) gains if kept, else None.  A component not used at a sample (e.g.
    a radar beam off the terrain) is NaN in y, S, z_pred and K.  A step may hold several samples
    of one channel (samples are in processing order).
    """

    t: np.ndarray
    step: np.ndarray
    z: np.ndarray
    z_pred: np.ndarray
    y: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    accepted: np.ndarray
    K: np.ndarray | None = None

    @staticmethod
    def from_rows(rows: Sequence[tuple], m: int, n_e: int | None = None) -> InnovationHistory:
        """Stack per-sample rows ``(t, step, z, z_pred, y, S, nis, accepted[, K])`` of a channel of
        size m (gains kept when ``n_e`` is given and the rows carry K)."""
        k = len(rows)
        keep = n_e is not None and k > 0 and len(rows[0]) > 8
        out = InnovationHistory(
            t=np.array([r[0] for r in rows], dtype=float),
            step=np.array([r[1] for r in rows], dtype=int),
            z=np.array([r[2] for r in rows], dtype=float).reshape(k, m),
            z_pred=np.array([r[3] for r in rows], dtype=float).reshape(k, m),
            y=np.array([r[4] for r in rows], dtype=float).reshape(k, m),
            S=np.array([r[5] for r in rows], dtype=float).reshape(k, m, m),
            nis=np.array([r[6] for r in rows], dtype=float),
            accepted=np.array([r[7] for r in rows], dtype=bool),
            K=np.array([r[8] for r in rows], dtype=float).reshape(k, n_e, m) if keep else None,
        )
        return out


@dataclass(frozen=True)
class ForwardPass:
    """Every step of a forward (filter) pass over n times; the input of :func:`rts_smooth`.

    ``t`` (n,) [s]; ``x_prior``, ``x_post`` (n, n_x); ``P_prior``, ``P_post`` (n, n_e, n_e)
    (forward-pass covariances, error state); ``F`` (n, n_e, n_e) with ``F[k]`` the error-state
    transition from step k−1 to k (``F[0] = I``); ``Q`` (n, n_e, n_e) the process noise added in
    that transition (``Q[0] = 0``), or None when the pass does not keep it (the smoother does not
    need it); ``innovations``: name -> :class:`InnovationHistory`.
    """

    t: np.ndarray
    x_prior: np.ndarray
    P_prior: np.ndarray
    x_post: np.ndarray
    P_post: np.ndarray
    F: np.ndarray
    Q: np.ndarray | None
    innovations: dict[str, InnovationHistory]


# ---------------------------------------------------------------------------------------------
# Jacobians by central differences in the error state
# ---------------------------------------------------------------------------------------------


def _eps_vector(eps: float | np.ndarray, n_e: int) -> np.ndarray:
    e = np.asarray(eps, dtype=float)
    if e.shape != (n_e,):
        e = np.broadcast_to(e, (n_e,))
    if (e <= 0.0).any():
        raise ValueError("eps must be positive")
    return e


def numeric_transition_jacobian(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    layout: ErrorStateLayout,
    eps: float | np.ndarray = 1e-6,
    fx: np.ndarray | None = None,
) -> np.ndarray:
    """Error-state Jacobian F (n_e, n_e) of ``f: x (n_x,) -> x_next (n_x,)`` by central differences.

    ``F[:, j] = [(f(x ⊞ ε e_j) ⊟ f(x)) − (f(x ⊞ −ε e_j) ⊟ f(x))] / (2 ε_j)``: both perturbed images
    are taken relative to the nominal image ``f(x)`` (pass it as ``fx`` to save a call), so the
    quaternion columns are body-frame small angles at ``f(x)``; for additive entries this is the
    plain ``(f₊ − f₋)/(2ε)``.  ``eps`` is a scalar or (n_e,) perturbation in error-state units
    (choose it per state for badly scaled states, like POST2's perturbation sizes).  Costs 2·n_e
    calls of ``f``.
    """
    x = np.asarray(x, dtype=float)
    n_e = layout.n_e
    e = _eps_vector(eps, n_e)
    fx = np.asarray(f(x), dtype=float) if fx is None else np.asarray(fx, dtype=float)
    D = np.diag(e)
    Xp = layout.boxplus(x, D)
    Xm = layout.boxplus(x, -D)
    Fp = np.array([np.asarray(f(xi), dtype=float) for xi in Xp])
    Fm = np.array([np.asarray(f(xi), dtype=float) for xi in Xm])
    cols = (layout.boxminus(Fp, fx) - layout.boxminus(Fm, fx)) / (2.0 * e)[:, None]
    return np.ascontiguousarray(cols.T)


def numeric_measurement_jacobian(
    h: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    layout: ErrorStateLayout,
    residual: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    eps: float | np.ndarray = 1e-6,
    hx: np.ndarray | None = None,
) -> np.ndarray:
    """Jacobian H (m, n_e) of ``h: x -> z_pred (m,)`` w.r.t. the error state, by central differences.

    ``H[:, j] = [r(h(x ⊞ ε e_j), h(x)) − r(h(x ⊞ −ε e_j), h(x))] / (2 ε_j)`` with ``r`` the
    measurement's residual function (default subtraction, so angle wrapping in a custom residual
    is respected).  ``eps`` scalar or (n_e,), error-state units.  Costs 2·n_e calls of ``h``.
    """
    x = np.asarray(x, dtype=float)
    n_e = layout.n_e
    e = _eps_vector(eps, n_e)
    D = np.diag(e)
    Xp = layout.boxplus(x, D)
    Xm = layout.boxplus(x, -D)
    Zp = [np.atleast_1d(np.asarray(h(xi), dtype=float)) for xi in Xp]
    Zm = [np.atleast_1d(np.asarray(h(xi), dtype=float)) for xi in Xm]
    if residual is None:
        cols = np.array(Zp) - np.array(Zm)
    else:
        h0 = np.atleast_1d(np.asarray(h(x), dtype=float)) if hx is None else hx
        cols = np.array(
            [np.atleast_1d(residual(a, h0)) - np.atleast_1d(residual(b, h0)) for a, b in zip(Zp, Zm, strict=True)]
        )
    cols = cols / (2.0 * e)[:, None]
    return np.ascontiguousarray(cols.T)


def numeric_jacobian_batched(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    layout: ErrorStateLayout,
    eps: float | np.ndarray = 1e-6,
    out_layout: ErrorStateLayout | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(f(x), J)`` with J the error-state Jacobian of ``f`` by central differences, in ONE call of
    a vectorised ``f``.

    ``f`` maps a batch (b, n_x) to (b, m); it is called once on the stack
    ``[x, x ⊞ ε e_0, …, x ⊞ ε e_{n_e−1}, x ⊞ −ε e_0, …]`` (1 + 2 n_e rows).  ``out_layout``: the
    layout of f's output when it is a state (a transition: columns taken with ⊟ about ``f(x)`` as in
    :func:`numeric_transition_jacobian`, J (n_e_out, n_e)); None: the output is additive
    (a measurement: J (m, n_e) as in :func:`numeric_measurement_jacobian` without a residual
    function).  ``eps`` scalar or (n_e,), error-state units.  Same numbers as the one-call-per-column
    functions, for models that are cheaper evaluated as a batch.
    """
    x = np.asarray(x, dtype=float)
    n_e = layout.n_e
    e = _eps_vector(eps, n_e)
    key = e.tobytes()
    steps = layout._steps.get(key)
    if steps is None:  # built once per ε (a filter passes the same one at every step)
        if len(layout._steps) > 16:
            layout._steps.clear()
        D = np.diag(e)
        steps = layout._steps[key] = np.concatenate([D, -D], axis=0)
        steps.flags.writeable = False
    X = np.empty((1 + 2 * n_e, x.shape[-1]))
    X[0] = x
    X[1:] = layout.boxplus(x, steps)  # row by row: x ⊞ ε e_j, then x ⊞ −ε e_j
    Y = np.asarray(f(X), dtype=float)
    y0 = Y[0]
    if out_layout is None:
        cols = Y[1 : 1 + n_e] - Y[1 + n_e :]
    else:
        d = out_layout.boxminus(Y[1:], y0)
        cols = d[:n_e] - d[n_e:]
    cols = cols / (2.0 * e)[:, None]
    return y0, np.ascontiguousarray(cols.T)


def derived_with_sigma(
    g: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    P: np.ndarray,
    layout: ErrorStateLayout,
    eps: float | np.ndarray = 1e-6,
    *,
    compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quantities derived from a history of states, with their covariance by first-order propagation.

    ``x`` (n, n_x) states and ``P`` (n, n_e, n_e) their error covariances (e.g. a smoothed pass);
    ``g`` maps states (n, r, n_x) to (n, r, k) derived quantities (sample i of the leading axis
    belongs to ``x[i]``, so g may broadcast per-sample constants shaped (n, 1, ...)).  It is called
    once on the stack ``[x, x ⊞ ε e_j, x ⊞ −ε e_j]`` (r = 1 + 2 n_e); ``J`` (n, k, n_e) are the central
    differences.  Returns ``(g(x) (n, k), 1σ (n, k) = sqrt(diag(J P Jᵀ)), covariance (n, k, k))``.
    ``eps`` scalar or (n_e,), error-state units.  ``compiled``: ``J P Jᵀ`` by
    :func:`.propagation_kernel.sandwich`; False: by ``np.einsum``, the reference (the same sums).
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    n_e = layout.n_e
    e = _eps_vector(eps, n_e)
    D = np.diag(e)
    dx = np.concatenate([np.zeros((1, n_e)), D, -D], axis=0)  # (r, n_e)
    X = layout.boxplus(x[:, None, :], dx[None, :, :])
    Y = np.asarray(g(X), dtype=float)
    y0, Yp, Ym = Y[:, 0], Y[:, 1 : 1 + n_e], Y[:, 1 + n_e :]
    J = np.swapaxes((Yp - Ym) / (2.0 * e)[None, :, None], 1, 2)
    if compiled:
        # imported here: a cached numba kernel needs a writable cache folder when its module is
        # imported, and every problem imports this module before it can say its output is unwritable
        from workbench.estimation.propagation_kernel import sandwich

        C = np.empty((J.shape[0], J.shape[1], J.shape[1]))
        sandwich(J, P, C)
    else:
        C = np.einsum("nkj,nji,nli->nkl", J, P, J)
    C = 0.5 * (C + np.swapaxes(C, 1, 2))
    return y0, np.sqrt(np.maximum(np.einsum("nkk->nk", C), 0.0)), C


# ---------------------------------------------------------------------------------------------
# predict / update
# ---------------------------------------------------------------------------------------------


def predict(
    x: np.ndarray,
    P: np.ndarray,
    f: Callable[[np.ndarray], np.ndarray],
    Q: np.ndarray,
    layout: ErrorStateLayout,
    F: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None,
    eps: float | np.ndarray = 1e-6,
) -> Prediction:
    """Propagate state and error covariance one step.

    x (n_x,), P (n_e, n_e), ``f(x) -> x_next`` (n_x,), Q (n_e, n_e) discrete process noise of the
    step (error-state units, e.g. rad² for a body-frame attitude error).  ``F`` (n_e, n_e), a
    callable ``F(x)``, or None for :func:`numeric_transition_jacobian` (body-frame attitude
    error, see module docstring).  ``P_prior = F P Fᵀ + Q``, symmetrised.
    """
    x = np.asarray(x, dtype=float)
    x_prior = np.asarray(f(x), dtype=float)
    if F is None:
        Fm = numeric_transition_jacobian(f, x, layout, eps, fx=x_prior)
    elif callable(F):
        Fm = np.asarray(F(x), dtype=float)
    else:
        Fm = np.asarray(F, dtype=float)
    A = Fm @ P @ Fm.T + Q
    return Prediction(x_prior, 0.5 * (A + A.T), Fm)


def _as_vector(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a.reshape(1) if a.ndim == 0 else a


_NON_FINITE = (
    "non-finite innovation (check z, h(x) and R): the state diverged, or this measurement's values are not in "
    "the unit its file declares"
)


def _update(
    x, P, z, h, R, layout, H, residual, gate_probability, iterations, eps,
    gain_projector=None, step_tol=None, gate_threshold=None,
):  # fmt: skip
    """Core of :func:`update`; returns a tuple (x_post, P_post, y, S, K, H, nis, accepted, z_pred)."""
    z = _as_vector(z)
    zp = _as_vector(h(x))
    y = z - zp if residual is None else np.atleast_1d(np.asarray(residual(z, zp), dtype=float))
    if H is None:
        Hk = numeric_measurement_jacobian(h, x, layout, residual, eps, hx=zp)
    elif callable(H):
        Hk = np.asarray(H(x), dtype=float)
    else:
        Hk = H
    if Hk.ndim == 1:
        Hk = Hk.reshape(1, -1)
    R = np.asarray(R, dtype=float)
    if R.ndim < 2:
        R = R.reshape(1, 1)
    if not np.all(np.isfinite(y)):  # before S: a NaN in S passes some LAPACKs' potrf, not others
        raise np.linalg.LinAlgError(_NON_FINITE)
    PHt = P @ Hk.T
    S = Hk @ PHt + R
    c, info = _potrf(S, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"innovation covariance S is not positive definite (potrf info={info})")
    w, _ = _potrs(c, y, lower=1)
    nis = float(y @ w)
    if not math.isfinite(nis):
        raise np.linalg.LinAlgError(_NON_FINITE)
    Kt, _ = _potrs(c, PHt.T, lower=1)
    K = Kt.T
    if gain_projector is not None:
        K = gain_projector(x) @ K
    if gate_threshold is None and gate_probability is not None:
        gate_threshold = chi2_gate(float(gate_probability), y.shape[0])
    if gate_threshold is not None and nis > gate_threshold:
        return x, P, y, S, K, Hk, nis, False, zp
    dx = K @ y
    x_new = layout.boxplus(x, dx)
    for _ in range(1, iterations):
        # Gauss-Newton step about the current iterate x_i (Bell & Cathey 1993):
        # x_{i+1} = x ⊞ K_i [ r(z, h(x_i)) − H_i (x ⊟ x_i) ]
        x_i = x_new
        zp_i = _as_vector(h(x_i))
        if not np.all(np.isfinite(zp_i)):
            break  # the model is not defined at the iterate: keep the last one
        r_i = z - zp_i if residual is None else np.atleast_1d(np.asarray(residual(z, zp_i), dtype=float))
        if H is None:
            H_i = numeric_measurement_jacobian(h, x_i, layout, residual, eps, hx=zp_i)
        elif callable(H):
            H_i = np.asarray(H(x_i), dtype=float)
            if H_i.ndim == 1:
                H_i = H_i.reshape(1, -1)
        else:
            H_i = Hk
        PHt_i = P @ H_i.T
        S_i = H_i @ PHt_i + R
        c, info = _potrf(S_i, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"iterated update: H P Hᵀ + R not positive definite (potrf info={info})")
        Kt, _ = _potrs(c, PHt_i.T, lower=1)
        K = Kt.T
        if gain_projector is not None:
            K = gain_projector(x_i) @ K
        Hk, PHt = H_i, PHt_i
        dx_new = K @ (r_i - Hk @ layout.boxminus(x, x_i))
        x_new = layout.boxplus(x, dx_new)
        step = np.abs(dx_new - dx)
        dx = dx_new
        if step_tol is None:
            if np.max(step) <= 1e-13 * (1.0 + np.max(np.abs(dx_new))):
                break
        elif np.all(step < step_tol):
            break
    # Joseph form (I − KH) P (I − KH)ᵀ + K R Kᵀ, associated as M = (I − KH) P = P − K (P Hᵀ)ᵀ,
    # P_post = M − (M Hᵀ − K R) Kᵀ: the same products without forming n_e × n_e temporaries
    # beyond M (O(n_e² m) instead of O(n_e³)); no optimal-gain identity is used, so it holds for a
    # projected (sub-optimal) gain as well.
    M = P - K @ PHt.T
    A = M - (M @ Hk.T - K @ R) @ K.T
    A += A.T
    A *= 0.5
    return x_new, A, y, S, K, Hk, nis, True, zp


def update(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    h: Callable[[np.ndarray], np.ndarray],
    R: np.ndarray,
    layout: ErrorStateLayout,
    H: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None,
    residual: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    gate_probability: float | None = None,
    iterations: int = 1,
    eps: float | np.ndarray = 1e-6,
    *,
    gain_projector: Callable[[np.ndarray], np.ndarray] | None = None,
    step_tol: np.ndarray | None = None,
    gate_threshold: float | None = None,
) -> UpdateResult:
    """Measurement update of an error-state EKF with Joseph-form covariance.

    x (n_x,) and P (n_e, n_e) prior; z (m,) measurement (SI units); ``h(x) -> z_pred`` (m,);
    R (m, m) measurement noise covariance.  ``H`` (m, n_e) w.r.t. the error state (body-frame
    attitude error δθ, ``q_true = q ⊗ exp(δθ)``), a callable ``H(x)``, or None for
    :func:`numeric_measurement_jacobian`.  ``residual(z, z_pred)`` defaults to ``z − z_pred``.

    ``y = residual(z, h(x))``, ``S = H P Hᵀ + R``, ``K = P Hᵀ S⁻¹`` (Cholesky solve),
    ``x_post = x ⊞ K y``, ``P_post = (I − KH) P (I − KH)ᵀ + K R Kᵀ`` symmetrised, ``nis = yᵀ S⁻¹ y``.
    The quaternion reset keeps ``P_post`` as is (reset Jacobian ``I − ½[δθ×] ≈ I``, see module
    docstring).

    ``gate_probability``: if given and ``nis > chi2.ppf(gate_probability, m)`` the update is
    rejected: ``x_post = x``, ``P_post = P``, ``accepted = False``; y, S, K, nis still returned.
    ``iterations > 1``: iterated EKF (Gauss-Newton on the MAP cost, Bell & Cathey 1993)
    ``x_{i+1} = x ⊞ K_i [r(z, h(x_i)) − H_i (x ⊟ x_i)]``, stopping early when the step no longer
    changes; the covariance is the Joseph form with the last ``H_i``, ``K_i``.  The gate uses the
    prior innovation.  ``eps``: numeric-Jacobian perturbation (scalar or (n_e,)).

    Options (keyword-only):

    * ``gain_projector(x) -> Π`` (n_e, n_e): constrained update directions by gain projection
      (Simon 2006, Sect. 7.5), ``K ← Π(x_i) K`` with Π evaluated at the prior and then at each
      iterate.  The Joseph form stays the exact covariance for such a sub-optimal gain.
    * ``step_tol`` (n_e,): absolute stop rule of the iterations, ``|δ_{i+1} − δ_i| < step_tol``
      componentwise (error-state units); None: the relative rule
      ``max|δ_{i+1} − δ_i| ≤ 1e-13 (1 + max|δ_{i+1}|)``.  An iterate where ``h`` is not finite
      ends the iterations (the previous iterate and its gain are kept).
    * ``gate_threshold``: χ² threshold on the NIS used instead of ``gate_probability``.
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    if H is not None and not callable(H):
        H = np.asarray(H, dtype=float)
    if iterations < 1:
        raise ValueError("iterations must be >= 1")
    return UpdateResult(
        *_update(
            x, P, z, h, R, layout, H, residual, gate_probability, int(iterations), eps,
            gain_projector, step_tol, gate_threshold,
        )
    )  # fmt: skip


# ---------------------------------------------------------------------------------------------
# forward driver
# ---------------------------------------------------------------------------------------------


def _scatter(slots, size, z, zp, y, S, K):
    idx = np.asarray(slots, dtype=int)
    zf, zpf, yf = (np.full(size, np.nan) for _ in range(3))
    zf[idx], zpf[idx], yf[idx] = z, zp, y
    Sf = np.full((size, size), np.nan)
    Sf[np.ix_(idx, idx)] = S
    Kf = np.full((K.shape[0], size), np.nan)
    Kf[:, idx] = K
    return zf, zpf, yf, Sf, Kf


def apply_measurements(
    k: int,
    tk: float,
    x: np.ndarray,
    P: np.ndarray,
    measurements: Sequence[Measurement],
    layout: ErrorStateLayout,
    rows: dict[str, list[tuple]],
    sizes: dict[str, int],
    keep_gains: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The measurement part of step ``k`` of :func:`run_filter`: each :class:`Measurement` its own
    :func:`update` of x (n_x,), P (n_e, n_e), in list order; returns the posterior (x, P).

    Appends one row ``(t, step, z, z_pred, y, S, nis, accepted[, K])`` per measurement to
    ``rows[name]`` (the input of :meth:`InnovationHistory.from_rows`) and keeps the channel's size
    in ``sizes[name]``; ``tk`` [s] the step's time.  For drivers that run part of a step
    themselves (a compiled recursion) and the rest through here.
    """
    for meas in measurements:
        H = meas.H
        if H is not None and not callable(H):
            H = np.asarray(H, dtype=float)
        try:
            xn, Pn, y, S, K, _, nis, ok, zp = _update(
                x,
                P,
                meas.z,
                meas.h,
                meas.R,
                layout,
                H,
                meas.residual,
                meas.gate_probability,
                meas.iterations,
                meas.eps,
                meas.gain_projector,
                meas.step_tol,
                meas.gate_threshold,
            )
        except (np.linalg.LinAlgError, ValueError) as err:
            raise type(err)(f"step {k} (t={tk} s), measurement {meas.name!r}: {err}") from err
        zr = _as_vector(meas.z)
        if meas.slots is not None:  # scatter into the channel's full size, NaN elsewhere
            zr, zp, y, S, K = _scatter(meas.slots, int(meas.size), zr, zp, y, S, K)
        m = sizes.setdefault(meas.name, y.shape[0])
        if m != y.shape[0]:
            raise ValueError(f"step {k}: measurement {meas.name!r} changed size ({m} -> {y.shape[0]})")
        row = (tk, k, zr, zp, y, S, nis, ok)
        rows.setdefault(meas.name, []).append((*row, K) if keep_gains else row)
        x, P = xn, Pn
    return x, P


def run_filter(
    x0: np.ndarray,
    P0: np.ndarray,
    t: np.ndarray,
    transition: Callable[[np.ndarray, float, float], tuple[np.ndarray, np.ndarray | None]],
    process_noise: Callable[[np.ndarray, float, float], np.ndarray] | None,
    measurements_at: Callable[[int, float, np.ndarray], Sequence[Measurement]],
    layout: ErrorStateLayout,
    adapt_q: Callable[[int, np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
    keep_gains: bool = False,
    eps: float | np.ndarray = 1e-6,
    keep_q: bool = True,
) -> ForwardPass:
    """Run the error-state EKF over the times ``t`` (n,) [s] and record every step.

    x0 (n_x,), P0 (n_e, n_e): state and covariance at ``t[0]``; step 0 gets only updates
    (``x_prior[0] = x0``).  For k ≥ 1:

    * ``transition(x, t[k-1], t[k]) -> (x_next, F or None)``; F (n_e, n_e) error-state
      transition (None: central differences of ``transition`` with perturbation ``eps``); a
      model that computes its process noise with F returns ``(x_next, F, Q)`` instead;
    * otherwise ``Q = process_noise(x, t[k-1], t[k])`` (n_e, n_e), then ``Q = adapt_q(k, x, P, Q)`` if given
      — the hook for raising process noise on rapid acceleration changes (REDLand); x, P are the
      posterior of step k−1;
    * ``P_prior = F P Fᵀ + Q`` (symmetrised).

    Then ``measurements_at(k, t[k], x_prior)`` returns a list of :class:`Measurement`, processed
    sequentially (each its own :func:`update`, in list order) and recorded in the
    :class:`InnovationHistory` of its name (a name may appear several times at one step; it must
    keep its size m).  Gains are kept (``InnovationHistory.K``) only with ``keep_gains=True``;
    the process-noise history (``ForwardPass.Q``, which the smoother does not read) only with
    ``keep_q=True`` (else None: n·n_e² floats saved).
    Attitude errors follow the body-frame convention of the module.
    Errors in an update are re-raised with the step, time and measurement name.
    """
    t = np.asarray(t, dtype=float)
    n = t.shape[0]
    n_x, n_e = layout.n_x, layout.n_e
    x = np.array(x0, dtype=float)
    P = np.array(P0, dtype=float)
    if x.shape != (n_x,) or P.shape != (n_e, n_e):
        raise ValueError(f"x0 must be ({n_x},) and P0 ({n_e}, {n_e}); got {x.shape}, {P.shape}")
    x_prior = np.empty((n, n_x))
    x_post = np.empty((n, n_x))
    P_prior = np.empty((n, n_e, n_e))
    P_post = np.empty((n, n_e, n_e))
    F_hist = np.empty((n, n_e, n_e))
    Q_hist = np.empty((n, n_e, n_e)) if keep_q else None
    if n:
        F_hist[0] = np.eye(n_e)
        if keep_q:
            Q_hist[0] = 0.0
    rows: dict[str, list[tuple]] = {}
    sizes: dict[str, int] = {}
    tl = t.tolist()
    for k in range(n):
        tk = tl[k]
        if k:
            t0 = tl[k - 1]
            step = transition(x, t0, tk)
            if len(step) == 3:  # the model gives its own process noise
                x_next, Fk, Qk = step
            else:
                x_next, Fk = step
                Qk = process_noise(x, t0, tk)
            if adapt_q is not None:
                Qk = adapt_q(k, x, P, Qk)
            x_next = np.asarray(x_next, dtype=float)
            if Fk is None:
                Fk = numeric_transition_jacobian(
                    lambda xx, t0=t0, t1=tk: transition(xx, t0, t1)[0], x, layout, eps, fx=x_next
                )
            A = Fk @ P @ Fk.T
            A += Qk
            A += A.T
            A *= 0.5
            P = A
            F_hist[k] = Fk
            if keep_q:
                Q_hist[k] = Qk
            x = x_next
        x_prior[k] = x
        P_prior[k] = P
        x, P = apply_measurements(k, tk, x, P, measurements_at(k, tk, x), layout, rows, sizes, keep_gains)
        x_post[k] = x
        P_post[k] = P
    return ForwardPass(
        t=t,
        x_prior=x_prior,
        P_prior=P_prior,
        x_post=x_post,
        P_post=P_post,
        F=F_hist,
        Q=Q_hist,
        innovations={
            name: InnovationHistory.from_rows(r, sizes[name], n_e if keep_gains else None) for name, r in rows.items()
        },
    )
