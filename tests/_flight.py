"""Helpers shared by the band-resolver tests: the shipped band knobs and a closed-form path."""

import numpy as np

#: the boxed-fallback knobs (K1) that both shipped scenarios give bands-flown-intent
#: (scenarios/ring.toml, scenarios/dense_random.toml; they add priority_by_crossing)
K1 = dict(
    fresh_sides_only=True,
    switch_below=1.0,
    switch_blocked_at_once=True,
    boxed_best_both=True,
    boxed_margin=0.1,
    boxed_horizon_s=20.0,
    boxed_horizon_guard=0.7,
)


def arc_path(speed, heading, rate, turn_s, t):
    """(x, y) (T,) m of an arc at ``rate`` (signed, rad/s) for ``turn_s`` s, then straight,
    from the origin at ``heading`` rad and ``speed`` m/s, sampled at ``t`` (T,) s."""
    tt = np.minimum(t, turn_s)
    if rate != 0.0:
        h1 = heading + rate * tt
        x = speed / rate * (np.sin(h1) - np.sin(heading))
        y = speed / rate * (np.cos(heading) - np.cos(h1))
    else:
        h1 = np.full_like(t, heading)
        x, y = speed * tt * np.cos(heading), speed * tt * np.sin(heading)
    return x + (t - tt) * speed * np.cos(h1), y + (t - tt) * speed * np.sin(h1)
