"""Placing objects without overlaps: the occupied outlines of a world being generated.

Every outline ever taken (walls, furniture at each of its poses, shuffle regions, keep-out
zones in front of doorways) is kept, so that an object placed later never overlaps one
placed before, at any run of the calendar.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dynmap_sim.world.polygons import (
    FloatArray,
    box_vertices,
    ccw,
    circle_vertices,
    edge_normals,
    sat_separation,
    thick_segment,
    transform,
)

HALF_PI = 1.5708


def outline(obj: dict[str, Any], pose=None, scale: float = 1.0) -> FloatArray:
    """Outline ``(K, 2)`` [m] of a world-file object dict at ``pose`` (default: its own)."""
    local = (
        circle_vertices(obj["radius_m"])
        if obj.get("shape") == "circle"
        else box_vertices(*obj["size"])
    )
    return transform(local, tuple(obj["pose"] if pose is None else pose), scale)


def box_poly(box) -> FloatArray:
    """A box ``(x0, y0, x1, y1)`` as a CCW polygon."""
    x0, y0, x1, y1 = box
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


class Placer:
    """Occupied outlines with a bounding-box broad phase and SAT narrow phase."""

    def __init__(self, walls: list[dict[str, Any]]) -> None:
        self._polys: list[FloatArray] = []
        self._axes: list[FloatArray] = []
        self._boxes = np.zeros((0, 4))
        self.tags: list[str] = []
        for w in walls:
            pts = w["points"]
            for a, b in zip(pts, pts[1:], strict=False):
                self.add(ccw(thick_segment(a, b, w["thickness_m"])), "wall")

    def add(self, poly: FloatArray, tag: str) -> None:
        """Mark ``poly`` occupied (``tag`` names what it is)."""
        self._polys.append(poly)
        self._axes.append(edge_normals(poly))
        box = np.concatenate([poly.min(axis=0), poly.max(axis=0)])
        self._boxes = np.vstack([self._boxes, box])
        self.tags.append(tag)

    def polygons(
        self, skip: tuple[str, ...] = (), only: str | tuple[str, ...] | None = None
    ) -> list[FloatArray]:
        """The occupied outlines whose tag starts with none of ``skip`` (and with ``only``)."""
        return [
            p
            for p, t in zip(self._polys, self.tags, strict=True)
            if not (skip and t.startswith(skip)) and (only is None or t.startswith(only))
        ]

    def free(self, poly: FloatArray, gap: float = 0.05, ignore: set[str] | None = None) -> bool:
        """True where ``poly`` keeps ``gap`` [m] from every occupied outline (but ``ignore``)."""
        lo, hi = poly.min(axis=0) - gap, poly.max(axis=0) + gap
        bb = self._boxes
        near = np.flatnonzero(
            (bb[:, 0] < hi[0]) & (bb[:, 2] > lo[0]) & (bb[:, 1] < hi[1]) & (bb[:, 3] > lo[1])
        )
        if not len(near):
            return True
        axes = edge_normals(poly)
        for k in near:
            if ignore and self.tags[k] in ignore:
                continue
            if sat_separation(poly, self._polys[k], axes, self._axes[k]) < gap:
                return False
        return True


def inside(poly: FloatArray, box, margin: float = 0.0) -> bool:
    """True where ``poly`` lies in ``box`` shrunk by ``margin`` (to a micrometre: headings
    are written to 1e-4 rad)."""
    lo, hi = poly.min(axis=0) + 1e-6, poly.max(axis=0) - 1e-6
    return bool(
        lo[0] >= box[0] + margin
        and lo[1] >= box[1] + margin
        and hi[0] <= box[2] - margin
        and hi[1] <= box[3] - margin
    )


def rounded_pose(x: float, y: float, th: float) -> list[float]:
    """A pose as written to the file: millimetres and 1e-4 rad."""
    return [round(float(x), 3), round(float(y), 3), round(float(th), 4)]
