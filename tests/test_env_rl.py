"""What RL training needs: SuperSuit vectorisation (with processes) and SB3 PPO through
episode ends, many agents, randomised geometry, reset options, the global state, ended
agents flying the resolver or leaving.
"""

import math

import numpy as np
import pytest

import airspace_sim.env as aenv
from airspace_sim.scenarios import load

# west arrives after ~44 steps, east flies on: agents end at different times
STAGGERED = dict(
    scenario="head_on",
    agents=2,
    max_cycles=70,
    overrides=["aircraft[0].waypoints=[[-10000.0, 0.0]]"],
)


# ------------------------------------------------------------------ vectorisation


@pytest.mark.parametrize("num_cpus", [0, 2])
def test_supersuit_chain_runs_through_episode_ends(num_cpus):
    from airspace_sim.env.vector import supersuit_vec_env

    venv = supersuit_vec_env(num_vec_envs=2, num_cpus=num_cpus, **STAGGERED)
    try:
        assert venv.num_envs == 4  # 2 copies × 2 agents
        obs, _ = venv.reset(seed=3)
        assert obs.shape == (4, venv.observation_space.shape[-1])
        rng = np.random.default_rng(0)
        ends = 0
        for _ in range(160):  # more than two episodes
            act = rng.uniform(-1, 1, (4, 1)).astype(np.float32)
            obs, rew, term, trunc, _ = venv.step(act)
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
            ends += int(np.sum(term | trunc))
        assert ends >= 8  # every slot saw at least two episode ends
    finally:
        venv.close()


def test_sb3_ppo_trains_and_is_repeatable_with_processes():
    pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO

    from airspace_sim.env.vector import sb3_vec_env

    torch.set_num_threads(1)
    params = []
    for num_cpus in (2, 0):  # processes or not, the same seed trains the same policy
        venv = sb3_vec_env(num_vec_envs=2, num_cpus=num_cpus, **STAGGERED)
        try:
            model = PPO("MlpPolicy", venv, n_steps=50, batch_size=100, n_epochs=1, seed=7)
            model.learn(400)  # 2 rollouts of 50 vector steps × 4 slots, through episode ends
            params.append([p.detach().numpy().copy() for p in model.policy.parameters()])
        finally:
            venv.close()
    assert all(np.array_equal(a, b) for a, b in zip(*params))


# -------------------------------------------------------------------- many agents


@pytest.mark.parametrize("name,n", [("ring4", 4), ("ring8", 8), ("dense8", 8)])
def test_multi_agent_ids_make_every_aircraft_an_agent(name, n):
    import pettingzoo

    assert aenv.env_id(name) in aenv.REGISTERED_IDS
    env = pettingzoo.make("parallel", aenv.env_id(name), max_cycles=3)
    obs, _ = env.reset(seed=0)
    assert len(env.possible_agents) == n == env.world.n == len(obs)
    assert env.possible_agents == env.world.ids


# -------------------------------------------------------------- randomised geometry


def test_ring_geometry_is_drawn_within_the_stated_ranges():
    env = aenv.make("ring8")
    sc = env.scenario
    r = sc.randomise
    seen = []
    for seed in range(6):
        env.reset(seed=seed)
        w = env.world
        for s in w.specs:
            # the waypoint is the diametric point of the drawn ring: |wp| is the radius
            radius = math.hypot(*s.waypoints[0])
            assert r.radius[0] <= radius <= r.radius[1]
            assert r.speed[0] <= s.speed <= r.speed[1]
            start = math.hypot(*s.position)
            # start delay: speed · delay metres back along the (offset) heading
            assert radius - 1e-6 <= start <= radius + s.speed * r.start_s[1] + 1e-6
            to_centre = math.degrees(math.atan2(-s.position[1], -s.position[0]))
            off = (s.heading_deg - to_centre + 180) % 360 - 180
            assert abs(off) <= r.heading_deg[1] + 1e-6
        seen.append(w.positions.copy())
    assert all(not np.allclose(seen[0], p) for p in seen[1:])  # the seed draws the geometry
    env.reset(seed=2)
    assert np.array_equal(env.world.positions, seen[2])  # and the same seed replays it


def test_without_randomise_every_seed_flies_the_closed_form_ring():
    sc = load("ring", ["traffic.count=8", "traffic.radius=20000.0"])
    env = aenv.parallel_env(scenario=sc, agents="all", max_cycles=2)
    for seed in (0, 1, 5):
        env.reset(seed=seed)
        a = 2 * np.pi * np.arange(8) / 8
        expect = 20000.0 * np.stack([np.cos(a), np.sin(a)], axis=1)
        np.testing.assert_allclose(env.world.positions, expect, atol=1e-9)


def test_bad_randomise_ranges_are_one_line_errors():
    from airspace_sim.errors import UserError

    with pytest.raises(UserError, match="randomise.radius: expected a low end of at least"):
        load("ring", ["traffic.count=8", "randomise.radius=[1000.0, 30000.0]"])
    with pytest.raises(UserError, match=r"randomise.speed: expected \[low, high\]"):
        load("head_on", ["randomise.speed=[250.0, 200.0]"])
    # hand-placed aircraft are randomised too
    sc = load("head_on", ["randomise.heading_deg=[-20.0, 20.0]"])
    env = aenv.parallel_env(scenario=sc, agents=2)
    env.reset(seed=0)
    h0 = env.world.headings.copy()
    env.reset(seed=1)
    assert not np.allclose(h0, env.world.headings)


# -------------------------------------------------------------------- reset options


