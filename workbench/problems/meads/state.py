"""The named layout of the MEADS EKF state (Karlgaard et al. 2009/2013, Sect. III.B): one place
for every index, so the filter (:mod:`.ekf`), its compiled kernel (:mod:`.kernel`), the recording
and the tests name the states instead of counting columns.

All states are additive (the attitude is a small-angle error of the strapdown's); the blocks, in
order (units in :data:`STATE_NAMES` order):

====================  ====================================================  =============
``IP``, ``IV``        inertial position / velocity in M (3 each)            m, m/s
``ITH``               body-frame attitude error δθ_B (3)                    rad
``IW``                wind north, east, down (3; ``IW_NORTH`` …)            m/s
``ILP``, ``ILR``      ln p∞, ln ρ∞                                          ln Pa, ln kg/m³
``ILAM``              transducer scale factors λ_i (:data:`N_PORTS`)        of reading
``IC``                common level error of the pressure model              of reading
``IB``, ``IBD``       per-port model error b_i and its rate b'_i            of reading
``IBIAS``             per-port additive residual bias β_i                   Pa
``IMM``               the model's relative Mach error m                     -
``IMA``               the model's flow-angle errors a_m, b_m (2)            rad
====================  ====================================================  =============
"""

from __future__ import annotations

__all__ = [
    "N_PORTS",
    "IP",
    "IV",
    "ITH",
    "IW",
    "IW_NORTH",
    "IW_EAST",
    "IW_DOWN",
    "ILP",
    "ILR",
    "ILAM",
    "IC",
    "IB",
    "IBD",
    "IBIAS",
    "IMM",
    "IMA",
    "N_X",
    "N_U_COLS",
    "STATE_NAMES",
]

#: ports of the MEADS layout (the filter's scale-factor, model-error and bias blocks)
N_PORTS = 7
IP = slice(0, 3)
IV = slice(3, 6)
ITH = slice(6, 9)
IW = slice(9, 12)
IW_NORTH, IW_EAST, IW_DOWN = IW.start, IW.start + 1, IW.start + 2
ILP = IW.stop
ILR = ILP + 1
ILAM = slice(ILR + 1, ILR + 1 + N_PORTS)
IC = ILAM.stop
#: the per-port model-error Gauss-Markov states b_i [of reading] and, for the second-order
#: process, its rate b_i' [of reading per correlation length]
IB = slice(IC + 1, IC + 1 + N_PORTS)
IBD = slice(IB.stop, IB.stop + N_PORTS)
#: the transducers' additive residual biases [Pa]
IBIAS = slice(IBD.stop, IBD.stop + N_PORTS)
#: the model's Mach error (relative): the pressure model read at M (1 + m)
IMM = IBIAS.stop
#: the model's flow-angle errors [rad]: the pressure model read at (α + a_m, β + b_m)
IMA = slice(IMM + 1, IMM + 3)
N_X = IMA.stop
#: state columns the air velocity depends on (position, velocity, attitude error, wind)
N_U_COLS = IW.stop

STATE_NAMES = (
    *(f"p_M_{a}" for a in "xyz"),
    *(f"v_M_{a}" for a in "xyz"),
    *(f"dtheta_B_{a}" for a in "xyz"),
    "wind_north",
    "wind_east",
    "wind_down",
    "ln_p_inf",
    "ln_rho_inf",
    *(f"scale_{i + 1}" for i in range(N_PORTS)),
    "model_level",
    *(f"model_error_{i + 1}" for i in range(N_PORTS)),
    *(f"model_error_rate_{i + 1}" for i in range(N_PORTS)),
    *(f"bias_{i + 1}" for i in range(N_PORTS)),
    "model_mach_error",
    "model_alpha_error",
    "model_beta_error",
)
assert len(STATE_NAMES) == N_X
