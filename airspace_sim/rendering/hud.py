"""The frame's overlays in screen space: time panel, scale bar and legend (pygame)."""

from __future__ import annotations

import math
from typing import NamedTuple

import pygame
import pygame.gfxdraw

from airspace_sim.rendering.geometry import (
    ViewTransform,
    format_distance,
    nice_scale_length,
    triangle,
)
from airspace_sim.rendering.style import COLORS, MODE_COLORS, STATE_LABELS
from airspace_sim.world.snapshot import Snapshot


class Fonts(NamedTuple):
    big: pygame.font.Font
    normal: pygame.font.Font
    small: pygame.font.Font


def make_fonts() -> Fonts:
    """pygame's default font at three sizes (needs only :func:`pygame.font.init`)."""
    pygame.font.init()
    return Fonts(pygame.font.Font(None, 22), pygame.font.Font(None, 18), pygame.font.Font(None, 15))


def draw_hud(s, snap: Snapshot, fonts: Fonts, transform: ViewTransform, legend: bool) -> None:
    """Time and counts (top left), scale bar (bottom left), legend (top right)."""
    minutes, seconds = divmod(snap.time, 60.0)
    text = f"t = {snap.time:7.1f} s  ({int(minutes):d}:{seconds:04.1f})   step {snap.step}"
    on = snap.active
    sub = (
        f"{int(on.sum())} aircraft   conflict {int((snap.conflict & on).sum())}   "
        f"LoS {int((snap.in_los & on).sum())}   NMAC {int((snap.nmac & on).sum())}"
    )
    panel(s, 8, 8, [(text, fonts.big), (sub, fonts.normal)])
    draw_scale_bar(s, transform, fonts)
    if legend:
        draw_legend(s, snap, fonts)


def panel(s, x: int, y: int, lines) -> None:
    """Lines of ``(text, font)`` on a translucent panel with its top left at (x, y) px."""
    rendered = [font.render(t, True, COLORS["text"]) for t, font in lines]
    w = max(r.get_width() for r in rendered) + 12
    h = sum(r.get_height() + 3 for r in rendered) + 8
    bg = pygame.Surface((w, h), pygame.SRCALPHA)
    bg.fill((*COLORS["panel"], 200))
    s.blit(bg, (x, y))
    yy = y + 5
    for r in rendered:
        s.blit(r, (x + 6, yy))
        yy += r.get_height() + 3


def draw_scale_bar(s, t: ViewTransform, fonts: Fonts) -> None:
    """A bar of a round length (1, 2 or 5 × 10^k m) at most a quarter of the frame wide."""
    length = nice_scale_length(0.25 * t.width / t.scale)
    px = t.length(length)
    x0, y0 = 18, s.get_height() - 22
    bg = pygame.Surface((int(px) + 24, 40), pygame.SRCALPHA)
    bg.fill((*COLORS["panel"], 200))
    s.blit(bg, (x0 - 10, y0 - 28))
    pygame.draw.line(s, COLORS["text"], (x0, y0), (x0 + px, y0), 3)
    for xx in (x0, x0 + px / 2, x0 + px):
        pygame.draw.line(s, COLORS["text"], (xx, y0 - 6), (xx, y0 + 3), 2)
    label = fonts.normal.render(format_distance(length), True, COLORS["text"])
    s.blit(label, (x0 + px / 2 - label.get_width() / 2, y0 - 24))


def draw_legend(s, snap: Snapshot, fonts: Fonts) -> None:
    rows = [
        ("tri", COLORS["agent"], "agent aircraft"),
        ("tri", COLORS["traffic"], "traffic"),
        ("text", None, f"r_safe/2 = {format_distance(snap.r_safe / 2)} circle (touch = LoS)"),
    ]
    for key, label in STATE_LABELS:
        rows.append(("circle", COLORS[key], label))
    rows += [
        ("cross", COLORS["track"], "track estimate + 2-sigma ellipse"),
        ("dot", COLORS["prediction"], "predicted positions"),
        ("bars", None, "modes: " + (" / ".join(snap.mode_names[:3]) or "none")),
        ("ring", COLORS["track"], "ownship whose tracks are shown"),
        ("line", COLORS["advice"], "resolver advice (in conflict)"),
    ]
    line_h = 17
    w = 262
    h = line_h * len(rows) + 10
    x0 = s.get_width() - w - 8
    y0 = 8
    bg = pygame.Surface((w, h), pygame.SRCALPHA)
    bg.fill((*COLORS["panel"], 200))
    s.blit(bg, (x0, y0))
    for k, (kind, col, label) in enumerate(rows):
        cy = y0 + 5 + k * line_h + line_h // 2
        cx = x0 + 14
        if kind == "tri":
            tri = [tuple(p) for p in triangle((cx, cy), math.pi / 2, 7.0)]
            pygame.gfxdraw.filled_polygon(s, tri, col)
        elif kind == "circle":
            pygame.gfxdraw.filled_circle(s, cx, cy, 6, tuple(c // 3 for c in col))
            pygame.gfxdraw.aacircle(s, cx, cy, 6, col)
        elif kind == "cross":
            pygame.draw.line(s, col, (cx - 4, cy - 4), (cx + 4, cy + 4), 2)
            pygame.draw.line(s, col, (cx - 4, cy + 4), (cx + 4, cy - 4), 2)
        elif kind == "dot":
            pygame.gfxdraw.filled_circle(s, cx, cy, 2, col)
            pygame.gfxdraw.filled_circle(s, cx + 6, cy - 2, 2, col)
        elif kind == "line":
            pygame.draw.line(s, col, (cx - 7, cy + 3), (cx + 5, cy - 3), 2)
            pygame.draw.circle(s, col, (cx + 5, cy - 3), 3)
        elif kind == "ring":
            pygame.gfxdraw.aacircle(s, cx, cy, 7, col)
        elif kind == "bars":
            for m, hh in enumerate((10, 5, 3)):
                pygame.draw.rect(s, MODE_COLORS[m], (cx - 6 + 4 * m, cy + 5 - hh, 3, hh))
        text = fonts.small.render(label, True, COLORS["text"])
        s.blit(text, (x0 + 28, cy - text.get_height() // 2))