def test_reset_options_change_the_knobs_for_one_episode():
    env = aenv.make("ring8", max_cycles=5)
    obs, _ = env.reset(seed=0, options={"traffic_count": 4, "sensor_sigma": 10.0})
    assert env.agents == ["ring00", "ring01", "ring02", "ring03"] and set(obs) == set(env.agents)
    assert env.world.n == 4 and env.world.scenario.sensor.sigma == 10.0
    state = env.state().reshape(8, -1)
    assert np.all(state[:4, 0] == 1) and np.all(state[4:] == 0)  # padded rows
    while env.agents:
        env.step({})
    env.reset(seed=0)  # options apply to that episode only
    assert len(env.agents) == 8 and env.world.scenario.sensor.sigma == 50.0

    dense = aenv.make("dense8", max_cycles=3)
    dense.reset(seed=0, options={"density": 3.0})  # half the density: a √2 wider sector
    side = dense.world.scenario.traffic.sector
    assert np.isclose(side, math.sqrt(8 / 3.0 * 1e9))
    assert np.all(np.abs(dense.world.positions) <= side / 2)
    with pytest.warns(UserWarning, match="unknown key"):
        env.reset(seed=0, options={"bogus": 1})
    from airspace_sim.errors import UserError

    with pytest.raises(UserError, match="max_aircraft"):
        env.reset(options={"traffic_count": 9})


# ------------------------------------------------------------------- global state


def test_global_state_is_every_aircraft_absolute_and_masked():
    # 3 agents among 8 aircraft: the state holds the background traffic too
    env = aenv.parallel_env(scenario="demo", agents=3, max_cycles=30)
    env.reset(seed=1)
    for _ in range(10):
        env.step({a: np.full(1, 0.3, np.float32) for a in env.agents})
    s = env.state()
    assert env.state_space.contains(s) and s.shape == env.state_space.shape
    rows = s.reshape(env.max_aircraft, len(aenv.STATE_NAMES))
    w = env.world
    act = w.active
    assert np.array_equal(rows[:, 0] == 1, act)
    S = env.state_scale_m
    np.testing.assert_allclose(rows[act, 1], np.clip(w.positions[act, 0] / S, -1, 1), atol=1e-6)
    np.testing.assert_allclose(rows[act, 2], np.clip(w.positions[act, 1] / S, -1, 1), atol=1e-6)
    np.testing.assert_allclose(rows[act, 3], w.velocities[act, 0] / 600, atol=1e-6)
    np.testing.assert_allclose(rows[act, 5], np.sin(w.headings[act]), atol=1e-6)
    agent = np.isin(w.ids, env.agents)
    assert np.array_equal(rows[:, 8] == 1, agent & act)
    assert np.all(rows[~act] == 0)


# ---------------------------------------------------------------- ended agents


def collide(ended):
    """Head-on agents flown straight into each other; returns the env right after their
    NMAC, with both ended."""
    env = aenv.parallel_env(scenario="head_on", agents=2, max_cycles=200, ended=ended)
    env.reset(seed=0)
    while env.agents:
        _, _, term, _, info = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert all(term.values()) and all(i["nmac"] for i in info.values())
    return env


@pytest.mark.parametrize("resolver,collides", [("bands", False), ("none", True)])
def test_ended_agents_keep_flying_with_the_resolver(resolver, collides):
    # the agents' episodes end (truncated) long before the head-on conflict; the world flies
    # on with the built-in pilots: with the resolver the ended agents avoid each other,
    # without one (the oracle that they would meet) they collide
    env = aenv.parallel_env(
        scenario="head_on", agents=2, max_cycles=10, overrides=[f"resolver.kind={resolver}"]
    )
    env.reset(seed=0)
    while env.agents:
        env.step({a: np.zeros(1, np.float32) for a in env.agents})
    w = env.world
    for _ in range(150):
        w.step(np.full(w.n, np.nan))
    m = w.metrics()
    assert (m["nmac_events"] > 0) == collides
    assert (m["los_events"] > 0) == collides


def test_ended_agents_can_leave_the_world():
    env = collide("leave")
    w = env.world
    assert not w.active.any() and not w.in_los.any() and not w.nmac.any()
    assert env.step({}) == ({}, {}, {}, {}, {})  # what black_death_v3 calls once more


def test_pettingzoo_parallel_api_test_on_a_multi_agent_ring():
    from pettingzoo.test import parallel_api_test

    parallel_api_test(aenv.make("ring4", max_cycles=20), num_cycles=25)


def test_a_randomised_multi_agent_env_pickles_mid_episode():
    import pickle

    env = aenv.make("ring4", max_cycles=30)
    env.reset(seed=4, options={"traffic_count": 3})
    for _ in range(5):
        env.step({a: np.full(1, 0.2, np.float32) for a in env.agents})
    copy = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        act = {a: np.full(1, -0.4, np.float32) for a in env.agents}
        o1, r1, *_ = env.step(act)
        o2, r2, *_ = copy.step(act)
        assert r1 == r2 and all(np.array_equal(o1[a], o2[a]) for a in o1)
    assert np.array_equal(env.state(), copy.state())


def test_bench_env_command(tmp_path, capsys):
    import json

    from airspace_sim.cli import main

    out = tmp_path / "bench.json"
    args = ["bench-env", "--env", "head_on", "--steps", "5", "--repeats", "1"]
    assert main(args + ["--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["agents"] == 1 and r["env_ms_per_step"] > 0 and r["world_ms_per_step"] > 0
    assert "env / world" in capsys.readouterr().out
    assert main(args + ["--json", str(tmp_path / "missing" / "b.json")]) == 2
    err = capsys.readouterr().err
    assert "no such folder" in err and err.count("\n") == 1
