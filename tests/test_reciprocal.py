"""bands-reciprocal (avoidance/reciprocal.py) against the closed-form head-on geometry."""

import math

import numpy as np
import pytest

from airspace_sim import registry

V, D, R_SAFE, MARGIN = 230.0, 20000.0, 3000.0, 0.1


def head_on():
    own = np.array([[V, 0.0]])
    rel_p = np.array([[[D, 0.0]]])
    rel_v = np.array([[[-2 * V, 0.0]]])  # intruder at (−V, 0)
    return own, rel_p, rel_v, np.array([[True]]), np.array([math.pi / 2])


def choice(name, **params):
    res = registry.build("resolver", name, params={"r_safe": R_SAFE, "margin": MARGIN, **params})
    out = res.resolve(*head_on())
    assert bool(out.conflict[0])
    return abs(float(out.heading_change[0]))


def test_head_on_share_half_turns_half_the_miss_angle():
    # both turn by ψ: relative velocity 2v(−cos ψ, −sin ψ), miss distance D·sin ψ, so the
    # smallest clear ψ is asin(ρ/D), ρ = r_safe(1 + margin). Alone (bands): the relative
    # velocity is v(−1 − cos ψ, −sin ψ), miss D·sin(ψ/2), ψ = 2·asin(ρ/D).
    rho = R_SAFE * (1 + MARGIN)
    assert choice("bands-reciprocal", share=0.5) == pytest.approx(math.asin(rho / D), abs=1e-6)
    assert choice("bands") == pytest.approx(2 * math.asin(rho / D), abs=1e-6)


def test_full_share_is_bands():
    assert choice("bands-reciprocal", share=1.0) == choice("bands")
