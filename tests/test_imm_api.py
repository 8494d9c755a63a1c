"""IMM public API: shapes, validation, append/remove, determinism, predict_modes, bench."""

from __future__ import annotations

import json

import numpy as np
import pytest

from airspace_sim.cli import main as cli_main
from airspace_sim.dynamics import presets
from airspace_sim.errors import UserError
from airspace_sim.tracking import IMM
from airspace_sim.tracking.benchmark import format_table, run_benchmark


def seed_model():
    pre = presets.get("seed")
    return pre, pre.imm_arguments()


def initial(rng, B):
    x0 = np.zeros((B, 5))
    heading = rng.uniform(-np.pi, np.pi, B)
    speed = rng.uniform(285.0, 570.0, B)
    x0[:, 0], x0[:, 2] = rng.uniform(-5e3, 5e3, (2, B))
    x0[:, 1], x0[:, 3] = speed * np.cos(heading), speed * np.sin(heading)
    s = rng.uniform(0.5, 2.0, (B, 1))
    P0 = np.diag([2500.0, 400.0, 2500.0, 400.0, 0.25])[None] * s[:, :, None]
    mu0 = rng.dirichlet(np.ones(3), B)
    return x0, P0, mu0


def measurements(rng, x0, T, missing=0.1, outliers=0.02):
    """Straight-line positions with noise (T, B, 2), some rows NaN, some 10 km off."""
    B = len(x0)
    t = 0.1 * np.arange(1, T + 1)[:, None, None]
    z = x0[None, :, [0, 2]] + t * x0[None, :, [1, 3]] + 50 * rng.standard_normal((T, B, 2))
    u = rng.random((T, B))
    z[u < missing] = np.nan
    z[(u >= missing) & (u < missing + outliers)] += 1e4
    return z


STATE = ("x", "P", "mu", "x_modes", "P_modes", "nis", "log_likelihood", "gated")


def snapshot(imm, rows=None):
    rows = slice(None) if rows is None else rows
    return {k: np.array(getattr(imm, k)[rows]) for k in STATE}


def assert_same_bits(a: dict, b: dict):
    for k in STATE:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k, strict=True)


# ---------------------------------------------------------------- shapes and views
def test_shapes_and_defaults():
    rng = np.random.default_rng(0)
    _, args = seed_model()
    B = 7
    x0, P0, mu0 = initial(rng, B)
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    assert imm.B == B and (imm.M, imm.n, imm.m) == (3, 5, 2)
    assert imm.x.shape == (B, 5) and imm.P.shape == (B, 5, 5) and imm.mu.shape == (B, 3)
    assert imm.x_modes.shape == (B, 3, 5) and imm.P_modes.shape == (B, 3, 5, 5)
    assert imm.nis.shape == (B,) and imm.log_likelihood.shape == (B, 3) and imm.gated.shape == (B,)
    np.testing.assert_allclose(imm.x, x0, rtol=1e-15)
    np.testing.assert_allclose(imm.mu, mu0, rtol=1e-15)  # renormalised exactly to sum 1
    assert np.all(np.isnan(imm.nis)) and not imm.gated.any()
    assert 0.99 < imm.gate_probability < 1 and np.isfinite(imm.gate_threshold)
    z = measurements(rng, x0, 1, missing=0, outliers=0)[0]
    imm.step(z)
    assert imm.x.dtype == np.float64 and imm.gated.dtype == bool
    assert np.all(np.isfinite(imm.nis)) and np.all(np.isfinite(imm.log_likelihood))
    assert "B=7" in repr(imm)


def test_broadcast_P0_mu0_equal_explicit():
    rng = np.random.default_rng(1)
    pre, args = seed_model()
    x0, P0, _ = initial(rng, 5)
    a = IMM(x0=x0, P0=P0[0], mu0=pre.mu0(), **args)
    b = IMM(x0=x0, P0=np.repeat(P0[:1], 5, axis=0), mu0=np.tile(pre.mu0(), (5, 1)), **args)
    z = measurements(rng, x0, 10)
    for k in range(10):
        a.step(z[k])
        b.step(z[k])
    assert_same_bits(snapshot(a), snapshot(b))


