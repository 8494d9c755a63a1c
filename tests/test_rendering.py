"""Renderer: frames from hand-made snapshots (no world needed)."""

import numpy as np
import pytest

from airspace_sim.rendering import COLORS, Renderer, save_frames, write_gif
from airspace_sim.rendering.geometry import (
    ViewTransform,
    covariance_ellipse,
    fit_view,
    format_distance,
    nice_scale_length,
)
from airspace_sim.rendering.snapshot import predict_positions


def one_aircraft(controlled=False, **extra):
    snap = dict(
        time=12.0,
        ids=["A"],
        positions=np.array([[0.0, 0.0]]),
        headings=np.array([0.0]),
        active=np.array([True]),
        controlled=np.array([controlled]),
        r_safe=3000.0,
    )
    snap.update(extra)
    return snap


def near(frame, color, cx, cy, half=12):
    patch = frame[cy - half : cy + half, cx - half : cx + half].reshape(-1, 3)
    return np.any(np.all(patch == np.array(color, dtype=np.uint8), axis=1))


def test_single_aircraft_drawn_at_centre():
    r = Renderer(400, 300, view=(-10000, 10000, -10000, 10000))
    frame = r.render(one_aircraft())
    assert frame.shape == (300, 400, 3) and frame.dtype == np.uint8
    assert near(frame, COLORS["traffic"], 200, 150)
    # far from the centre (and from the panels) there is no aircraft colour
    assert not near(frame, COLORS["traffic"], 120, 150, half=8)
    agent = Renderer(400, 300, view=(-10000, 10000, -10000, 10000)).render(
        one_aircraft(controlled=True)
    )
    assert near(agent, COLORS["agent"], 200, 150)
    assert not near(agent, COLORS["traffic"], 200, 150, half=6)


def test_aircraft_points_along_heading():
    view = (-10000, 10000, -10000, 10000)
    east = Renderer(200, 200, view=view).render(one_aircraft(headings=np.array([0.0])))
    west = Renderer(200, 200, view=view).render(one_aircraft(headings=np.array([np.pi])))
    col = np.array(COLORS["traffic"], dtype=np.uint8)

    def centroid_x(f):
        ys, xs = np.nonzero(np.all(f[90:110, 90:110] == col, axis=2))
        return xs.mean()

    # the triangle's mass lies behind the nose: an east-pointing one has its centroid
    # left of the one pointing west
    assert centroid_x(east) < centroid_x(west)


def test_state_colours_and_frames_have_content():
    snap = dict(
        time=5.0,
        ids=["a", "b", "c", "d"],
        positions=np.array([[0, 0], [2000, 0], [-15000, 8000], [15000, -9000.0]]),
        headings=np.array([0, np.pi, 1.0, 2.0]),
        controlled=np.array([True, False, False, False]),
        conflict=np.array([True, True, True, False]),
        in_los=np.array([True, True, False, False]),
        nmac=np.array([False, False, False, False]),
        r_safe=3000.0,
        tracks=dict(
            owner=np.array([0, 0, 0]),
            intruder=np.array([1, 2, 3]),
            x=np.array(
                [
                    [2000, -200, 50, 0, 0],
                    [-15000, 100, 8000, 50, 0.02],
                    [15000, 0, -9000, -200, -(0.05).__float__()],
                ],
                dtype=float,
            ),
            P=np.tile(np.diag([300.0**2, 25, 300.0**2, 25, 1e-4]), (3, 1, 1)),
            mu=np.array([[0.8, 0.1, 0.1], [0.2, 0.7, 0.1], [0.1, 0.1, 0.8]]),
        ),
    )
    r = Renderer()
    frame = r.render(snap)
    assert frame.shape == (800, 800, 3)
    assert frame.std() > 5
    colours = {tuple(c) for c in frame.reshape(-1, 3)[::7]}
    assert len(colours) > 20
    flat = frame.reshape(-1, 3)
    for key in ("los", "conflict", "clear", "agent", "track"):
        assert np.any(np.all(flat == np.array(COLORS[key], np.uint8), axis=1)), key
    # the view is kept from the first frame
    view = r.view
    snap2 = dict(snap, positions=snap["positions"] * 3)
    r.render(snap2)
    assert r.view == view
    r.reset()
    r.render(snap2)
    assert r.view != view


def test_renderer_tolerates_minimal_snapshot():
    frame = Renderer(128, 96).render({"positions": np.zeros((0, 2))})
    assert frame.shape == (96, 128, 3)
    with pytest.raises(KeyError):
        Renderer(128, 96).render({})


def test_geometry_helpers():
    v = fit_view([[0, 0], [10000, 20000]], margin=0.0, min_span=0)
    assert v == (-5000.0, 15000.0, 0.0, 20000.0)
    t = ViewTransform((0, 100, 0, 100), 200, 100)
    # equal scale: 1 px per metre, view centred horizontally; north up
    assert t.scale == 1.0
    assert np.allclose(t.to_pixels([50, 50]), [100, 50])
    assert np.allclose(t.to_pixels([50, 100]), [100, 0])
    assert nice_scale_length(7300) == 5000 and nice_scale_length(2500) == 2000
    assert format_distance(5000) == "5 km" and format_distance(500) == "500 m"
    ell = covariance_ellipse([0, 0], np.diag([4.0, 1.0]), n_sigma=2.0)
    assert np.isclose(np.abs(ell[:, 0]).max(), 4.0) and np.isclose(np.abs(ell[:, 1]).max(), 2.0)
    # coordinated-turn prediction: straight line, and a quarter turn
    p = predict_positions(np.array([[0, 100, 0, 0, 0.0]]), 10.0, 2)
    assert np.allclose(p, [[[500, 0], [1000, 0]]])
    w = np.pi / 20  # quarter turn in 10 s, radius 100/w
    q = predict_positions(np.array([[0, 100, 0, 0, w]]), 10.0, 1)
    assert np.allclose(q[0, -1], [100 / w, 100 / w])


def test_save_frames_and_gif(tmp_path):
    r = Renderer(160, 120)
    frames = [r.render(one_aircraft(time=float(k))) for k in range(3)]
    paths = save_frames(frames, tmp_path / "png")
    assert [p.name for p in paths] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    import imageio.v3 as iio

    assert np.array_equal(iio.imread(paths[1]), frames[1])
    gif = write_gif(frames, tmp_path / "a.gif", fps=5)
    assert iio.imread(gif).shape[0] == 3
    with pytest.raises(ValueError):
        write_gif([np.zeros((4, 4), np.uint8)], tmp_path / "b.gif")
