"""Every bad input to the env is a one-line error of the kind Gymnasium raises (issue 11).

Table-driven: each row is (what is called, the exception class, a fragment of the message).
Seeds follow ``gymnasium.utils.seeding.np_random`` (``gymnasium.error.Error``, its
wording), actions raise ``gymnasium.error.InvalidAction``, a step before reset
``gymnasium.error.ResetNeeded``; all of them are also the project's ``UserError``, so the
CLI prints them as one line.
"""

import datetime

import gymnasium
import numpy as np
import pytest

import airspace_sim.env as aenv
from airspace_sim.errors import UserError

SMALL = dict(scenario="head_on", agents=2, max_cycles=20)


def fresh(**kw):
    env = aenv.parallel_env(**{**SMALL, **kw})
    env.reset(seed=0)
    return env


def step_west(action, **kw):
    env = fresh(**kw)
    env.step({"west": action, "east": None})


CONSTRUCTOR = [
    # (kwargs, exception, message fragment)
    (dict(seed=-1), gymnasium.error.Error, "greater or equal to zero"),
    (dict(seed="x"), gymnasium.error.Error, "must be a python integer"),
    (dict(seed=1.5), gymnasium.error.Error, "must be a python integer"),
    (dict(seed=True), gymnasium.error.Error, "must be a python integer"),
    (dict(seed=2**70), gymnasium.error.Error, "2**63 - 1"),
    (dict(max_cycles=1.5), UserError, "max_cycles: expected an integer"),
    (dict(max_cycles=0), UserError, "max_cycles: expected an integer"),
    (dict(max_cycles=float("nan")), UserError, "max_cycles"),
    (dict(max_cycles=True), UserError, "max_cycles"),
    (dict(n_intruders=-1), UserError, "n_intruders"),
    (dict(n_intruders=2.5), UserError, "n_intruders"),
    (dict(discrete_actions="yes"), UserError, "discrete_actions"),
    (dict(ended="stay"), UserError, "ended"),
    (dict(render_mode="ansi"), UserError, "render_mode"),
    (dict(render_size=(0, 100)), UserError, "render_size"),
    (dict(render_size="big"), UserError, "render_size"),
    (dict(agents="some"), UserError, "agents"),
    (dict(agents=0), UserError, "agents"),
    (dict(agents=["west", "west"]), UserError, "twice"),
    (dict(agents=["nobody"]), UserError, "unknown aircraft 'nobody'"),
    (dict(reward={"nmac": -1.0}), UserError, "reward.nmac"),
    (dict(reward={"nmac": 0.0}), UserError, "reward.nmac"),
    (dict(reward={"los": float("nan")}), UserError, "reward.los"),
    (dict(reward={"los": "x"}), UserError, "reward.los"),
    (dict(reward={"bogus": 1.0}), UserError, "unknown term"),
    (dict(max_aircraft=1), UserError, "max_aircraft"),
    (dict(state_scale_m=float("nan")), UserError, "state_scale_m"),
    (dict(overrides=["traffic.count=abc"]), UserError, "traffic.count"),
    # a keyword the env does not take (the old capture_radius) is Python's TypeError, as
    # gymnasium.make leaves it
    (dict(capture_radius=float("nan")), TypeError, "capture_radius"),
]


@pytest.mark.parametrize("kwargs,exc,fragment", CONSTRUCTOR, ids=lambda v: repr(v)[:40])
def test_bad_constructor_arguments(kwargs, exc, fragment):
    with pytest.raises(exc) as info:
        aenv.parallel_env(**{**SMALL, **kwargs})
    assert fragment in str(info.value) and "\n" not in str(info.value)
    if exc is not TypeError:
        assert isinstance(info.value, UserError)


