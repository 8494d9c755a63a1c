"""The IMM's measurement gate: the chi-square threshold on d² = νᵀ S⁻¹ ν for a gate
probability (used by :class:`~airspace_sim.tracking.imm.IMM` and every caller that gates)."""

from __future__ import annotations

#: Default gate: a measurement is dropped when it lies outside the 1 − 10⁻⁶ chi-square
#: region of every mode (d² > 27.6 for m = 2): an in-model measurement is dropped
#: about once per million updates, a 10-sigma outlier always.
DEFAULT_GATE_PROBABILITY = 1.0 - 1e-6


def gate_threshold(gate_probability: float, m: int = 2) -> float:
    """The gate on d² = νᵀ S⁻¹ ν for ``gate_probability`` and ``m`` measurement components:
    the χ²(m) quantile with Pr(d² > gate) = 1 − p (inf for p = 1, no gate). 27.6 for the
    default 1 − 10⁻⁶ and m = 2."""
    if gate_probability == 1.0:
        return float("inf")
    from scipy.special import chdtri  # lighter to import than scipy.stats

    return float(chdtri(m, 1.0 - gate_probability))