def test_views_are_read_only_and_valid_until_the_next_step():
    """The ownership rule of the IMM docstring: attributes are read-only views of the
    estimator's buffers, overwritten in place by the next step; a copy keeps its values."""
    rng = np.random.default_rng(2)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 3)
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    z = measurements(rng, x0, 2, missing=0, outliers=0)
    imm.step(z[0])
    x, P, mu = imm.x, imm.P, imm.mu
    kept = x.copy(), P.copy(), mu.copy()
    for a in (x, P, mu, imm.nis, imm.log_likelihood, imm.gated, imm.x_modes, imm.P_modes):
        with pytest.raises(ValueError):
            a.flat[0] = 1.0
    imm.step(z[1])
    # no new output arrays per step: the views held now show the new estimate
    for a, now in zip((x, P, mu), (imm.x, imm.P, imm.mu)):
        assert np.shares_memory(a, now)
        np.testing.assert_array_equal(a, now)
    assert not np.array_equal(imm.x, kept[0])
    # and the copies kept the old one: a fresh IMM stepped once gives the same bits
    ref = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    ref.step(z[0])
    for a, b in zip((ref.x, ref.P, ref.mu), kept):
        np.testing.assert_array_equal(a, b)


def test_missing_row_gives_nan_nis_and_loglik():
    rng = np.random.default_rng(3)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 4)
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    z = measurements(rng, x0, 1, missing=0, outliers=0)[0]
    z[1] = np.nan
    z[2, 0] = np.nan
    imm.step(z)
    assert np.isnan(imm.nis[[1, 2]]).all() and np.isfinite(imm.nis[[0, 3]]).all()
    assert np.isnan(imm.log_likelihood[[1, 2]]).all() and not imm.gated.any()


def test_empty_batch_and_append_to_empty():
    pre, args = seed_model()
    imm = IMM(x0=np.zeros((0, 5)), P0=np.eye(5), mu0=pre.mu0(), **args)
    assert imm.B == 0
    imm.step(np.zeros((0, 2)))
    xs, Ps = imm.predict_modes(3)
    assert xs.shape == (0, 3, 3, 5) and Ps.shape == (0, 3, 3, 5, 5)
    idx = imm.append(np.ones((2, 5)), np.eye(5), pre.mu0())
    np.testing.assert_array_equal(idx, [0, 1])
    imm.step(np.ones((2, 2)))
    assert imm.B == 2 and np.all(np.isfinite(imm.x))
    imm.remove([0, 1])
    assert imm.B == 0


# ---------------------------------------------------------------- validation
def _kwargs(**over):
    pre, args = seed_model()
    kw = dict(args, x0=np.zeros((2, 5)), P0=np.eye(5), mu0=pre.mu0())
    kw.update(over)
    return kw


@pytest.mark.parametrize(
    "over, match",
    [
        (dict(transitions=np.zeros((3, 5, 4))), "transitions"),
        (dict(transitions=np.full((3, 5, 5), np.nan)), "non-finite"),
        (dict(process_noise=np.zeros((2, 5, 5))), "process_noise"),
        (dict(process_noise=-np.eye(5)), "positive semi-definite"),
        (dict(process_noise=np.triu(np.ones((5, 5)))), "symmetric"),
        (dict(measurement_matrix=np.zeros((2, 4))), "measurement_matrix"),
        (dict(measurement_noise=np.eye(3)), "measurement_noise"),
        (dict(measurement_noise=np.zeros((2, 2))), "positive definite"),
        (dict(transition_matrix=np.full((3, 3), 0.5)), "row 0 sums"),
        (dict(transition_matrix=np.eye(2)), r"\(3, 3\)"),
        (dict(x0=np.zeros(5)), "x0"),
        (dict(x0=np.zeros((2, 4))), "x0"),
        (dict(x0=np.array([[0, 0, 0, 0, np.inf]] * 2)), "non-finite"),
        (dict(P0=np.zeros((3, 5, 5))), "P0"),
        (dict(P0=np.diag([1.0, 1, 1, 1, -1])), "positive definite"),
        (dict(mu0=[0.5, 0.5]), "mu0"),
        (dict(mu0=[0.5, 0.6, -0.1]), "negative"),
        (dict(mu0=[0.5, 0.4, 0.0]), "sums to"),
        (dict(offsets=np.zeros((3, 4))), "offsets"),
        (dict(gate_probability=0.0), "gate_probability"),
        (dict(gate_probability=1.5), "gate_probability"),
        (dict(gate_probability="high"), "gate_probability"),
    ],
)
def test_constructor_validation(over, match):
    with pytest.raises(UserError, match=match):
        IMM(**_kwargs(**over))


