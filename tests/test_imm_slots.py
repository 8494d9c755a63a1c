"""The slot storage of the IMM (:class:`SlotIMM`): births, drops, reuse and growth.

Oracles: an independent dense :class:`IMM` per track (one tracker, no slots ever freed or
reused, so nothing but its own data in its batch): the same bits, since a tracker's result
does not depend on its lane, chunk or neighbours; and filterpy's ``IMMEstimator`` for a few
tracks (to the tolerance of tests/test_imm_filterpy.py). Free lanes are checked by their
raw state, which must never change while they are free.
"""

from __future__ import annotations

import pickle
import re
import warnings

import numpy as np
import pytest

from airspace_sim.dynamics import presets
from airspace_sim.errors import UserError
from airspace_sim.tracking import IMM
from airspace_sim.tracking.imm import SlotIMM
from airspace_sim.tracking.keymap import KeyMap
from airspace_sim.tracking.slots import Slots

KERNELS = ["generated", "loops"]


def model(sigma=50.0):
    p = presets.get("realistic").with_(measurement_sigma=sigma)
    return p, p.imm_arguments()


def new_tracks(rng, k):
    x0 = np.zeros((k, 5))
    x0[:, [0, 2]] = rng.uniform(-2e4, 2e4, (k, 2))
    x0[:, [1, 3]] = rng.uniform(-250, 250, (k, 2))
    P0 = np.diag([2500.0, 400.0, 2500.0, 400.0, 1e-3])
    P0 = np.broadcast_to(P0, (k, 5, 5)) * rng.uniform(0.5, 2.0, (k, 1, 1))
    return x0, P0


def raw_lane(s: SlotIMM, slot):
    """The stored mode-conditioned state of one lane (copies)."""
    c, w = divmod(int(slot), s._W)
    return s._xs[c, ..., w].copy(), s._Ps[c, ..., w].copy(), s._mus[c, ..., w].copy()


