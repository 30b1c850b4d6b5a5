"""A small valid world used by the world tests (a 6 m x 4 m room)."""

import copy
import datetime as dt

import pytest

BASE = {
    "name": "box-room",
    "bounds": [-0.5, -0.5, 6.5, 4.5],
    "calendar": {"start": dt.date(2024, 1, 1), "n_days": 10, "runs": ["09:00", "14:00"]},
    "robot": {"start": [1.0, 1.0, 0.0], "route": [[1.0, 1.0], [5.0, 1.0], [5.0, 3.0]]},
    "walls": [
        {
            "id": "outer",
            "points": [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]],
            "thickness_m": 0.2,
        }
    ],
    "objects": [
        {"id": "table", "kind": "furniture", "size": [1.0, 0.6], "pose": [3.0, 3.0, 0.0]},
        {
            "id": "chair_1",
            "kind": "furniture",
            "group": "chairs",
            "size": [0.4, 0.4],
            "pose": [1.5, 3.2, 0.0],
        },
        {
            "id": "chair_2",
            "kind": "furniture",
            "group": "chairs",
            "size": [0.4, 0.4],
            "pose": [2.2, 3.2, 0.0],
        },
        {
            "id": "poster",
            "kind": "exhibit",
            "group": "expo",
            "size": [0.6, 0.1],
            "pose": [4.0, 2.0, 0.0],
        },
        {
            "id": "door",
            "kind": "door",
            "size": [0.8, 0.05],
            "pose": [5.5, 2.0, 0.0],
            "open": False,
        },
        {
            "id": "plant",
            "kind": "furniture",
            "shape": "circle",
            "radius_m": 0.2,
            "pose": [0.6, 3.3, 0.0],
        },
    ],
    "schedule": [
        {"action": "present", "group": "expo", "start": 3, "end": 5},
        {"action": "shuffle", "group": "chairs", "region": [0.4, 2.4, 2.8, 3.8]},
        {"action": "open", "target": "door", "at": 4, "run": 2},
        {
            "action": "grow",
            "target": "plant",
            "start": 1,
            "end": 10,
            "scale_start": 1.0,
            "scale_end": 1.5,
        },
    ],
    "people": [
        {"id": "walkers", "count": 3, "areas": [[0.5, 0.5, 5.5, 2.2]], "start": 2, "end": 4}
    ],
}


@pytest.fixture
def base_world() -> dict:
    """A deep copy of the small valid world, safe to mutate."""
    return copy.deepcopy(BASE)
