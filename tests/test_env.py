"""PettingZoo env: the official API tests plus determinism, spaces, rewards, errors, frames.

Scenarios are kept short (``max_cycles`` tens of steps) so the whole file runs in seconds.
"""

import subprocess
import sys
import types
import warnings

import numpy as np
import pettingzoo
import pytest
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
)

import airspace_sim.env as aenv
from airspace_sim.env.spaces import DISCRETE_LEVELS
from airspace_sim.errors import UserError

SMALL = dict(scenario="head_on", agents=2, render_size=(240, 240))


def par(**kw):
    return aenv.parallel_env(**{**SMALL, **kw})


def aec(**kw):
    return aenv.env(**{**SMALL, **kw})


# --------------------------------------------------------------------- pettingzoo.test


def test_parallel_api_test():
    parallel_api_test(par(), num_cycles=40)


def test_api_test_on_aec_form():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # naming advice ("player_0") only
        api_test(aec(), num_cycles=30)


def test_render_test_on_aec_form():
    def env_fn(render_mode=None):
        return aec(render_mode=render_mode)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no display" for human mode on a headless box
        render_test(env_fn)


def test_max_cycles_test():
    mod = types.SimpleNamespace(parallel_env=lambda **kw: par(**kw), env=lambda **kw: aec(**kw))
    max_cycles_test(mod)
    # and the package itself (its default scenario) satisfies it too
    max_cycles_test(aenv)


def test_parallel_seed_test():
    parallel_seed_test(lambda: par(), num_cycles=20)


# ------------------------------------------------------------------------ determinism


def rollout(env, seed, steps=100, action_seed=0):
    rng = np.random.default_rng(action_seed)
    obs, infos = env.reset(seed=seed)
    trace = [(obs, infos)]
    for _ in range(steps):
        if not env.agents:
            break
        actions = {
            a: rng.uniform(-1, 1, 1).astype(np.float32) * env.action_space(a).high
            for a in env.agents
        }
        trace.append(env.step(actions))
    return trace


def same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return type(a) is type(b) and a == b


def test_same_seed_same_everything_for_100_steps():
    kw = dict(scenario="demo", agents=3, max_cycles=100)
    t1 = rollout(par(**kw), seed=5)
    # a used env, reset with the same seed, replays a fresh env exactly
    env = par(**kw)
    rollout(env, seed=9, steps=3)
    t2 = rollout(env, seed=5)
    assert len(t1) == len(t2) > 50
    for k, (s1, s2) in enumerate(zip(t1, t2)):
        assert same(s1, s2), f"step {k} differs"
    # a different seed changes the observations (sensor noise, traffic): the check can fail
    t3 = rollout(par(**kw), seed=6, steps=10)
    assert not all(same(s1[0], s3[0]) for s1, s3 in zip(t1[1:], t3[1:]))


# ---------------------------------------------------------------------- spaces, obs


def test_spaces_built_once_and_layout():
    env = par(n_intruders=4)
    for a in env.possible_agents:
        assert env.observation_space(a) is env.observation_space(a)
        assert env.action_space(a) is env.action_space(a)
    lay = env.observation_layout
    assert lay.n_intruders == 4
    assert env.observation_space("west").shape == (lay.size,) == (len(lay.names()),)
    assert env.observation_space("west").dtype == np.float32
    assert np.all(np.isfinite(env.observation_space("west").low))
    assert np.all(np.isfinite(env.observation_space("west").high))
    box = env.action_space("west")
    # normalised: a fraction of the turn-rate limit
    assert box.shape == (1,) and box.low[0] == -1.0 and box.high[0] == 1.0


def test_observations_stay_in_space_every_step():
    env = par(scenario="demo", agents=3, max_cycles=80)
    obs, _ = env.reset(seed=2)
    lay = env.observation_layout
    seen_track = False
    while env.agents:
        for a, o in obs.items():
            assert env.observation_space(a).contains(o), (
                a,
                lay.names()[
                    np.argmax(
                        (o < env.observation_space(a).low) | (o > env.observation_space(a).high)
                    )
                ],
            )
            rows = lay.intruder_block(o)
            seen_track |= bool(rows[:, 0].sum() > 0)
            # padding rows are all zero, mask column is 0/1, tracks come first
            assert set(np.unique(rows[:, 0])) <= {0.0, 1.0}
            assert np.all(rows[rows[:, 0] == 0] == 0)
            assert np.all(np.diff(rows[:, 0]) <= 0)
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
    assert seen_track