@pytest.mark.parametrize("kernel", KERNELS)
def test_random_births_drops_steps_equal_one_imm_per_track(kernel):
    """A random life of births (into reused and new lanes, with growth), drops, steps with
    missing measurements: every live track equals, bit for bit, its own one-tracker IMM."""
    rng = np.random.default_rng(7)
    p, args = model()
    mu0 = p.mu0()
    s = SlotIMM(**args, kernel=kernel)
    refs: dict[int, IMM] = {}  # slot -> reference
    truth: dict[int, np.ndarray] = {}
    caps = []
    for step in range(60):
        live = np.array(sorted(refs), dtype=np.int64)
        if live.size and step % 3 == 0:
            gone = rng.choice(live, size=rng.integers(0, max(1, live.size // 3)), replace=False)
            s.drop(gone)
            for g in gone:
                del refs[int(g)], truth[int(g)]
        k = int(rng.integers(0, 25))
        x0, P0 = new_tracks(rng, k)
        slots = s.birth(x0, P0, mu0)
        assert len(set(slots.tolist()) & set(refs)) == 0
        for i, sl in enumerate(slots):
            refs[int(sl)] = IMM(**args, x0=x0[i : i + 1], P0=P0[i], mu0=mu0, kernel=kernel)
            truth[int(sl)] = x0[i].copy()
        caps.append(s.capacity)
        Z = np.full((s.capacity, 2), np.nan)
        for sl, xt in truth.items():
            xt[[0, 2]] += xt[[1, 3]] * p.dt
            if rng.random() > 0.2:  # else missed: predict only
                Z[sl] = xt[[0, 2]] + 50.0 * rng.standard_normal(2)
        s.step(Z)
        for sl, ref in refs.items():
            ref.step(Z[sl : sl + 1])
        live = np.array(sorted(refs), dtype=np.int64)
        assert np.array_equal(np.flatnonzero(s.alive), live)
        assert s.n_live == live.size
        for sl in live:
            ref = refs[int(sl)]
            for got, want in ((s.x, ref.x), (s.P, ref.P), (s.mu, ref.mu), (s.nis, ref.nis)):
                np.testing.assert_array_equal(got[sl], want[0])
        xm, Pm = s.modes(live)
        np.testing.assert_array_equal(xm, np.concatenate([refs[int(i)].x_modes for i in live]))
        np.testing.assert_array_equal(Pm, np.concatenate([refs[int(i)].P_modes for i in live]))
        free = ~s.alive
        assert np.isnan(s.x[free]).all() and not s.gated[free].any()
    # capacity grew geometrically, in whole chunks, and never shrank
    assert all(c % s._W == 0 for c in caps) and caps == sorted(caps) and caps[-1] > caps[0]
    assert all(b >= 2 * a for a, b in zip(caps, caps[1:], strict=False) if b != a)


def test_slots_equal_filterpy_for_a_few_tracks():
    """Tracks born into reused lanes of a fragmented table still equal filterpy."""
    pytest.importorskip("filterpy")
    from test_imm_filterpy import assert_posterior_close, filterpy_imm, filterpy_step

    rng = np.random.default_rng(3)
    p, args = model()
    mu0 = p.mu0()
    s = SlotIMM(**args)
    x0, P0 = new_tracks(rng, 100)
    s.birth(x0, P0, mu0)
    s.drop(np.arange(0, 100, 3))  # holes in every chunk
    x1, P1 = new_tracks(rng, 4)
    slots = s.birth(x1, P1, mu0)
    assert set(slots.tolist()) <= set(range(0, 100, 3))  # freed lanes are reused
    fps = [filterpy_imm(args, x1[i], P1[i], mu0) for i in range(4)]
    xt = x1.copy()
    for _ in range(40):
        xt[:, [0, 2]] += xt[:, [1, 3]] * p.dt
        Z = np.full((s.capacity, 2), np.nan)
        Z[slots] = xt[:, [0, 2]] + 50.0 * rng.standard_normal((4, 2))
        s.step(Z)
        for f, z in zip(fps, Z[slots], strict=True):
            filterpy_step(f, z)
        assert_posterior_close(
            s.x[slots], s.P[slots], s.mu[slots],
            np.array([f.x[:, 0] for f in fps]),
            np.array([f.P for f in fps]),
            np.array([f.mu for f in fps]),
        )  # fmt: skip


@pytest.mark.parametrize("kernel", KERNELS)
def test_births_and_drops_touch_only_their_lanes(kernel):
    """Births and drops elsewhere (including a growth) leave every other slot's stored
    state and outputs bit-identical."""
    rng = np.random.default_rng(1)
    p, args = model()
    s = SlotIMM(**args, kernel=kernel)
    x0, P0 = new_tracks(rng, 40)
    slots = s.birth(x0, P0, p.mu0())
    Z = np.full((s.capacity, 2), np.nan)
    Z[slots] = x0[:, [0, 2]]
    s.step(Z)
    keep = slots[::2]
    before = [raw_lane(s, sl) for sl in keep]
    outs = [a[keep].copy() for a in (s.x, s.P, s.mu, s.nis, s.log_likelihood, s.gated)]
    s.drop(slots[1::2])
    x1, P1 = new_tracks(rng, 3 * s.capacity)  # reuses the holes, then grows
    s.birth(x1, P1, p.mu0())
    s.drop(s.birth(x1[:5], P1[:5], p.mu0()))
    for sl, lane in zip(keep, before, strict=True):
        for a, b in zip(raw_lane(s, sl), lane, strict=True):
            np.testing.assert_array_equal(a, b)
    for a, b in zip((s.x, s.P, s.mu, s.nis, s.log_likelihood, s.gated), outs, strict=True):
        np.testing.assert_array_equal(a[keep], b)


@pytest.mark.parametrize("kernel", KERNELS)
def test_free_lanes_are_frozen_and_never_nan(kernel):
    """A free lane holds the benign state written when it was freed and the kernel never
    writes it: bit-identical after thousands of steps (so after any number), no NaN, no
    overflow, no warning — whatever garbage the free rows of z hold."""
    rng = np.random.default_rng(5)
    p, args = model()
    s = SlotIMM(**args, kernel=kernel, capacity=200)
    x0, P0 = new_tracks(rng, 3 * s._W)
    slots = s.birth(x0, P0, p.mu0())
    freed = slots[1::5]
    s.drop(freed)  # free lanes inside live chunks
    never = np.flatnonzero(~s.alive)[-1]  # a lane of a chunk never used
    lanes = {int(sl): raw_lane(s, sl) for sl in list(freed) + [never]}
    live = np.flatnonzero(s.alive)
    xt = x0[np.isin(slots, live)].copy()
    Z = np.full((s.capacity, 2), np.inf)  # free rows: garbage, never read
    Z[~s.alive] = 1e308
    with warnings.catch_warnings(), np.errstate(all="raise"):
        warnings.simplefilter("error")
        for _ in range(3000):
            xt[:, [0, 2]] += xt[:, [1, 3]] * p.dt
            Z[live] = xt[:, [0, 2]] + 50.0 * rng.standard_normal((live.size, 2))
            s.step(Z)
    for sl, lane in lanes.items():
        for a, b in zip(raw_lane(s, sl), lane, strict=True):
            np.testing.assert_array_equal(a, b)
        assert np.all(np.isfinite(lane[0])) and np.all(np.isfinite(lane[1]))
    assert np.all(np.isfinite(s.x[live])) and np.all(np.isfinite(s.P[live]))
    assert np.isnan(s.x[~s.alive]).all()
    # the live tracks are on target (the free lanes disturbed nothing)
    assert np.sqrt(np.mean((s.x[live][:, [0, 2]] - xt[:, [0, 2]]) ** 2)) < 50.0


@pytest.mark.parametrize("kernel", KERNELS)
def test_pickle_after_births_and_drops_continues_bit_for_bit(kernel):
    rng = np.random.default_rng(2)
    p, args = model()
    s = SlotIMM(**args, kernel=kernel)
    x0, P0 = new_tracks(rng, 50)
    slots = s.birth(x0, P0, p.mu0())
    s.drop(slots[::4])
    imm = IMM(**args, x0=x0, P0=P0, mu0=p.mu0(), kernel=kernel)
    imm.remove(np.arange(0, 50, 4))
    copies = [pickle.loads(pickle.dumps(o)) for o in (s, imm)]
    assert copies[0].kernel == copies[1].kernel == kernel
    for _ in range(5):
        z = x0[:, [0, 2]] + 30.0 * rng.standard_normal((50, 2))
        Z = np.full((s.capacity, 2), np.nan)
        Z[: z.shape[0]] = z
        zd = np.delete(z, np.arange(0, 50, 4), axis=0)
        s.step(Z)
        copies[0].step(Z)
        imm.step(zd)
        copies[1].step(zd)
    for a, b in ((s, copies[0]), (imm, copies[1])):
        for name in ("x", "P", "mu", "nis"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(s.alive, copies[0].alive)
    np.testing.assert_array_equal(imm.x, s.x[s.alive])  # the dense view, in row order


def test_dense_imm_remove_append_keep_row_order_over_reused_slots():
    rng = np.random.default_rng(4)
    p, args = model()
    x0, P0 = new_tracks(rng, 10)
    imm = IMM(**args, x0=x0, P0=P0, mu0=p.mu0())
    imm.remove([1, 4, 4, -1])  # repeated and negative indices, as numpy would
    x1, P1 = new_tracks(rng, 3)
    assert imm.append(x1, P1, p.mu0()).tolist() == [7, 8, 9]
    want = np.concatenate([np.delete(x0, [1, 4, 9], axis=0), x1])
    ref = IMM(**args, x0=want, P0=np.concatenate([np.delete(P0, [1, 4, 9], 0), P1]), mu0=p.mu0())
    np.testing.assert_array_equal(imm.x, ref.x)
    # the new rows went into the freed slots, and the view follows the row order
    assert sorted(imm._rows[7:].tolist()) == [1, 4, 9]
    for _ in range(3):
        Z = want[:, [0, 2]] + 10.0
        imm.step(Z)
        ref.step(Z)
    for name in ("x", "P", "mu", "x_modes", "P_modes", "nis", "log_likelihood", "gated"):
        np.testing.assert_array_equal(getattr(imm, name), getattr(ref, name))


def test_slot_errors_are_one_line():
    p, args = model()
    s = SlotIMM(**args)
    slots = s.birth(np.zeros((2, 5)), np.eye(5), p.mu0())
    for bad, match in (([100], "out of range"), ([0, 0], "repeated"), ([1.5], "integers")):
        with pytest.raises(UserError, match=match):
            s.drop(bad)
    s.drop([slots[0]])
    with pytest.raises(UserError, match="not live"):
        s.drop([slots[0]])
    with pytest.raises(UserError, match=rf"z must have shape \({s.capacity}, 2\) \(by slot\)"):
        s.step(np.zeros((1, 2)))


def test_slots_free_list_order_and_growth():
    sl = Slots(chunk=8)
    assert sl.capacity_for(3) == 8
    sl.grow(8)
    assert sl.take(3).tolist() == [0, 1, 2]
    sl.release([1])
    assert sl.take(2).tolist() == [1, 3]  # the freed lane first, then the lowest new one
    assert sl.capacity_for(5) == 16 and sl.capacity_for(4) == 8
    sl.grow(16)
    assert sl.take(5).tolist() == [4, 5, 6, 7, 8]
    assert sl.n_live == 9 and sl.live().tolist() == list(range(9))


def test_keymap_against_a_dict_under_random_inserts_and_deletes():
    rng = np.random.default_rng(0)
    km, ref = KeyMap(), {}
    for _ in range(300):
        keys = np.unique(rng.integers(0, 5000, rng.integers(0, 60)))
        if rng.random() < 0.5:
            vals = rng.integers(0, 10**6, keys.size)
            km.put(keys, vals)
            ref.update(zip(keys.tolist(), vals.tolist(), strict=True))
        else:
            km.delete(keys)
            for k in keys.tolist():
                ref.pop(k, None)
        q = rng.integers(0, 5000, 200)
        assert km.get(q).tolist() == [ref.get(k, -1) for k in q.tolist()]
        assert len(km) == len(ref)


def test_slots_release_refuses_bad_slots_and_frees_nothing():
    """Slots.release: out of range, not live and repeated slots are refused in that order,
    with the table unchanged; a good release pushes the slots on the free stack."""
    sl = Slots(4)
    sl.grow(8)
    taken = sl.take(5)
    before = (sl.alive.copy(), sl._free.copy(), sl._n_free)
    for bad, msg in (
        ([1, 9, -1], "slot 9 out of range 0..7"),
        ([0, 6, 7], "slot 6 is not live"),
        ([2, 3, 2], "repeated slots in [2, 3, 2]"),
    ):
        with pytest.raises(UserError, match=re.escape(msg)):
            sl.release(np.array(bad))
        assert sl._n_free == before[2] and np.array_equal(sl.alive, before[0])
        assert np.array_equal(sl._free, before[1])
    out = sl.release(np.array([taken[1], taken[3]], dtype=np.int32))
    assert out.dtype == np.int64 and out.tolist() == [taken[1], taken[3]]
    assert sl.n_live == 3 and sl.take(2).tolist() == [taken[3], taken[1]]
