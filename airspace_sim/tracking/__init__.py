"""Target tracking: the batched IMM estimator (paper §IV).

:class:`IMM` tracks B independent targets with one jump-Markov model in a numba kernel;
see :mod:`airspace_sim.tracking.imm`.
"""

from airspace_sim.tracking.imm import DEFAULT_GATE_PROBABILITY, IMM

__all__ = ["DEFAULT_GATE_PROBABILITY", "IMM"]