def test_method_validation():
    imm = IMM(**_kwargs())
    with pytest.raises(UserError, match="shape"):
        imm.step(np.zeros((3, 2)))
    with pytest.raises(UserError, match="out of range"):
        imm.remove([2])
    with pytest.raises(UserError, match="integers"):
        imm.remove([0.5])
    with pytest.raises(UserError, match="steps"):
        imm.predict_modes(-1)
    with pytest.raises(UserError, match="x0"):
        imm.append(np.zeros((1, 4)), np.eye(5), [1, 0, 0])
    assert imm.B == 2


# ---------------------------------------------------------------- append / remove
def test_append_remove_keep_others_bit_for_bit():
    rng = np.random.default_rng(4)
    _, args = seed_model()
    B, T = 40, 60
    x0, P0, mu0 = initial(rng, B)
    z = measurements(rng, x0, T)
    ref = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    ref_hist = []
    for k in range(T):
        ref.step(z[k])
        ref_hist.append(snapshot(ref))

    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    orig = np.arange(B)  # original index of each current row (-1 = added later)
    xa, Pa, mua = initial(rng, 9)
    za = measurements(rng, xa, T)
    for k in range(T):
        if k == 10:
            new = imm.append(xa, Pa, mua)
            np.testing.assert_array_equal(new, np.arange(B, B + 9))
            orig = np.concatenate([orig, -1 - np.arange(9)])
        if k == 25:
            drop = np.array([0, 3, 17, 39, 41, 44])
            imm.remove(drop)
            orig = np.delete(orig, drop)
        if k == 40:
            mask = np.zeros(imm.B, dtype=bool)
            mask[[1, 5, -1]] = True
            imm.remove(mask)
            orig = orig[~mask]
        zk = np.where(
            orig[:, None] >= 0, z[k][np.maximum(orig, 0)], za[k][np.maximum(-1 - orig, 0)]
        )
        imm.step(zk)
        kept = np.flatnonzero(orig >= 0)
        assert_same_bits(snapshot(imm, kept), {n: v[orig[kept]] for n, v in ref_hist[k].items()})
    assert imm.B == B + 9 - 6 - 3


# ---------------------------------------------------------------- determinism
def test_same_inputs_same_bits():
    rng = np.random.default_rng(5)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 100)
    z = measurements(rng, x0, 30)
    runs = []
    for _ in range(2):
        imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
        for k in range(30):
            imm.step(z[k])
        runs.append(snapshot(imm))
    assert_same_bits(*runs)


def test_result_independent_of_batch_composition():
    """Tracker b gives the same bits alone, in its batch, or in a shuffled, larger batch."""
    rng = np.random.default_rng(6)
    _, args = seed_model()
    B, T = 70, 25  # > one SIMD chunk, with a partial last chunk
    x0, P0, mu0 = initial(rng, B)
    z = measurements(rng, x0, T)
    together = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    perm = rng.permutation(B)
    shuffled = IMM(x0=x0[perm], P0=P0[perm], mu0=mu0[perm], **args)
    singles = [
        IMM(x0=x0[b : b + 1], P0=P0[b : b + 1], mu0=mu0[b : b + 1], **args) for b in range(B)
    ]
    for k in range(T):
        together.step(z[k])
        shuffled.step(z[k][perm])
        for b, s in enumerate(singles):
            s.step(z[k][b : b + 1])
    t = snapshot(together)
    s = snapshot(shuffled)
    inv = np.argsort(perm)
    assert_same_bits(t, {n: v[inv] for n, v in s.items()})
    one = {n: np.concatenate([snapshot(s)[n] for s in singles]) for n in STATE}
    assert_same_bits(t, one)


