"""Renderer and frame writer: frames from hand-made snapshots (no world needed)."""

import numpy as np
import pytest

from airspace_sim.rendering import COLORS, FrameWriter, Renderer
from airspace_sim.rendering.geometry import (
    ViewTransform,
    covariance_ellipse,
    fit_view,
    format_distance,
    nice_scale_length,
)
from airspace_sim.world.snapshot import Snapshot, Tracks


def make_tracks(owner=(), intruder=(), x=None, P=None, mu=None):
    p = len(owner)
    return Tracks(
        owner=np.asarray(owner, int),
        intruder=np.asarray(intruder, int),
        x=np.zeros((p, 5)) if x is None else x,
        P=np.zeros((p, 5, 5)) if P is None else P,
        mu=np.zeros((p, 3)) if mu is None else mu,
        misses=np.zeros(p, int),
        age=np.zeros(p, int),
    )


def make_snapshot(positions, predicted=None, **kw):
    """A Snapshot of ``positions`` (N, 2): everybody active, clear, heading east, no tracks,
    unless ``kw`` says otherwise."""
    pos = np.asarray(positions, float).reshape(-1, 2)
    n = len(pos)
    tracks = kw.pop("tracks", make_tracks())
    fields = dict(
        time=0.0,
        step=0,
        dt=1.0,
        ids=[str(i) for i in range(n)],
        positions=pos,
        velocities=np.zeros((n, 2)),
        headings=np.zeros(n),
        speeds=np.zeros(n),
        turn_rates=np.zeros(n),
        max_turn_rate=np.zeros(n),
        active=np.ones(n, bool),
        controlled=np.zeros(n, bool),
        avoid=np.zeros(n, bool),
        true_modes=np.full(n, -1),
        in_los=np.zeros(n, bool),
        nmac=np.zeros(n, bool),
        conflict=np.zeros(n, bool),
        advice=np.zeros(n),
        r_safe=3000.0,
        nmac_distance=150.0,
        sensor_range=50000.0,
        lookahead=120.0,
        mode_names=("straight", "left", "right"),
        tracks=tracks,
        predicted=np.zeros((len(tracks), 6, 2)) if predicted is None else predicted,
        los_pairs=np.zeros((0, 2), int),
        nmac_pairs=np.zeros((0, 2), int),
    )
    fields.update(kw)
    return Snapshot(**fields)


def one_aircraft(controlled=False, **extra):
    return make_snapshot(
        [[0.0, 0.0]], **{"time": 12.0, "ids": ["A"], "controlled": [controlled], **extra}
    )


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


def four_aircraft(**kw):
    x = np.array(
        [[2000, -200, 50, 0, 0], [-15000, 100, 8000, 50, 0.02], [15000, 0, -9000, -200, -0.05]],
        dtype=float,
    )
    t = 120.0 * np.arange(1, 7) / 6
    straight = x[:, None, (0, 2)] + t[None, :, None] * x[:, None, (1, 3)]  # (3, 6, 2)
    fields = dict(
        time=5.0,
        ids=["a", "b", "c", "d"],
        headings=[0, np.pi, 1.0, 2.0],
        controlled=[True, False, False, False],
        conflict=[True, True, True, False],
        in_los=[True, True, False, False],
        los_pairs=[[0, 1]],
        tracks=make_tracks(
            owner=[0, 0, 0],
            intruder=[1, 2, 3],
            x=x,
            P=np.tile(np.diag([300.0**2, 25, 300.0**2, 25, 1e-4]), (3, 1, 1)),
            mu=[[0.8, 0.1, 0.1], [0.2, 0.7, 0.1], [0.1, 0.1, 0.8]],
        ),
        predicted=straight,
    )
    fields.update(kw)
    pos = fields.pop("positions", [[0, 0], [2000, 0], [-15000, 8000], [15000, -9000.0]])
    return make_snapshot(pos, **fields)


def test_state_colours_and_frames_have_content():
    snap = four_aircraft()
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
    snap2 = four_aircraft(positions=snap.positions * 3)
    r.render(snap2)
    assert r.view == view
    r.reset()
    r.render(snap2)
    assert r.view != view