# ------------------------------------------------------------------- actions, errors


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_action_is_a_user_error(bad):
    env = par()
    env.reset(seed=0)
    with pytest.raises(UserError) as exc:
        env.step({"west": np.array([bad], np.float32), "east": np.zeros(1, np.float32)})
    msg = str(exc.value)
    assert "west" in msg and str(float(bad)) in msg and "\n" not in msg


def test_other_bad_inputs_are_user_errors():
    env = par(discrete_actions=True)
    env.reset(seed=0)
    with pytest.raises(UserError, match="east"):
        env.step({"west": 2, "east": 7})
    env = par()
    env.reset(seed=0)
    with pytest.raises(UserError, match="unknown agent"):
        env.step({"nobody": np.zeros(1)})
    with pytest.raises(UserError, match="reward"):
        par(reward={"bogus": 1.0})
    with pytest.raises(UserError, match="render_mode"):
        par(render_mode="ansi")
    with pytest.raises(UserError, match="agents"):
        par(agents=["west", "nobody"])


def test_discrete_actions_turn_the_right_way():
    env = par(discrete_actions=True, overrides=["resolver.kind=none"])
    assert env.action_space("west").n == len(DISCRETE_LEVELS) + 1 == 6
    env.reset(seed=0)
    h0 = env.world.headings.copy()
    i_w, i_e = env.world.ids.index("west"), env.world.ids.index("east")
    for _ in range(5):
        env.step({"west": 0, "east": 4})  # hard left (CCW), hard right (CW)
    dh = (env.world.headings - h0 + np.pi) % (2 * np.pi) - np.pi
    limit = env.world.max_turn_rate
    assert np.isclose(dh[i_w], 5 * limit[i_w] * env.world.dt, rtol=0.05)
    assert np.isclose(dh[i_e], -5 * limit[i_e] * env.world.dt, rtol=0.05)


# ---------------------------------------------------------- rewards and termination


def test_nmac_terminates_and_is_penalised():
    # head-on, nobody avoids: the two agents collide and leave env.agents
    env = par(overrides=["resolver.kind=none"], max_cycles=200)
    env.reset(seed=0)
    ended = {}
    while env.agents:
        obs, rew, term, trunc, info = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        for a in term:
            total = sum(info[a]["reward_terms"].values())
            assert np.isclose(rew[a], total)
            if term[a]:
                ended[a] = (info[a], rew[a])
            assert (a in env.agents) == (not term[a] and not trunc[a])
    assert set(ended) == {"west", "east"}
    for info, r in ended.values():
        # the NMAC costs w_nmac plus the worst the rest of the episode could have cost
        steps_left = 200 - info["step"]
        assert steps_left > 50
        assert info["nmac"] and info["reward_terms"]["nmac"] < -aenv.DEFAULT_WEIGHTS["nmac"]
        assert info["reward_terms"]["nmac"] <= -(
            aenv.DEFAULT_WEIGHTS["nmac"] + steps_left * aenv.DEFAULT_WEIGHTS["los"]
        )
        # an NMAC is the worst intrusion: severity 1
        assert info["reward_terms"]["los"] == -aenv.DEFAULT_WEIGHTS["los"]
        assert r < -aenv.DEFAULT_WEIGHTS["nmac"]


def test_arrival_terminates_with_bonus_and_weights_apply():
    env = par(
        overrides=["aircraft[0].waypoints=[[-10000.0, 0.0]]"],
        reward={"arrival": 3.0, "progress": 0.0},
        max_cycles=100,
    )
    env.reset(seed=0)
    while "west" in env.agents:
        _, rew, term, trunc, info = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert term["west"] and not trunc["west"] and info["west"]["arrived"]
    assert info["west"]["reward_terms"]["arrival"] == 3.0
    assert info["west"]["reward_terms"]["progress"] == 0.0
    assert "east" in env.agents  # the other agent goes on


