"""Drawing world snapshots and writing them as frames.

- ``Renderer(width=800, height=800, view=None).render(world.snapshot()) -> (H, W, 3) uint8``
  (:mod:`.renderer`, overlays in :mod:`.hud`, colours in :mod:`.style`, pure-numpy view
  geometry in :mod:`.geometry`); it reads :class:`~airspace_sim.world.snapshot.Snapshot`
  values only;
- ``FrameWriter(directory, video=None | "gif" | "mp4", fps=10)``: numbered PNG frames plus
  an optional video (:mod:`.frames`).

This is the only package of airspace_sim that imports pygame.
"""

import os

# before pygame is first imported (by .renderer and .hud): no banner on stdout
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

from airspace_sim.rendering.frames import FrameWriter  # noqa: E402
from airspace_sim.rendering.renderer import Renderer  # noqa: E402
from airspace_sim.rendering.style import COLORS  # noqa: E402

__all__ = ["COLORS", "FrameWriter", "Renderer"]
