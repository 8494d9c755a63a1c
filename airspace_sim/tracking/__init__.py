"""Target tracking: the batched IMM estimator (paper §IV).

:class:`IMM` tracks B independent targets with one jump-Markov model in a numba kernel, a
dense view over :class:`SlotIMM` (filters in stable slots); see
:mod:`airspace_sim.tracking.imm`. :func:`two_point_initialisation` starts tracks from two
position measurements.
"""

from airspace_sim.tracking.imm import DEFAULT_GATE_PROBABILITY, IMM, SlotIMM
from airspace_sim.tracking.initialisation import two_point_initialisation

__all__ = ["DEFAULT_GATE_PROBABILITY", "IMM", "SlotIMM", "two_point_initialisation"]