ROUTE = [
    "resolver.kind=none",
    "aircraft[0].waypoints=[[-10000.0, 2000.0], [-2000.0, -3000.0], [5000.0, 0.0]]",
]


def route_oracle(p, start, wps, k):
    """Cross-track (+ left), bearing and distance of position ``p`` on leg ``k`` of the route
    ``start -> wps[0] -> ...``, from the waypoints as written in the scenario."""
    a = np.asarray(start if k == 0 else wps[k - 1], float)
    b = np.asarray(wps[k], float)
    leg, rel, d = b - a, np.asarray(p) - a, b - np.asarray(p)
    cross = (leg[0] * rel[1] - leg[1] * rel[0]) / np.hypot(*leg)
    return cross, np.arctan2(d[1], d[0]), np.hypot(*d)


def test_route_progress_is_the_route_autopilots():
    # the agent sends no action: the world's route autopilot flies it through 3 waypoints;
    # the observation's route entries and the waypoint index follow that autopilot
    env = par(overrides=ROUTE, max_cycles=400)
    obs, infos = env.reset(seed=0)
    w = env.world
    i = w.index("west")
    wps = w.scenario.aircraft[0].waypoints
    start = w.positions[i].copy()
    lay = env.observation_layout
    names = lay.names()
    col = {n: names.index(f"own.{n}") for n in ("cross_track", "sin_bearing_to_waypoint",
                                                "cos_bearing_to_waypoint", "distance_to_waypoint",
                                                "has_waypoint")}  # fmt: skip
    seen, prev_k = set(), 0
    while "west" in env.agents:
        o, k = obs["west"], infos["west"]["waypoint_index"]
        assert k in (prev_k, prev_k + 1)
        if k == prev_k + 1:  # switched: the last step ended within one step's travel or abeam
            to_wp = np.asarray(wps[prev_k]) - w.positions[i]
            leg = np.asarray(wps[prev_k]) - np.asarray(start if prev_k == 0 else wps[prev_k - 1])
            assert np.hypot(*to_wp) <= w.speeds[i] * w.dt or to_wp @ leg < 0
        seen.add(k)
        cross, bearing, dist = route_oracle(w.positions[i], start, wps, k)
        rel = bearing - w.headings[i]
        np.testing.assert_allclose(o[col["cross_track"]], np.clip(cross / (10 * 3000.0), -1, 1),
                                   atol=1e-6)  # fmt: skip
        np.testing.assert_allclose(o[col["sin_bearing_to_waypoint"]], np.sin(rel), atol=1e-6)
        np.testing.assert_allclose(o[col["cos_bearing_to_waypoint"]], np.cos(rel), atol=1e-6)
        np.testing.assert_allclose(o[col["distance_to_waypoint"]], dist / 80000.0, atol=1e-6)
        assert o[col["has_waypoint"]] == 1.0
        prev_k = k
        obs, rew, term, trunc, infos = env.step({})
    # arrival is the step the world's autopilot finishes and the aircraft leaves the world
    assert term["west"] and infos["west"]["arrived"] and not w.active[i]
    assert infos["west"]["waypoint_index"] == 3 and seen == {0, 1, 2}
    assert obs["west"][col["has_waypoint"]] == 0.0
    to_wp, leg = np.asarray(wps[-1]) - w.positions[i], np.subtract(wps[-1], wps[-2])
    assert np.hypot(*to_wp) <= w.speeds[i] * w.dt or to_wp @ leg < 0


@pytest.mark.parametrize("autopilot", ["straight", "route"])  # route with no waypoints
def test_agent_without_a_route_has_no_waypoint_terms(autopilot):
    env = par(
        overrides=[f'aircraft[0].autopilot="{autopilot}"', "aircraft[0].waypoints=[]"],
        max_cycles=5,
    )
    obs, _ = env.reset(seed=0)
    names = env.observation_layout.names()
    for _ in range(3):
        obs, rew, term, trunc, infos = env.step(
            {a: np.full(1, 0.01, np.float32) for a in env.agents}
        )
        o = obs["west"]
        assert o[names.index("own.has_waypoint")] == 0.0
        assert o[names.index("own.cross_track")] == 0.0
        assert infos["west"]["reward_terms"]["path"] == 0.0
        assert infos["west"]["reward_terms"]["progress"] == 0.0
        assert infos["west"]["waypoint_index"] == 0


