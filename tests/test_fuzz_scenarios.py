"""Property-based fuzzing of every shipped scenario (issue 11): mutate it (drop keys, change
types, extreme and signed-zero numbers, huge counts), then load it and step the world a few
times. Either it loads and steps with finite state and metrics, or it raises the project's
:class:`UserError` on one line. Anything else (a traceback, NaN positions) is a bug.

Profiles: ``ci`` (default) is derandomised, the same examples every run, a few seconds;
``AIRSPACE_SIM_FUZZ=long`` runs many more random examples on demand::

    AIRSPACE_SIM_FUZZ=long python -m pytest -q tests/test_fuzz_scenarios.py
"""

from __future__ import annotations

import copy
import math
import os
import tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from airspace_sim.errors import UserError
from airspace_sim.scenarios import loader

settings.register_profile(
    "ci",
    derandomize=True,
    max_examples=25,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "long",
    max_examples=1000,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
PROFILE = settings.get_profile(os.environ.get("AIRSPACE_SIM_FUZZ", "ci"))

SCENARIOS = loader.available()
STEPS = 3
#: Worlds bigger than this are loaded but not stepped (a few steps of 10 000 aircraft take
#: minutes; that they load, or are refused, is what is checked).
MAX_STEPPED_AIRCRAFT = 120
#: Metrics that are NaN when there is nothing to measure (no tracks, no Markov truth).
#: metrics that world/metrics.py defines as NaN when undefined (no Markov intruder, no track,
#: nothing planned covered, nothing flown, no alert, nothing arrived)
MAY_BE_NAN = {
    "mode_accuracy",
    "track_rmse_m",
    "extra_path_pct",
    "alerts_per_flight_hour",
    "first_alert_s",
    "arrival_delay_mean_s",
    "arrival_delay_max_s",
}

EXTREME_NUMBERS = [
    0, -0.0, 0.0, 1, -1, 2, 0.5, -0.5, 1e-3, 5e-324, -5e-324, 1e-300, 1e300, 1e308, -1e308,
    math.inf, -math.inf, math.nan, 2**31, 2**63 - 1, 2**63, 2**70, -(2**63), 10**9, 10000, 3,
]  # fmt: skip
OTHER_VALUES = [
    "", " ", "x", "radar", "imm", "bands", "ring", "random", "\n", "\x1b[31m", True, False,
    [], [0.0], [0.0, 0.0], [1e308, 0.0], [[0.0, 0.0]], {}, {"bogus": 1}, [[[[]]]],
]  # fmt: skip
# a fresh copy each draw: a shared {} or [] put in two places could grow into a cycle
VALUES = st.sampled_from(EXTREME_NUMBERS + OTHER_VALUES).map(copy.deepcopy)


def _paths(node, prefix=()):
    """Every (path, value) below ``node``: dict keys and list indices."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for k, v in items:
        yield prefix + (k,), v
        if isinstance(v, (dict, list)):
            yield from _paths(v, prefix + (k,))


def _parent(data, path):
    node = data
    for k in path[:-1]:
        node = node[k]
    return node


@st.composite
def mutated(draw, data: dict):
    """``data`` with 1 to 4 mutations: a key dropped, a value replaced, a new key added."""
    data = copy.deepcopy(data)
    for _ in range(draw(st.integers(1, 4))):
        paths = [p for p, _ in _paths(data)]
        op = draw(st.sampled_from(["drop", "replace", "replace", "replace", "add"]))
        if not paths:
            op = "add"
        if op == "add":
            tables = [()] + [p for p, v in _paths(data) if isinstance(v, dict)]
            where = draw(st.sampled_from(tables))
            node = _parent(data, where + ("",)) if where else data
            key = draw(st.sampled_from(["count", "seed", "bogus", "params", "a\nb", "x"]))
            node[key] = draw(VALUES)
            continue
        path = draw(st.sampled_from(paths))
        parent = _parent(data, path)
        if op == "drop":
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(VALUES)
    return data


def _check_user_error(exc: UserError):
    msg = str(exc)
    assert "\n" not in msg and "\x1b" not in msg, repr(msg)
    assert msg.strip(), "empty error message"


def _run(data: dict, name: str):
    """Load ``data`` and step it; returns None, or raises (a UserError is fine)."""
    from airspace_sim.world import World

    sc = loader.from_dict(data, source=f"{name}.toml", name=name, runnable=True)  # as load()
    if len(sc.aircraft) + sc.traffic.count > MAX_STEPPED_AIRCRAFT:
        return
    world = World(sc)
    for _ in range(STEPS):
        world.step()
    active = world.active
    for arr in (world.positions, world.headings, world.speeds):
        assert np.all(np.isfinite(np.asarray(arr)[active])), arr
    for key, value in world.metrics().items():
        if isinstance(value, float) and key not in MAY_BE_NAN:
            assert not math.isnan(value), (key, value)


@pytest.mark.parametrize("name", SCENARIOS)
def test_mutated_scenarios_load_and_step_or_fail_in_one_line(name):
    path = loader.resolve(name)
    base = tomllib.loads(path.read_text())

    @PROFILE
    @given(mutated(base))
    def check(data):
        try:
            _run(data, name)
        except UserError as exc:
            _check_user_error(exc)

    check()


def test_fuzz_profiles_are_registered():
    assert settings.get_profile("ci").derandomize
    assert settings.get_profile("long").max_examples > settings.get_profile("ci").max_examples
