"""The window of ``render_mode="human"``: the env's RGB frames shown at the scan rate.

Gymnasium's convention for ``"human"``: the env draws itself at every ``reset`` and ``step``
and ``render()`` returns None. The frame is the same numpy raster as ``"rgb_array"``; a
matplotlib figure (a core dependency, so the mode works on every install) only puts it on the
screen, throttled to ``render_fps`` so that an episode plays in real time. Where matplotlib
has no interactive backend (a headless machine: ``Agg``) the figure is drawn off screen and
the throttle still holds. Closing the window ends nothing: the env steps on without it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray


class HumanWindow:
    """A matplotlib window that shows ``(H, W, 3)`` uint8 frames at ``fps`` frames per
    second."""

    def __init__(self, title: str, fps: int) -> None:
        if int(fps) < 1:
            raise ValueError(f"fps must be >= 1, not {fps}")
        self.title = title
        self.fps = int(fps)
        self._fig: Any = None
        self._image: Any = None
        self._next_s = 0.0
        self._on_close = -1
        self.closed = False

    def _open(self, frame: NDArray[np.uint8]) -> None:
        import matplotlib.pyplot as plt

        h, w = frame.shape[:2]
        dpi = 100
        self._fig = plt.figure(self.title, figsize=(w / dpi, h / dpi), dpi=dpi)
        ax = self._fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        self._image = ax.imshow(frame, interpolation="nearest")
        self._on_close = self._fig.canvas.mpl_connect("close_event", lambda _e: self._forget())
        if self._fig.canvas.manager is not None and _interactive():
            self._fig.canvas.manager.show()

    def show(self, frame: NDArray[np.uint8]) -> None:
        """Put ``frame`` on the screen (the window opens, or resizes, to its size)."""
        if self.closed:
            return
        if self._image is None or self._image.get_array().shape != frame.shape:
            self.close_figure()
            self._open(frame)
        else:
            self._image.set_data(frame)
        self._fig.canvas.draw()
        wait = self._next_s - time.monotonic()
        if _interactive():
            self._fig.canvas.flush_events()  # the GUI's events: a click on close lands here
            self._fig.canvas.start_event_loop(max(wait, 1e-3))
        elif wait > 0:
            time.sleep(wait)
        self._next_s = time.monotonic() + 1.0 / self.fps

    def pixels(self) -> NDArray[np.uint8]:
        """What the window shows now, ``(H, W, 3)`` (for tests and screenshots)."""
        return np.asarray(self._fig.canvas.buffer_rgba())[..., :3].copy()

    def _forget(self) -> None:
        """The user closed the window: show nothing more."""
        self._fig = None
        self._image = None
        self.closed = True

    def close_figure(self) -> None:
        """Close the figure, if open, without taking it for the user's close."""
        if self._fig is not None:
            import matplotlib.pyplot as plt

            self._fig.canvas.mpl_disconnect(self._on_close)
            plt.close(self._fig)
        self._fig = None
        self._image = None

    def close(self) -> None:
        """Close the window (again: nothing)."""
        self.close_figure()
        self.closed = True


def _interactive() -> bool:
    """Whether matplotlib's backend draws on a screen (not ``Agg``, ``pdf``, ...)."""
    import matplotlib

    backend = matplotlib.get_backend().lower()
    return not any(backend.startswith(b) for b in ("agg", "pdf", "ps", "svg", "pgf", "cairo"))
