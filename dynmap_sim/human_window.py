"""The window of ``render_mode="human"``: the env's RGB frames shown at the scan rate.

Gymnasium's convention for ``"human"``: the env draws itself at every ``reset`` and ``step``
and ``render()`` returns None. The frame is the same numpy raster as ``"rgb_array"``; pygame
(extra ``video``) only puts it on the screen, throttled to ``render_fps`` so that an episode
plays in real time. Closing the window ends nothing: the env steps on without it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

#: What to install when pygame is missing.
INSTALL_HINT = "render_mode='human' needs pygame: pip install 'dynmap-sim[video]'"


class HumanWindow:
    """A pygame window that shows ``(H, W, 3)`` uint8 frames at ``fps`` frames per second."""

    def __init__(self, title: str, fps: int) -> None:
        try:
            import pygame
        except ImportError as exc:
            raise ImportError(INSTALL_HINT) from exc
        self._pg: Any = pygame
        self.title = title
        self.fps = int(fps)
        self._screen: Any = None
        self._clock: Any = None
        self.closed = False

    def show(self, frame: NDArray[np.uint8]) -> None:
        """Put ``frame`` on the screen (the window opens, or resizes, to its size)."""
        if self.closed:
            return
        pg = self._pg
        h, w = frame.shape[:2]
        if self._screen is None or self._screen.get_size() != (w, h):
            pg.display.init()
            pg.display.set_caption(self.title)
            self._screen = pg.display.set_mode((w, h))
            self._clock = pg.time.Clock()
        for event in pg.event.get():
            if event.type == pg.QUIT:
                self.close()
                return
        # pygame's surfaces are (x, y): the frame's transpose
        pg.surfarray.blit_array(self._screen, np.ascontiguousarray(frame.transpose(1, 0, 2)))
        pg.display.flip()
        self._clock.tick(self.fps)

    def pixels(self) -> NDArray[np.uint8]:
        """What the window shows now, ``(H, W, 3)`` (for tests and screenshots)."""
        return self._pg.surfarray.array3d(self._screen).transpose(1, 0, 2)

    def close(self) -> None:
        """Close the window (again: nothing)."""
        if self._screen is not None:
            self._pg.display.quit()
        self._screen = None
        self.closed = True
