"""Draw :class:`~airspace_sim.world.snapshot.Snapshot` values into RGB frames with pygame,
offscreen (works with no display).

Frames are drawn on a plain :class:`pygame.Surface`; only :meth:`Renderer.show` opens a
window. The video driver is never forced to ``dummy`` (that can blank frames); fonts need
only :func:`pygame.font.init`.

What a frame shows (north up, equal scale on both axes):

- aircraft as triangles pointing along their heading; agent (controlled) aircraft blue,
  background traffic white; a grey trail of the positions drawn in the last
  ``trail_seconds`` of simulated time;
- around every aircraft a circle of radius **r_safe / 2**, so two circles touch exactly
  when the pair loses separation; coloured by the aircraft's state: green clear, amber
  conflict alert, red loss of separation, magenta NMAC;
- for the selected ownships (the agents by default, else the first aircraft; ringed in
  yellow): each intruder track's estimated position (yellow cross), its 2-σ position
  ellipse (true scale), the snapshot's predicted positions (dots over the look-ahead),
  and the track's mode probabilities as small bars (straight, left, right);
- a red line joining the two aircraft of each pair in loss of separation;
- a pink line for the resolver's advised heading on aircraft in conflict;
- a time label, a scale bar in m / km and a legend (:mod:`.hud`).
"""

from __future__ import annotations

import math
import os
import sys
import warnings

import numpy as np
import pygame
import pygame.gfxdraw

from airspace_sim.rendering.geometry import (
    ViewTransform,
    covariance_ellipse,
    fit_view,
    nice_scale_length,
    triangle,
)
from airspace_sim.rendering.hud import draw_hud, make_fonts
from airspace_sim.rendering.style import COLORS, MODE_COLORS
from airspace_sim.world.snapshot import Snapshot


