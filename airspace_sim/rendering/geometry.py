"""Pure-numpy geometry for the renderer: view fitting, world-to-pixel mapping, ellipses.

No pygame here, so these can be tested and reused without a drawing backend. Units: metres
in the world (x east, y north), pixels on screen (x right, y down).
"""

from __future__ import annotations

import math

import numpy as np


def fit_view(positions, margin: float = 0.15, min_span: float = 10000.0, pad: float = 0.0):
    """A view ``(xmin, xmax, ymin, ymax)`` in metres enclosing ``positions`` (N, 2).

    The box is grown by ``margin`` times its largest side plus ``pad`` metres on every side,
    and is at least ``min_span`` metres wide and tall. NaN rows are ignored; with no finite
    position the view is ``min_span`` wide around the origin.
    """
    pos = np.asarray(positions, dtype=float).reshape(-1, 2)
    pos = pos[np.all(np.isfinite(pos), axis=1)]
    if len(pos) == 0:
        half = min_span / 2
        return (-half, half, -half, half)
    lo = pos.min(axis=0)
    hi = pos.max(axis=0)
    centre = (lo + hi) / 2
    span = max(float(np.max(hi - lo)), min_span)
    half = span / 2 * (1 + 2 * margin) + pad
    return (centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half)


class ViewTransform:
    """Maps world metres to pixels of a ``width`` x ``height`` map area at ``origin``.

    The scale is equal on both axes (metres per pixel); the view box is centred in the map
    area and extended along the shorter direction so that nothing is distorted. North is up.
    """

    def __init__(self, view, width: int, height: int, origin=(0, 0)):
        xmin, xmax, ymin, ymax = (float(v) for v in view)
        if not (xmax > xmin and ymax > ymin) or not all(
            math.isfinite(v) for v in (xmin, xmax, ymin, ymax)
        ):
            raise ValueError(f"view must be finite with xmin < xmax, ymin < ymax, got {view}")
        self.view = (xmin, xmax, ymin, ymax)
        self.width = int(width)
        self.height = int(height)
        self.origin = (int(origin[0]), int(origin[1]))
        #: pixels per metre
        self.scale = min(self.width / (xmax - xmin), self.height / (ymax - ymin))
        self._cx = (xmin + xmax) / 2
        self._cy = (ymin + ymax) / 2

    def to_pixels(self, xy) -> np.ndarray:
        """(..., 2) metres -> (..., 2) float pixels."""
        xy = np.asarray(xy, dtype=float)
        px = self.origin[0] + self.width / 2 + (xy[..., 0] - self._cx) * self.scale
        py = self.origin[1] + self.height / 2 - (xy[..., 1] - self._cy) * self.scale
        return np.stack([px, py], axis=-1)

    def length(self, metres: float) -> float:
        """Metres -> pixels."""
        return metres * self.scale


def nice_scale_length(max_metres: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``max_metres`` (for a scale bar)."""
    if not max_metres > 0:
        return 1.0
    exp = math.floor(math.log10(max_metres))
    for mant in (5, 2, 1):
        v = mant * 10.0**exp
        if v <= max_metres:
            return v
    return 10.0**exp


def format_distance(metres: float) -> str:
    """``'500 m'``, ``'2 km'``, ``'2.5 km'``."""
    if metres >= 1000:
        km = metres / 1000
        return f"{km:g} km"
    return f"{metres:g} m"


def covariance_ellipse(mean, cov, n_sigma: float = 2.0, n_points: int = 36) -> np.ndarray:
    """Points (n_points, 2) of the ``n_sigma`` contour of a 2D Gaussian ``(mean, cov)``.

    ``cov`` is the (2, 2) position covariance in m²; it is symmetrised and negative
    eigenvalues (round-off) are clipped to zero.
    """
    cov = np.asarray(cov, dtype=float)
    cov = (cov + cov.T) / 2
    w, v = np.linalg.eigh(cov)
    w = np.clip(w, 0.0, None)
    t = np.linspace(0, 2 * np.pi, n_points, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.asarray(mean, dtype=float) + n_sigma * (circle * np.sqrt(w)) @ v.T


def triangle(centre_px, heading: float, size: float) -> np.ndarray:
    """Pixel vertices (3, 2) of an aircraft triangle pointing along ``heading``.

    ``heading`` is in radians, counter-clockwise from east in world axes; screen y points
    down so the screen direction is (cos h, -sin h).
    """
    c = np.asarray(centre_px, dtype=float)
    f = np.array([math.cos(heading), -math.sin(heading)])
    s = np.array([-f[1], f[0]])
    nose = c + f * size
    left = c - f * size * 0.7 + s * size * 0.6
    right = c - f * size * 0.7 - s * size * 0.6
    return np.stack([nose, left, right])
