"""The two IMM step kernels — generated straight-line code and the generic loops — give the
same bits; the choice between them, its validation and pickling.

Both kernels are also compared with filterpy on their own (tests/test_imm_filterpy.py: the
presets and the small random model run the generated kernel, the larger dense random models
the loops); this file checks that they agree exactly, so that either can be trusted where
the other was compared.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from test_imm_api import STATE, assert_same_bits, initial, measurements, seed_model, snapshot

from airspace_sim.errors import UserError
from airspace_sim.tracking import IMM, _codegen


def random_model(rng, M, n, m, density=0.6):
    """A random jump-Markov model whose F_j have random sparsity patterns."""
    F = rng.standard_normal((M, n, n)) * 0.2 * (rng.random((M, n, n)) < density) + np.eye(n)
    A = rng.standard_normal((M, n, n))
    Q = 0.1 * (A @ np.swapaxes(A, 1, 2)) + 0.01 * np.eye(n)
    H = rng.standard_normal((m, n)) * (rng.random((m, n)) < 0.7)
    H[np.arange(m), np.arange(m)] = 1.0
    C = rng.standard_normal((m, m))
    R = C @ C.T + np.eye(m)
    Pi = rng.dirichlet(np.ones(M) * 0.3, M) * 0.2 + 0.8 * np.eye(M)
    return dict(
        transitions=F, process_noise=Q, measurement_matrix=H, measurement_noise=R,
        transition_matrix=Pi, offsets=0.1 * rng.standard_normal((M, n)),
    )  # fmt: skip


def run_both(args, x0, P0, mu0, z):
    imms = [IMM(x0=x0, P0=P0, mu0=mu0, kernel=k, **args) for k in ("generated", "loops")]
    assert [i.kernel for i in imms] == ["generated", "loops"]
    for k in range(len(z)):
        for imm in imms:
            imm.step(z[k])
        assert_same_bits(snapshot(imms[0]), snapshot(imms[1]))
    return imms


def test_seed_model_same_bits_with_missing_outliers_and_partial_chunks():
    rng = np.random.default_rng(21)
    _, args = seed_model()
    B = 1003  # not a multiple of either chunk width
    x0, P0, mu0 = initial(rng, B)
    z = measurements(rng, x0, 40, missing=0.1, outliers=0.05)
    z[7, ::11, 1] = np.inf  # one component not finite: no measurement
    z[9, ::13] = 1e200  # d² overflows: gated even though "finite"
    imms = run_both(args, x0, P0, mu0, z)
    assert imms[0].gated.any() or np.isnan(imms[0].nis).any()


def test_unreachable_mode_same_bits():
    """c̄_j = 0 takes the mixing special case (μ_{i|j} = δ_ij) in both kernels alike."""
    rng = np.random.default_rng(22)
    _, args = seed_model()
    args["transition_matrix"] = np.array([[0.9, 0.1, 0.0], [0.2, 0.8, 0.0], [0.3, 0.3, 0.4]])
    x0, P0, _ = initial(rng, 40)
    z = measurements(rng, x0, 20)
    imms = run_both(args, x0, P0, np.array([0.5, 0.5, 0.0]), z)
    assert np.all(imms[0].mu[:, 2] == 0.0)


@pytest.mark.parametrize("M,n,m", [(2, 3, 1), (2, 3, 3)])
def test_random_models_same_bits(M, n, m):
    """m = 1 (scalar S) and m = 3 (Cholesky path), with random sparsity in F and H."""
    rng = np.random.default_rng(100 * M + 10 * n + m)
    args = random_model(rng, M, n, m)
    B, T = 37, 30
    x0 = rng.standard_normal((B, n))
    P0 = np.eye(n) * rng.uniform(0.5, 2.0, (B, 1, 1))
    mu0 = rng.dirichlet(np.ones(M), B)
    H = args["measurement_matrix"]
    z = x0 @ H.T + rng.standard_normal((T, B, m))
    z[rng.random((T, B)) < 0.1] = np.nan
    z[rng.random((T, B)) < 0.03] += 1e3
    run_both(args, x0, P0, mu0, z)


def test_kernel_choice_and_validation():
    rng = np.random.default_rng(23)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 3)
    assert IMM(x0=x0, P0=P0, mu0=mu0, **args).kernel == "generated"
    assert IMM(x0=x0, P0=P0, mu0=mu0, kernel="loops", **args).kernel == "loops"
    with pytest.raises(UserError, match="IMM kernel: expected 'auto', 'generated' or 'loops'"):
        IMM(x0=x0, P0=P0, mu0=mu0, kernel="fast", **args)
    # a dense 3 × 6 model would take long to compile: "auto" falls back to the loops
    big = random_model(rng, 3, 6, 2, density=1.0)
    H = big["measurement_matrix"]
    assert (
        _codegen.step_kernel(big["transitions"], H, max_products=_codegen.AUTO_MAX_PRODUCTS) is None
    )
    imm = IMM(x0=np.zeros((2, 6)), P0=np.eye(6), mu0=np.full(3, 1 / 3), **big)
    assert imm.kernel == "loops"


@pytest.mark.parametrize("kernel", ["generated", "loops"])
def test_pickle_round_trip_continues_bit_for_bit(kernel):
    rng = np.random.default_rng(24)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 50)
    z = measurements(rng, x0, 20)
    a = IMM(x0=x0, P0=P0, mu0=mu0, kernel=kernel, **args)
    for k in range(10):
        a.step(z[k])
    b = pickle.loads(pickle.dumps(a))
    assert b.kernel == kernel
    assert_same_bits(snapshot(a), snapshot(b))
    for k in range(10, 20):
        a.step(z[k])
        b.step(z[k])
    assert_same_bits(snapshot(a), snapshot(b))
    assert set(STATE) <= set(dir(b))
