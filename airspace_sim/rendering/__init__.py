"""Drawing world snapshots: :class:`Renderer` (pygame, offscreen) and frame writers.

- ``Renderer(width=800, height=800, view=None).render(world.snapshot()) -> (H, W, 3) uint8``
- ``save_frames(frames, directory) -> list of PNG paths``
- ``write_gif(frames, path, fps=10) -> path``

This is the only package of airspace_sim that imports pygame.
"""

from airspace_sim.rendering.frames import save_frames, write_gif
from airspace_sim.rendering.renderer import COLORS, Renderer

__all__ = ["COLORS", "Renderer", "save_frames", "write_gif"]
