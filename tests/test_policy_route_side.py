"""The CDA policy's route side (``resolver.route_side_off_course_deg``, world/policy.py): which
ownships get it, the loader's rule for the knob, and an ownship far off course that turns
across a conflict toward its route instead of away from it."""

import dataclasses

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.geometry import wrap_angle
from airspace_sim.scenarios import load
from airspace_sim.scenarios.schema import AircraftSpec, TrafficSpec
from airspace_sim.world import World
from airspace_sim.world.policy import AvoidancePolicy


def _ring(degrees):
    """scenarios/ring.toml with ``route_side_off_course_deg`` set to ``degrees`` (None: unset)."""
    sc = load("ring")
    return dataclasses.replace(
        sc, resolver=dataclasses.replace(sc.resolver, route_side_off_course_deg=degrees)
    )


def _policy(n, degrees):
    return AvoidancePolicy(_ring(degrees), 1.0, np.ones(n, bool), np.ones(n, bool))


def test_route_side_is_the_sign_of_the_heading_error_far_off_course():
    pol = _policy(6, 60.0)
    # autopilots east (0 rad); headings 90° right, 90° left, 59° right, 61° left, 179° left
    # (the route is 181° round on the left, 179° on the right), and one without an autopilot
    pol.desired_heading = np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.nan])
    heading = np.radians([-90.0, 90.0, -59.0, 61.0, 179.0, 120.0])
    got = pol._route_side(np.arange(6), heading)
    # the route lies left (+1) of a heading pointing right of it; no autopilot: none
    assert got.tolist() == [1.0, -1.0, 0.0, -1.0, -1.0, 0.0]
    assert _policy(6, 60.0)._route_side(np.arange(6), heading).tolist() == [0.0] * 6  # NaN
    plain = _policy(6, None)
    plain.desired_heading = pol.desired_heading
    assert plain.route_side_off_course is None
    assert plain._route_side(np.arange(6), heading).tolist() == [0.0] * 6


def test_route_side_validation():
    from airspace_sim.scenarios.schema import ResolverSpec

    assert ResolverSpec().route_side_off_course_deg is None
    with pytest.raises(UserError) as info:
        load("ring", ["resolver.route_side_off_course_deg=-5.0"])
    msg = str(info.value)
    assert "\n" not in msg and "resolver.route_side_off_course_deg" in msg and "-5" in msg


def _head_on(route_side):
    """The ring file's policy on two aircraft: an ownship flying south, 90° off its route (a
    waypoint 60 km east), and a non-avoiding intruder 20 km south flying north at it. The
    committed side turns it right (west, away from its route), the route side left."""
    sc = dataclasses.replace(_ring(route_side), duration=40.0)
    own = AircraftSpec(
        "own", (0.0, 0.0), -90.0, 200.0, autopilot="route", waypoints=[(60000.0, 0.0)]
    )
    intruder = AircraftSpec("intruder", (0.0, -20000.0), 90.0, 200.0, avoid=False)
    return dataclasses.replace(sc, aircraft=[own, intruder], traffic=TrafficSpec())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_far_off_course_the_ownship_turns_toward_its_route(seed):
    plain, route = World(_head_on(None), seed=seed), World(_head_on(60.0), seed=seed)
    for world in (plain, route):
        for _ in range(40):
            world.step()
            gap = np.hypot(*(world.positions[1] - world.positions[0]))
            assert gap > 3000.0
    # unconfirmed tracks for 5 s: both turn back toward the route (left) at 3°/s first
    off_plain, off_route = (
        wrap_angle(w.headings[0] - w.policy.desired_heading[0]) for w in (plain, route)
    )
    assert off_plain < np.radians(-90.0)  # turned right, further off course
    assert abs(off_route) < np.radians(60.0)  # turned left, back toward the route
    assert route.positions[0, 0] > 1000.0 > plain.positions[0, 0]


def test_override_keeps_the_autopilots_headings_and_old_checkpoints_load():
    world = World(load("ring"), seed=0)
    world.step()
    # every ring aircraft flies a route autopilot: a desired heading for each
    assert np.isfinite(world.policy.desired_heading).all()
    state = dict(world.policy.__dict__)
    del state["desired_heading"], state["route_side_off_course"]
    policy = AvoidancePolicy.__new__(AvoidancePolicy)
    policy.__setstate__(state)  # a checkpoint from before the route side
    assert policy.route_side_off_course is None
    assert policy.desired_heading.shape == (world.n,) and np.isnan(policy.desired_heading).all()