# ---------------------------------------------------------------- predict_modes
def test_predict_modes_matches_repeated_multiplication():
    rng = np.random.default_rng(7)
    _, args = seed_model()
    x0, P0, mu0 = initial(rng, 6)
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    z = measurements(rng, x0, 5, missing=0, outliers=0)
    for k in range(5):
        imm.step(z[k])
    steps = 4
    xs, Ps = imm.predict_modes(steps)
    assert xs.shape == (6, 3, steps, 5) and Ps.shape == (6, 3, steps, 5, 5)
    F, Q, U = args["transitions"], args["process_noise"], args["offsets"]
    for b in range(6):
        for j in range(3):
            x, P = imm.x_modes[b, j].copy(), imm.P_modes[b, j].copy()
            for t in range(steps):
                x = F[j] @ x + U[j]
                P = F[j] @ P @ F[j].T + Q[j]
                np.testing.assert_allclose(xs[b, j, t], x, rtol=1e-12, atol=1e-9)
                np.testing.assert_allclose(Ps[b, j, t], P, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(Ps, np.swapaxes(Ps, -1, -2))
    x_before = np.array(imm.x)
    assert imm.predict_modes(0)[0].shape == (6, 3, 0, 5)
    np.testing.assert_array_equal(imm.x, x_before)  # no side effect


@pytest.mark.parametrize("preset", ["seed", "realistic"])
def test_predict_modes_at_equals_every_step_prediction_sampled(preset):
    # the k-step maps against the step-by-step kernel (and through it the loop above)
    rng = np.random.default_rng(11)
    p = presets.get(preset)
    B = 7
    x0, P0, _ = initial(rng, B)
    imm = IMM(**p.imm_arguments(), x0=x0, P0=P0, mu0=p.mu0())
    z = measurements(rng, x0, 6, missing=0, outliers=0)
    for k in range(6):
        imm.step(z[k])
    steps = np.array([1, 2, 5, 12, 40, 120])
    full_x, full_P = imm.predict_modes(int(steps[-1]))
    rows = np.array([5, 0, 3])
    xs, Ps = imm.predict_modes_at(steps, rows)
    assert xs.shape == (3, 3, 6, 5) and Ps.shape == (3, 3, 6, 5, 5)
    ref_x, ref_P = full_x[rows][:, :, steps - 1], full_P[rows][:, :, steps - 1]
    np.testing.assert_allclose(xs, ref_x, rtol=1e-9, atol=0)
    diag = np.sqrt(np.einsum("...ii->...i", ref_P))
    # covariances relative to the standard deviations (entries near 0 off the diagonal)
    np.testing.assert_allclose(
        Ps / (diag[..., :, None] * diag[..., None, :]),
        ref_P / (diag[..., :, None] * diag[..., None, :]),
        atol=1e-9,
    )
    np.testing.assert_array_equal(Ps, np.swapaxes(Ps, -1, -2))
    all_x, _ = imm.predict_modes_at(steps)
    np.testing.assert_array_equal(all_x[rows], xs)
    with pytest.raises(UserError, match="increasing"):
        imm.predict_modes_at([3, 2])
    with pytest.raises(UserError, match="positive"):
        imm.predict_modes_at([0, 1])


# ---------------------------------------------------------------- benchmark and CLI
def test_benchmark_function_tiny():
    res = run_benchmark(sizes=(1, 3), steps=2, repeats=2, filterpy_updates=4)
    assert [r["B"] for r in res["rows"]] == [1, 3]
    for r in res["rows"]:
        assert r["ours_updates_per_s"] > 0 and len(r["ours_all"]) == 2
        assert r["filterpy_updates_per_s"] > 0 and r["ratio"] > 0
    assert "ours updates/s" in format_table(res)
    with pytest.raises(UserError):
        run_benchmark(sizes=(0,), steps=1, repeats=1)


def test_bench_cli_tiny(tmp_path, capsys):
    out = tmp_path / "sub" / "bench.json"
    rc = cli_main(["bench", "--sizes", "2,5", "--steps", "2", "--repeats", "1",
                   "--filterpy-updates", "3", "--json", str(out)])  # fmt: skip
    assert rc == 0
    text = capsys.readouterr().out
    assert "filterpy" in text and "ratio" in text
    data = json.loads(out.read_text())
    assert [r["B"] for r in data["rows"]] == [2, 5]
    assert cli_main(["bench", "--sizes", "x"]) == 2
