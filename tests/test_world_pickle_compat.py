"""A world pickled by the code before the step kept derived state (route legs, desired
headings, the scan's pair keys) unpickles and steps exactly as one that never was pickled."""

import pickle

import numpy as np

from airspace_sim.env import make


def test_world_without_kept_state_resumes_bit_for_bit():
    env = make("ring8")
    w = env._make_world(env.scenario, 2)
    rng = np.random.default_rng(0)
    turns = [rng.uniform(-1, 1, w.n) * w.max_turn_rate for _ in range(60)]
    for r in turns[:30]:
        w.step(np.where(w.controlled, r, np.nan))
    old = pickle.loads(pickle.dumps(w))
    # what a world pickled before these caches existed lacks
    old.__dict__.pop("_last_pairs", None)
    for _, ap in old.autopilots:
        for name in ("_rows", "_no_waypoints", "_legs", "_desired"):
            ap.__dict__.pop(name, None)
    old = pickle.loads(pickle.dumps(old))
    for r in turns[30:]:
        w.step(np.where(w.controlled, r, np.nan))
        old.step(np.where(old.controlled, r, np.nan))
    for name in ("positions", "headings", "advice", "conflict"):
        assert getattr(w, name).tobytes() == getattr(old, name).tobytes()
    assert w.tracks.view().x.tobytes() == old.tracks.view().x.tobytes()
    assert w.metrics() == old.metrics() or str(w.metrics()) == str(old.metrics())