def test_truncation_at_max_cycles():
    env = par(max_cycles=7)
    env.reset(seed=0)
    for k in range(7):
        _, _, term, trunc, _ = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        assert all(trunc.values()) == (k == 6)
    assert env.agents == []


# -------------------------------------------------------------------------- frames


def test_rgb_array_frames_have_content():
    env = par(render_mode="rgb_array", render_size=(320, 256))
    env.reset(seed=0)
    frames = [env.render()]
    for _ in range(3):
        env.step({a: np.zeros(1, np.float32) for a in env.agents})
        frames.append(env.render())
    for f in frames:
        assert f.shape == (256, 320, 3) and f.dtype == np.uint8
        assert f.reshape(-1, 3).std(axis=0).max() > 5
        assert len(np.unique(f.reshape(-1, 3), axis=0)) > 10
    assert not np.array_equal(frames[0], frames[-1])  # time label and aircraft moved
    env.close()
    with pytest.warns(UserWarning, match="render_mode"):
        assert par().render() is None  # no render_mode: a warning, no frame


# ------------------------------------------------------------------ registry, imports


def test_registered_with_pettingzoo():
    assert "airspace_sim/head_on-v0" in aenv.REGISTERED_IDS
    assert "airspace_sim/head_on-v0" in pettingzoo.parallel_registry
    env = pettingzoo.make("parallel", "airspace_sim/crossing-v0", max_cycles=5, agents=2)
    assert isinstance(env, aenv.AirspaceParallelEnv)
    assert env.max_cycles == 5 and env.scenario.name == "crossing"
    assert sorted(env.possible_agents) == ["eastbound", "northbound"]
    a = pettingzoo.make("aec", "airspace_sim/head_on-v0")
    a.reset(seed=0)
    assert a.agent_selection == "west"
    assert aenv.make("head_on").scenario.name == "head_on"


def test_env_import_does_not_import_pygame():
    code = (
        "import sys, airspace_sim.env; e = airspace_sim.env.parallel_env(); e.reset(); "
        "print('pygame' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("eid", aenv.REGISTERED_IDS)
def test_every_registered_scenario_runs(eid):
    env = pettingzoo.make("parallel", eid, max_cycles=3)
    obs, infos = env.reset(seed=1)
    assert env.agents and set(obs) == set(env.agents) == set(infos)
    while env.agents:
        obs, rew, term, trunc, infos = env.step(
            {a: env.action_space(a).sample() for a in env.agents}
        )
        for a, o in obs.items():
            assert env.observation_space(a).contains(o)
            assert set(infos[a]["reward_terms"]) == set(aenv.DEFAULT_WEIGHTS)


def test_scenario_object_overrides_and_agent_choice():
    from airspace_sim.scenarios import load

    sc = load("demo")
    env = aenv.parallel_env(
        scenario=sc, overrides=["traffic.count=4"], agents=["markov2", "ring00"]
    )
    assert env.scenario.traffic.count == 4 and sc.traffic.count == 8  # the object is not changed
    assert env.possible_agents == ["markov2", "ring00"]
    _, infos = env.reset(seed=0)
    assert infos["ring00"]["reward_terms"]["los"] == 0.0
    # default: the scenario marks nobody, so the first aircraft is the agent
    assert aenv.parallel_env(scenario=sc).possible_agents == ["markov1"]
    # any generated aircraft can be an agent, not only the first of the traffic
    assert aenv.parallel_env(scenario=sc, agents=["ring02"]).possible_agents == ["ring02"]
    with pytest.raises(UserError, match="ring09"):
        aenv.parallel_env(scenario=sc, agents=["ring09"])
    with pytest.raises(UserError, match="unknown scenario"):
        aenv.parallel_env(scenario="no_such_scenario")