def test_predicted_points_are_drawn_where_the_snapshot_puts_them():
    view = (-20000, 20000, -20000, 20000)
    snap = four_aircraft()
    # only the first track, its predicted points moved far from everything else
    tracks = make_tracks([0], [1], x=snap.tracks.x[:1], P=snap.tracks.P[:1], mu=snap.tracks.mu[:1])
    pred = np.zeros((1, 6, 2))
    pred[0, :, 0] = np.linspace(-4000, -14000, 6)
    pred[0, :, 1] = -15000.0
    snap = four_aircraft(tracks=tracks, predicted=pred)
    frame = Renderer(400, 400, view=view, legend=False).render(snap)
    t = ViewTransform(view, 400, 400)
    blend = frame.astype(int)
    background = np.array(COLORS["background"])
    for q in pred[0]:
        cx, cy = np.round(t.to_pixels(q)).astype(int)
        patch = blend[cy - 2 : cy + 3, cx - 2 : cx + 3].reshape(-1, 3)
        # a dot of the prediction colour blended over the background: bluer than the grid
        assert np.any(np.abs(patch - background).sum(axis=1) > 100), q
    empty = Renderer(400, 400, view=view, legend=False).render(
        four_aircraft(tracks=make_tracks(), predicted=np.zeros((0, 6, 2)))
    )
    cx, cy = np.round(t.to_pixels(pred[0, -1])).astype(int)
    assert np.all(np.abs(empty[cy - 2 : cy + 3, cx - 2 : cx + 3] - background).sum(axis=-1) < 60)


def test_renderer_takes_snapshots_only():
    frame = Renderer(128, 96).render(make_snapshot(np.zeros((0, 2))))
    assert frame.shape == (96, 128, 3)
    with pytest.raises(TypeError, match="Snapshot"):
        Renderer(128, 96).render({"positions": np.zeros((1, 2))})


def test_snapshot_checks_shapes_and_is_read_only():
    with pytest.raises(ValueError, match="headings"):
        make_snapshot([[0, 0], [1, 1]], headings=[0.0])
    with pytest.raises(ValueError, match="predicted"):
        make_snapshot([[0, 0]], predicted=np.zeros((2, 6, 2)))
    s = make_snapshot([[0, 0]])
    with pytest.raises(ValueError):
        s.positions[0, 0] = 1.0
    with pytest.raises(AttributeError):
        s.time = 3.0


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


def test_frame_writer_pngs_and_gif(tmp_path):
    import imageio.v3 as iio

    r = Renderer(160, 120)
    frames = [r.render(one_aircraft(time=float(k))) for k in range(3)]
    (tmp_path / "png").mkdir()
    (tmp_path / "png" / "frame_00007.png").write_bytes(b"stale")
    with FrameWriter(tmp_path / "png", video="gif", fps=5) as w:
        for f in frames:
            w.add(f)
    assert [p.name for p in w.paths] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    assert sorted(p.name for p in (tmp_path / "png").glob("frame_*.png")) == [
        p.name for p in w.paths
    ]  # the stale frame is gone
    assert np.array_equal(iio.imread(w.paths[1]), frames[1])
    assert w.video == tmp_path / "png" / "run.gif"
    gif = iio.imread(w.video, index=None)
    assert gif.shape == (3, 120, 160, 3)
    # 256-colour palette of a ~350-colour frame: every pixel within a few levels
    assert np.abs(gif[2].astype(int) - frames[2]).max() <= 16
    with pytest.raises(ValueError, match="uint8"):
        FrameWriter(tmp_path / "bad").add(np.zeros((4, 4), np.uint8))
    plain = FrameWriter(tmp_path / "plain")
    plain.add(frames[0])
    assert plain.close() is None and not (tmp_path / "plain" / "run.gif").exists()
    with pytest.raises(ValueError, match="shape"):
        w2 = FrameWriter(tmp_path / "two")
        w2.add(frames[0])
        w2.add(np.zeros((10, 10, 3), np.uint8))
