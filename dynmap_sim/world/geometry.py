"""Array view of the world's geometry for sensors (the lidar ray-caster reads this).

Every wall piece and object outline is a closed polygon, stored as its edge segments, so a
ray hits the face it meets first. Round objects and people's legs are circles. Each
primitive carries the index of its object in ``object_ids`` and its :class:`BeamClass`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.types import BeamClass
from dynmap_sim.world.polygons import polygon_edges
from dynmap_sim.world.schedule import ObjectState

KIND_CLASS: dict[str, int] = {
    "wall": int(BeamClass.WALL),
    "furniture": int(BeamClass.FURNITURE),
    "exhibit": int(BeamClass.EXHIBIT),
    "door": int(BeamClass.DOOR),
    "robot": int(BeamClass.ROBOT),
    "person": int(BeamClass.PERSON),
}


@dataclass(frozen=True)
class GeometryView:
    """Read-only geometry arrays in the map frame [m].

    ``segments`` ``(N, 4)`` rows ``x0, y0, x1, y1``; ``segment_object`` ``(N,)`` int32 index
    into ``object_ids``; ``segment_class`` ``(N,)`` int8 :class:`BeamClass`. ``circles``
    ``(M, 3)`` rows ``x, y, r`` (round objects first, then people's legs) with
    ``circle_object`` and ``circle_class``. ``static_version`` changes whenever the segments
    (or static circles) change; people's circles change every step without bumping it.
    """

    segments: NDArray[np.float64]
    segment_object: NDArray[np.int32]
    segment_class: NDArray[np.int8]
    circles: NDArray[np.float64]
    circle_object: NDArray[np.int32]
    circle_class: NDArray[np.int8]
    object_ids: tuple[str, ...]
    static_version: int


@dataclass(frozen=True)
class StaticGeometry:
    """The static part of a :class:`GeometryView` (walls and present objects)."""

    segments: NDArray[np.float64]
    segment_object: NDArray[np.int32]
    segment_class: NDArray[np.int8]
    circles: NDArray[np.float64]
    circle_object: NDArray[np.int32]
    circle_class: NDArray[np.int8]
    object_ids: tuple[str, ...]


def _ro(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def build_static(objects: Iterable[ObjectState]) -> StaticGeometry:
    """Segments and circles of ``objects`` (polygons become outlines, circles stay circles)."""
    segs, sobj, scls = [], [], []
    circ, cobj, ccls = [], [], []
    ids: list[str] = []
    for k, o in enumerate(objects):
        ids.append(o.id)
        cls = KIND_CLASS[o.kind]
        if o.circle is not None:
            circ.append(o.circle)
            cobj.append(k)
            ccls.append(cls)
            continue
        e = polygon_edges(o.polygon)
        segs.append(e)
        sobj.append(np.full(len(e), k, dtype=np.int32))
        scls.append(np.full(len(e), cls, dtype=np.int8))
    return StaticGeometry(
        segments=_ro(np.concatenate(segs) if segs else np.zeros((0, 4))),
        segment_object=_ro(np.concatenate(sobj) if sobj else np.zeros(0, np.int32)),
        segment_class=_ro(np.concatenate(scls) if scls else np.zeros(0, np.int8)),
        circles=_ro(np.array(circ, dtype=np.float64).reshape(-1, 3)),
        circle_object=_ro(np.array(cobj, dtype=np.int32)),
        circle_class=_ro(np.array(ccls, dtype=np.int8)),
        object_ids=tuple(ids),
    )
