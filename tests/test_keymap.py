"""KeyMap's (key, value) rows: pickling, and the layout of a map pickled before them."""

import pickle

import numpy as np

from airspace_sim.tracking.keymap import _EMPTY, KeyMap


def _filled(seed=0, n=3000):
    rng = np.random.default_rng(seed)
    keys = rng.choice(10**9, n, replace=False)
    km = KeyMap()
    km.put(keys, np.arange(n))
    km.delete(keys[: n // 3])
    return km, keys


def test_pickled_map_answers_as_the_original():
    km, keys = _filled()
    copy = pickle.loads(pickle.dumps(km))
    query = np.concatenate([keys, [5, 7, 10**9 + 1]])
    np.testing.assert_array_equal(copy.get(query), km.get(query))
    assert len(copy) == len(km) == 2000
    assert (copy.get(keys[:1000]) == -1).all()
    np.testing.assert_array_equal(copy.get(keys[1000:]), np.arange(1000, 3000))


def test_map_pickled_with_separate_key_and_value_arrays_unpickles():
    # the state of a KeyMap before its rows: _k and _v arrays of the table size
    km, keys = _filled(seed=1)
    old = KeyMap.__new__(KeyMap)
    state = dict(vars(km))
    table = state.pop("_t")
    state["_k"], state["_v"] = table[:, 0].copy(), table[:, 1].copy()
    old.__setstate__(state)
    np.testing.assert_array_equal(old.get(keys), km.get(keys))
    old.put([10**9 + 5], [42])  # and it keeps working: insert, grow, delete
    old.put(np.arange(20000) + 2 * 10**9, np.arange(20000))
    old.delete(keys[1000:1500])
    assert old.get([10**9 + 5])[0] == 42 and (old.get(keys[1000:1500]) == -1).all()
    assert len(old) == 2000 + 1 + 20000 - 500
    assert (old._t[:, 0] != _EMPTY).sum() == len(old)
