"""Rewards: no policy that collides beats one that avoids.

Fixed policies on small rings where every aircraft is an agent (straight flight into the
8-way collision, uniform random turns, the built-in autopilot and resolver, and "advice +
steer to the waypoint" read from the observation) must come out in the order of their
safety; and every step's reward must respect the bound that makes this hold for any policy
(rewards docstring): r ≥ -c_max without an NMAC, and with one on step t the NMAC term is
≤ -(w_nmac + (T - t + 1) c_max) and the whole reward below what any step without one could
pay; c_max recomputed here from the weights.
"""

import numpy as np
import pytest

import airspace_sim.env as aenv

RING = ["traffic.count=8", "traffic.radius=9000.0", "duration=90.0"]
BUILTIN_COMMAND = 13  # own.builtin_command


def ring_env(overrides=RING, **kw):
    return aenv.parallel_env(scenario="ring", agents="all", overrides=overrides, **kw)


def play(env, policy, seed):
    """Mean return per agent, the world's LoS and NMAC counts, every step's rewards."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    ret = dict.fromkeys(env.agents, 0.0)
    steps = []
    while env.agents:
        if policy == "straight":
            act = {a: np.zeros(1, np.float32) for a in env.agents}
        elif policy == "random":
            act = {a: rng.uniform(-1, 1, 1).astype(np.float32) for a in env.agents}
        elif policy == "builtin":
            act = {a: None for a in env.agents}
        else:  # advice + steer to the waypoint, from the observation
            act = {a: obs[a][BUILTIN_COMMAND : BUILTIN_COMMAND + 1] for a in env.agents}
        obs, rew, term, trunc, info = env.step(act)
        for a in rew:
            ret[a] += rew[a]
        steps.append((env.num_cycles, rew, info))
    m = env.world.metrics()
    return float(np.mean(list(ret.values()))), m["los_events"], m["nmac_events"], steps


@pytest.fixture(scope="module")
def results():
    env = ring_env()
    return {
        p: [play(env, p, s) for s in (0, 1)] for p in ("straight", "random", "builtin", "advice")
    }


def test_policies_come_out_in_order_of_safety(results):
    for s in range(2):
        straight, random, builtin, advice = (
            results[p][s] for p in ("straight", "random", "builtin", "advice")
        )
        assert straight[2] >= 8  # the 8-way collision: every agent in an NMAC
        assert builtin[1] == builtin[2] == 0 and advice[2] == 0
        assert random[2] < straight[2]
        # returns follow: avoiders > random flyer > straight into the collision
        assert min(builtin[0], advice[0]) > random[0] > straight[0]


def test_every_step_respects_the_bound(results):
    w = aenv.DEFAULT_WEIGHTS
    env = ring_env()
    env.reset(seed=0)
    T = env.max_cycles
    world = env.world
    L = 2 * 9000.0  # every route crosses the ring
    seen_nmac = 0
    for runs in results.values():
        for *_, steps in runs:
            for t, rew, info in steps:
                for a, r in rew.items():
                    v = world.speeds[world.index(a)]
                    c_max = w["los"] + w["conflict"] + w["heading_change"]
                    c_max += (w["progress"] + 2 * w["path"]) * v * world.dt / L
                    terms = info[a]["reward_terms"]
                    if info[a]["nmac"]:
                        seen_nmac += 1
                        assert terms["nmac"] <= -(w["nmac"] + (T - t + 1) * c_max) + 1e-9
                        assert r <= -(w["nmac"] + (T - t) * c_max)
                    else:
                        assert terms["nmac"] == 0.0
                        assert r >= -c_max - 1e-9
    assert seen_nmac >= 16


def test_terms_sum_to_the_reward_and_progress_telescopes():
    ring4 = ["traffic.count=4", "traffic.radius=9000.0", "duration=150.0"]
    env = ring_env(overrides=ring4, reward={"arrival": 0.0})
    env.reset(seed=3)
    total = {}
    while env.agents:
        # turn left a little, then the built-in pilot flies the rest of the route
        act = {a: (0.6 if env.num_cycles < 10 else None) for a in env.agents}
        _, rew, term, _, info = env.step(act)
        for a, r in rew.items():
            assert np.isclose(r, sum(info[a]["reward_terms"].values()))
            t = total.setdefault(a, {"progress": 0.0, "path": 0.0, "arrived": False, "n": 0})
            t["n"] += 1
            t["v"] = env.world.speeds[env.world.index(a)]
            t["progress"] += info[a]["reward_terms"]["progress"]
            t["path"] += info[a]["reward_terms"]["path"]
            t["arrived"] |= info[a]["arrived"]
    done = [t for t in total.values() if t["arrived"]]
    assert done
    for t in done:
        # potential-based: the progress of a whole route is 1 (the route length over itself)
        assert np.isclose(t["progress"], 1.0, atol=1e-9)
        # and the path term is minus the extra path flown, over the route length
        L = 2 * 9000.0
        flown = t["n"] * t["v"] * env.world.dt
        assert t["path"] < 0
        assert np.isclose(t["path"], -(flown - L) / L, atol=1e-9)
