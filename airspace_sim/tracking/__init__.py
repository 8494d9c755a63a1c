"""Target tracking: the batched IMM estimator (paper §IV) and what a user needs around it.

:class:`IMM` tracks B independent targets with one jump-Markov model in a numba kernel, a
dense view over :class:`SlotIMM` (filters in stable slots); see
:mod:`airspace_sim.tracking.imm`. ``IMM.from_preset(preset, x0, P0)`` builds a preset's
matched IMM (mode names included) that can step with any time since the last step
(``imm.step(z, dt=...)``). Around it:

- :func:`two_point_initialisation`: tracks started from two position measurements (start
  from these, not from a guess: a guess far from the measurements is gated);
- gating diagnostics: ``imm.gated`` (B,) says which finite measurements were rejected,
  ``imm.nis`` their NIS and :func:`gate_threshold` the d² a probability gives;
- :func:`chi2_band`, :func:`nees`, :func:`nis`: consistency statistics;
- :func:`smooth_two_filter`: the IMM smoother, a forward IMM and one over the time-reversed
  record fused: fixed-interval (states and mode probabilities given the whole record:
  labelling recorded flights after the fact) or fixed-lag (given a few steps more: what a
  tracker that reports late can say);
- :func:`smooth`: the expectation-correction IMM smoother over a forward run's record alone,
  fixed-lag (as good up to a few steps) or fixed-interval;
- :mod:`.coordinated_turn`: the estimated-rate (EKF) mode; :mod:`.evaluation`: trackers
  measured on recorded flights.
"""

from airspace_sim.tracking.consistency import chi2_band, nees, nis
from airspace_sim.tracking.imm import DEFAULT_GATE_PROBABILITY, IMM, SlotIMM, gate_threshold
from airspace_sim.tracking.initialisation import two_point_initialisation
from airspace_sim.tracking.smoother import Smoothed, smooth
from airspace_sim.tracking.two_filter import smooth_two_filter

__all__ = [
    "DEFAULT_GATE_PROBABILITY",
    "IMM",
    "SlotIMM",
    "Smoothed",
    "chi2_band",
    "gate_threshold",
    "nees",
    "nis",
    "smooth",
    "smooth_two_filter",
    "two_point_initialisation",
]