class Renderer:
    """Turns :class:`Snapshot` values into ``(height, width, 3)`` uint8 frames.

    Parameters
    ----------
    width, height : frame size in pixels.
    view : ``(xmin, xmax, ymin, ymax)`` in metres, or None to fit the first snapshot's
        aircraft (plus a margin) and keep that view for later frames (call :meth:`reset`
        to refit).
    owners : whose tracks to draw: None (the controlled aircraft, else the first active
        aircraft), ``"all"``, or a list of aircraft ids or indices.
    trail_seconds : simulated seconds of past (rendered) positions drawn as a trail (0 = none).
    show_ids : draw aircraft names; None = only when there are at most 24 aircraft.
    legend : draw the legend; None = only when the frame is at least 560 x 480 pixels.
    """

    def __init__(
        self,
        width: int = 800,
        height: int = 800,
        view=None,
        owners=None,
        trail_seconds: float = 60.0,
        show_ids: bool | None = None,
        legend: bool | None = None,
    ):
        if width < 64 or height < 64:
            raise ValueError(f"frame must be at least 64x64 pixels, got {width}x{height}")
        self.width = int(width)
        self.height = int(height)
        self._given_view = None if view is None else tuple(float(v) for v in view)
        self.owners = owners
        self.trail_seconds = float(trail_seconds)
        self.show_ids = show_ids
        self.legend = legend if legend is not None else (width >= 560 and height >= 480)
        self._fonts = make_fonts()
        self._surface = pygame.Surface((self.width, self.height))
        self._window = None
        self._warned_no_display = False
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget trails and (unless a view was given) the fitted view."""
        self.transform = (
            None
            if self._given_view is None
            else ViewTransform(self._given_view, self.width, self.height)
        )
        self._trails: dict[str, list] = {}
        self._last_time = None

    @property
    def view(self):
        """The current view ``(xmin, xmax, ymin, ymax)`` in metres, or None before fitting."""
        return None if self.transform is None else self.transform.view

    # ---------------------------------------------------------------- drawing
    def render(self, snap: Snapshot) -> np.ndarray:
        """Draw one snapshot; returns a new ``(height, width, 3)`` uint8 array."""
        if not isinstance(snap, Snapshot):
            raise TypeError(f"Renderer.render: expected a Snapshot, got {type(snap).__name__}")
        if self.transform is None:
            pos = snap.positions[snap.active] if snap.active.any() else snap.positions
            view = fit_view(pos, pad=snap.r_safe / 2)
            self.transform = ViewTransform(view, self.width, self.height)
        self._update_trails(snap)
        s = self._surface
        s.fill(COLORS["background"])
        self._draw_grid(s)
        self._draw_trails(s, snap)
        self._draw_protected(s, snap)
        self._draw_pairs(s, snap)
        self._draw_tracks(s, snap)
        self._draw_aircraft(s, snap)
        draw_hud(s, snap, self._fonts, self.transform, self.legend)
        return np.ascontiguousarray(pygame.surfarray.array3d(s).transpose(1, 0, 2))

    def _px(self, xy) -> np.ndarray:
        return self.transform.to_pixels(xy)

    def _update_trails(self, f: Snapshot) -> None:
        if self.trail_seconds <= 0:
            return
        if self._last_time is not None and f.time < self._last_time:
            self._trails.clear()  # time went back: a new episode
        self._last_time = f.time
        horizon = f.time - self.trail_seconds
        for i in np.flatnonzero(f.active):
            trail = self._trails.setdefault(f.ids[i], [])
            p = (f.time, float(f.positions[i, 0]), float(f.positions[i, 1]))
            if not trail or trail[-1][1:] != p[1:]:
                trail.append(p)
            k = 0
            while k < len(trail) and trail[k][0] < horizon:
                k += 1
            del trail[:k]

    def _draw_grid(self, s) -> None:
        t = self.transform
        xmin, xmax, ymin, ymax = _visible_box(t)
        spacing = nice_scale_length((xmax - xmin) / 5)
        for gx in np.arange(math.ceil(xmin / spacing) * spacing, xmax, spacing):
            px = t.to_pixels([gx, 0.0])[0]
            pygame.draw.line(s, COLORS["grid"], (px, 0), (px, self.height))
        for gy in np.arange(math.ceil(ymin / spacing) * spacing, ymax, spacing):
            py = t.to_pixels([0.0, gy])[1]
            pygame.draw.line(s, COLORS["grid"], (0, py), (self.width, py))

    def _draw_trails(self, s, f: Snapshot) -> None:
        for i in np.flatnonzero(f.active):
            trail = self._trails.get(f.ids[i])
            if not trail or len(trail) < 2:
                continue
            pts = self._px(np.asarray(trail)[:, 1:])
            pygame.draw.lines(s, COLORS["trail"], False, [tuple(p) for p in pts], 1)

    @staticmethod
    def _state_color(f: Snapshot, i: int):
        if f.nmac[i]:
            return COLORS["nmac"]
        if f.in_los[i]:
            return COLORS["los"]
        if f.conflict[i]:
            return COLORS["conflict"]
        return COLORS["clear"]

    def _draw_protected(self, s, f: Snapshot) -> None:
        if not f.r_safe > 0:
            return
        r = max(2, int(round(self.transform.length(f.r_safe / 2))))
        pts = self._px(f.positions)
        overlay = pygame.Surface((self.width, self.height), pygame.SRCALPHA)
        for i in np.flatnonzero(f.active):
            x, y = int(round(pts[i, 0])), int(round(pts[i, 1]))
            if not _on_screen(x, y, r, self.width, self.height):
                continue
            col = self._state_color(f, i)
            pygame.gfxdraw.filled_circle(overlay, x, y, r, (*col, 40))
            pygame.gfxdraw.aacircle(overlay, x, y, r, (*col, 255))
            if col != COLORS["clear"] and r > 3:
                pygame.gfxdraw.aacircle(overlay, x, y, r - 1, (*col, 255))
        s.blit(overlay, (0, 0))

    def _draw_pairs(self, s, f: Snapshot) -> None:
        """A red line between the two aircraft of every pair in loss of separation."""
        pts = self._px(f.positions)
        for i, j in f.los_pairs:
            col = COLORS["nmac"] if (f.nmac[i] and f.nmac[j]) else COLORS["los"]
            pygame.draw.line(s, col, tuple(pts[i]), tuple(pts[j]), 2)

    def _selected_owners(self, f: Snapshot) -> np.ndarray:
        if self.owners is None:
            sel = np.flatnonzero(f.controlled & f.active)
            return sel if len(sel) else np.flatnonzero(f.active)[:1]
        if isinstance(self.owners, str) and self.owners == "all":
            return np.flatnonzero(f.active)
        idx = []
        for o in self.owners:
            if isinstance(o, (int, np.integer)):
                idx.append(int(o))
            elif str(o) in f.ids:
                idx.append(f.ids.index(str(o)))
        return np.asarray(idx, dtype=int)

    def _draw_tracks(self, s, f: Snapshot) -> None:
        tr = f.tracks
        owners = self._selected_owners(f)
        for i in owners:
            p = self._px(f.positions[i])
            pygame.gfxdraw.aacircle(s, int(p[0]), int(p[1]), 13, COLORS["track"])
        if len(tr) == 0 or len(owners) == 0:
            return
        rows = np.flatnonzero(np.isin(tr.owner, owners) & np.all(np.isfinite(tr.x[:, :4]), 1))
        overlay = pygame.Surface((self.width, self.height), pygame.SRCALPHA)
        for row in rows:
            mean = tr.x[row, [0, 2]]
            c = self._px(mean)
            if not _on_screen(c[0], c[1], 40, self.width, self.height):
                continue
            # predicted path: a faint line through the predicted points
            path = self._px(f.predicted[row])
            path = path[np.all(np.isfinite(path), axis=1)]
            if len(path):
                pts = [(int(c[0]), int(c[1]))] + [tuple(map(int, q)) for q in path]
                pygame.draw.lines(overlay, (*COLORS["prediction"], 70), False, pts, 1)
            for q in path:
                pygame.gfxdraw.filled_circle(
                    overlay, int(q[0]), int(q[1]), 2, (*COLORS["prediction"], 200)
                )
            # 2-sigma ellipse
            cov = tr.P[row][np.ix_([0, 2], [0, 2])]
            if np.all(np.isfinite(cov)):
                ell = self._px(covariance_ellipse(mean, cov, 2.0))
                radius = np.max(np.hypot(*(ell - c).T))
                if radius >= 2:
                    pygame.gfxdraw.aapolygon(
                        overlay, [tuple(map(int, p)) for p in ell], (*COLORS["track"], 230)
                    )
            # cross at the estimate
            x, y = int(round(c[0])), int(round(c[1]))
            pygame.draw.line(overlay, COLORS["track"], (x - 4, y - 4), (x + 4, y + 4), 2)
            pygame.draw.line(overlay, COLORS["track"], (x - 4, y + 4), (x + 4, y - 4), 2)
            # mode probability bars: straight, left, right
            mu = tr.mu[row]
            if mu.size and np.all(np.isfinite(mu)):
                _mode_bars(overlay, x + 7, y - 2, mu)
        s.blit(overlay, (0, 0))

    def _draw_aircraft(self, s, f: Snapshot) -> None:
        pts = self._px(f.positions)
        show_ids = self.show_ids if self.show_ids is not None else f.n <= 24
        small = self._fonts.small
        for i in np.flatnonzero(f.active):
            c = pts[i]
            if not _on_screen(c[0], c[1], 10, self.width, self.height):
                continue
            col = COLORS["agent"] if f.controlled[i] else COLORS["traffic"]
            tri = [tuple(p) for p in triangle(c, f.headings[i], 9.0)]
            pygame.gfxdraw.filled_polygon(s, tri, col)
            pygame.gfxdraw.aapolygon(s, tri, col)
            if f.conflict[i] and np.isfinite(f.advice[i]):
                h = f.headings[i] + f.advice[i]
                end = c + 26 * np.array([math.cos(h), -math.sin(h)])
                pygame.draw.line(s, COLORS["advice"], tuple(c), tuple(end), 2)
                pygame.draw.circle(s, COLORS["advice"], tuple(map(int, end)), 3)
            if show_ids:
                label = small.render(f.ids[i], True, COLORS["text"])
                s.blit(label, (c[0] + 10, c[1] + 6))

    # ------------------------------------------------------------------ human
    def show(self, frame: np.ndarray) -> None:
        """Display ``frame`` in a window (needs a display; used by render_mode="human")."""
        frame = np.asarray(frame)
        if self._window is None:
            if not has_display():
                if not self._warned_no_display:
                    warnings.warn(
                        "render_mode='human': no display found, frames are not shown", stacklevel=2
                    )
                    self._warned_no_display = True
                return
            pygame.display.init()
            pygame.display.set_caption("airspace_sim")
            self._window = pygame.display.set_mode((frame.shape[1], frame.shape[0]))
        pygame.event.pump()
        surf = pygame.surfarray.make_surface(frame.transpose(1, 0, 2))
        self._window.blit(surf, (0, 0))
        pygame.display.flip()

    def close(self) -> None:
        """Close the window, if one was opened."""
        if self._window is not None:
            pygame.display.quit()
            self._window = None


def has_display() -> bool:
    """Whether a window can be shown (on Linux: an X11 or Wayland display is set)."""
    if sys.platform.startswith("linux") or "bsd" in sys.platform:
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _visible_box(t: ViewTransform):
    x0, y0 = t.origin
    corners = np.array([[x0, y0 + t.height], [x0 + t.width, y0]], dtype=float)
    # invert the pixel mapping at two corners
    xs = (corners[:, 0] - x0 - t.width / 2) / t.scale + t._cx
    ys = -(corners[:, 1] - y0 - t.height / 2) / t.scale + t._cy
    return xs[0], xs[1], ys[0], ys[1]


def _on_screen(x, y, r, w, h) -> bool:
    return np.isfinite(x) and np.isfinite(y) and -r <= x <= w + r and -r <= y <= h + r


def _mode_bars(s, x: int, y_base: int, mu: np.ndarray, height: int = 16) -> None:
    """One bar per mode probability, ``height`` px for 1, left edge at x, base at y_base."""
    pygame.draw.rect(
        s, (*COLORS["panel"], 170), (x - 1, y_base - height - 1, 4 * len(mu) + 1, height + 2)
    )
    for m, p in enumerate(mu):
        h = int(round(float(np.clip(p, 0, 1)) * height))
        if h > 0:
            pygame.draw.rect(
                s, (*MODE_COLORS[m % len(MODE_COLORS)], 255), (x + 4 * m, y_base - h, 3, h)
            )
