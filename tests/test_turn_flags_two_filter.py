"""docs/benchmarks/turn_flags_two_filter.py: each flight reversed in time and mapped back, and
the two-filter combination against the exact smoothed probability of a two-state Markov chain
by enumeration of every state sequence."""

import itertools
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "docs", "benchmarks"))
from turn_flags_two_filter import reversed_in_time, two_filter  # noqa: E402


def test_each_flight_is_reversed_over_its_own_length():
    a = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, np.nan], [np.nan, np.nan]])  # (T=4, F=2)
    n = np.array([3, 2])
    out, index = reversed_in_time(a, n)
    np.testing.assert_array_equal(out[:3, 0], [3.0, 2.0, 1.0])
    np.testing.assert_array_equal(out[:2, 1], [20.0, 10.0])
    assert np.isnan(out[3, 0]) and np.isnan(out[2:, 1]).all()
    back = np.full_like(a, np.nan)
    back[index, np.arange(2)[None, :]] = out
    np.testing.assert_array_equal(back[:3, 0], a[:3, 0])  # mapped back step for step
    np.testing.assert_array_equal(back[:2, 1], a[:2, 1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_filter_is_the_exact_smoothed_probability_of_a_stationary_chain(seed):
    # a two-state chain (every two-state chain is reversible) started in its stationary
    # distribution; the forward filter sees y_1..y_k, the backward one y_{k+1}..y_T run on
    # the reversed chain and predicted one step: their evidence is independent given s_k
    rng = np.random.default_rng(seed)
    T = 7
    a, b = rng.uniform(0.05, 0.4, 2)
    P = np.array([[1 - a, a], [b, 1 - b]])
    pi = np.array([b, a]) / (a + b)
    like = rng.uniform(0.1, 1.0, (T, 2))  # p(y_k | s_k)

    def joint(seq):
        p = pi[seq[0]] * like[0, seq[0]]
        for k in range(1, T):
            p *= P[seq[k - 1], seq[k]] * like[k, seq[k]]
        return p

    seqs = list(itertools.product([0, 1], repeat=T))
    weights = np.array([joint(s) for s in seqs])
    for k in range(T - 1):
        exact = sum(w for s, w in zip(seqs, weights) if s[k] == 1) / weights.sum()
        # forward filter at k
        f = pi * like[0]
        f /= f.sum()
        for j in range(1, k + 1):
            f = (f @ P) * like[j]
            f /= f.sum()
        # backward filter over y_T..y_{k+1} (reversed chain = P for a reversible chain),
        # then predicted to k
        g = pi * like[T - 1]
        g /= g.sum()
        for j in range(T - 2, k, -1):
            g = (g @ P) * like[j]
            g /= g.sum()
        g = g @ P
        assert two_filter(f[1], g[1], pi[1]) == pytest.approx(exact, rel=1e-12)