RESET = [
    (dict(seed=-1), gymnasium.error.Error, "greater or equal to zero"),
    (dict(seed="x"), gymnasium.error.Error, "must be a python integer"),
    (dict(seed=1.5), gymnasium.error.Error, "must be a python integer"),
    (dict(seed=np.float64(2.0)), gymnasium.error.Error, "must be a python integer"),
    (dict(options="x"), UserError, "options"),
    (dict(options={"traffic_count": 0}), UserError, "traffic_count"),
    (dict(options={"traffic_count": 1.5}), UserError, "traffic_count"),
    (dict(options={"sensor_sigma": "x"}), UserError, "sensor_sigma"),
    (dict(options={"sensor_sigma": float("nan")}), UserError, "sensor.sigma"),
    (dict(options={"density": 1.0}), UserError, "density"),
    (dict(options={"overrides": [3]}), UserError, "overrides"),
]


@pytest.mark.parametrize("kwargs,exc,fragment", RESET, ids=lambda v: repr(v)[:40])
def test_bad_reset_arguments(kwargs, exc, fragment):
    env = aenv.parallel_env(**SMALL)
    with pytest.raises(exc) as info:
        env.reset(**kwargs)
    assert fragment in str(info.value) and "\n" not in str(info.value)
    assert isinstance(info.value, UserError)


def test_numpy_integer_seeds_are_accepted():
    env = aenv.parallel_env(**SMALL, seed=np.int64(3))
    a, _ = env.reset(seed=np.uint32(7))
    b, _ = aenv.parallel_env(**SMALL).reset(seed=7)
    assert all(np.array_equal(a[k], b[k]) for k in a)


CONTINUOUS = [
    "0.1",
    b"0.1",
    0.1 + 0.2j,
    np.array([0.1 + 0j]),
    True,
    np.bool_(False),
    np.array([True]),
    datetime.datetime(2026, 1, 1),
    np.datetime64("2026-01-01"),
    datetime.timedelta(seconds=1),
    object(),
    [...],
    {"rate": 0.1},
    [0.1, 0.2],
    np.zeros((2, 1)),
    np.array([np.nan]),
    float("inf"),
    -np.inf,
]


def _action_id(v) -> str:
    """A test id that is the same in every process (an object's repr holds its address)."""
    return type(v).__name__ if type(v) is object else repr(v)[:30]


@pytest.mark.parametrize("action", CONTINUOUS, ids=_action_id)
def test_bad_continuous_actions(action):
    with pytest.raises(gymnasium.error.InvalidAction) as info:
        step_west(action)
    assert "west" in str(info.value) and "\n" not in str(info.value)
    assert isinstance(info.value, UserError)


DISCRETE = [float("inf"), -1, 6, 2.0, 1.5, "1", True, np.array([1.0]), np.array([1, 2]), [1]]


@pytest.mark.parametrize("action", DISCRETE, ids=lambda v: repr(v)[:30])
def test_bad_discrete_actions(action):
    with pytest.raises(gymnasium.error.InvalidAction) as info:
        step_west(action, discrete_actions=True)
    assert "west" in str(info.value) and "0..5" in str(info.value)


@pytest.mark.parametrize("actions", [None, [0.1, 0.1], (0.1,), np.zeros(2), "west"])
def test_step_needs_a_dict(actions):
    env = fresh()
    with pytest.raises(gymnasium.error.InvalidAction, match="expected a dict"):
        env.step(actions)


def test_unknown_agent_and_step_before_reset():
    env = fresh()
    with pytest.raises(gymnasium.error.InvalidAction, match="unknown agent 'nobody'"):
        env.step({"nobody": np.zeros(1)})
    env = aenv.parallel_env(**SMALL)
    with pytest.raises(gymnasium.error.ResetNeeded, match="reset"):
        env.step({})
    with pytest.raises(gymnasium.error.ResetNeeded, match="reset"):
        env.state()


def test_good_actions_of_every_accepted_kind():
    env = fresh()
    for action in (0.5, 1, np.float32(0.5), np.array([0.5]), [0.5], (0.5,), np.array(0.5)):
        env.step({"west": action, "east": None})
    env = fresh(discrete_actions=True)
    for action in (0, np.int64(4), np.array(2), np.array([1]), aenv.BUILTIN_ACTION, None):
        env.step({"west": action, "east": 2})
