"""Many worlds stepped together (``WorldBatch``, the vector env's) give the numbers of
``World.step`` of each, bit for bit: people, legs, goals, pymunk bodies."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from dynmap_sim.world import World, load_world, resolve_world_path
from dynmap_sim.world.people import batch as people_batch
from dynmap_sim.world.people import correction
from dynmap_sim.world.world import WorldBatch


def _state(w: World) -> bytes:
    c = w.crowd
    arrays = (c.pos, c.vel, c.goal, c.phase, c.stuck_s, c.best_goal_m, c.waypoint)
    bodies = [tuple(b.position) + tuple(b.velocity) for b in w._people_bodies]
    return (
        b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)
        + repr((bodies, w.elapsed_s)).encode()
        + w.geometry.circles.tobytes()
    )


def _worlds(name: str, slots: list[tuple[int, int, int]]) -> list[World]:
    spec = load_world(resolve_world_path(name))
    out = []
    for seed, day, run in slots:
        w = World(spec, seed=seed)
        w.reset(day, run)
        out.append(w)
    return out


@pytest.mark.parametrize(
    ("name", "slots"),
    [
        # crowds of different sizes (and none) among different furniture
        ("lab", [(0, 1, 1), (1, 1, 2), (2, 1, 3), (3, 2, 2), (4, 1, 2)]),
        ("apartment", [(0, 15, 1), (1, 1, 1), (2, 16, 1)]),
    ],
)
def test_world_batch_is_world_step_of_each(name, slots, monkeypatch) -> None:
    """Robots drive into the crowds (some stand on people, so every correction of the step
    runs); the batch's worlds and copies stepped one by one stay identical throughout."""
    calls: dict[str, int] = {}
    for fn in ("_clear_robot", "_separate_pairs", "_push_out_of_walls"):
        real = getattr(correction, fn)

        def counted(*a, _real=real, _fn=fn, **kw):
            calls[_fn] = calls.get(_fn, 0) + 1
            return _real(*a, **kw)

        monkeypatch.setattr(people_batch, fn, counted)
    worlds = _worlds(name, slots)
    alone = copy.deepcopy(worlds)
    batch = WorldBatch()
    rng = np.random.default_rng(5)
    radii = [0.2, 0.25, 0.2, 0.3, 0.2][: len(worlds)]
    for t in range(150):
        poses = []
        for w in worlds:
            if w.crowd.n and t % 7 == 0:  # stand next to someone
                p = w.crowd.pos[rng.integers(w.crowd.n)] + rng.normal(0, 0.2, 2)
            else:
                p = np.asarray(w.spec.robot.start[:2]) + rng.normal(0, 1.0, 2)
            poses.append(np.array([p[0], p[1], rng.uniform(-3, 3)]))
        batch.step(worlds, 0.1, poses, radii)
        for w, pose, rr in zip(alone, poses, radii, strict=True):
            w.step(0.1, robot_pose=pose, robot_radius_m=rr)
        for a, b in zip(worlds, alone, strict=True):
            assert _state(a) == _state(b), t
    assert calls.get("_clear_robot", 0) > 0
    if name == "lab":  # the lunch crowd: bodies overlap now and then
        assert calls.get("_separate_pairs", 0) > 0 and calls.get("_push_out_of_walls", 0) > 0


def test_world_batch_after_a_world_stepped_alone_or_reset() -> None:
    """The batch keeps its crowds' state as views of joint rows; a world stepped on its own
    between batch steps, or reset to a new run, is picked up again with the same numbers."""
    worlds = _worlds("lab", [(0, 1, 2), (1, 1, 2), (2, 2, 2)])
    alone = copy.deepcopy(worlds)
    batch = WorldBatch()
    poses = [np.array([*w.spec.robot.start[:2], 0.0]) for w in worlds]
    for t in range(40):
        if t == 15:  # one world steps on its own
            for w in (worlds[1], alone[1]):
                w.step(0.1, robot_pose=poses[1], robot_radius_m=0.2)
        if t == 25:  # another starts a new run
            for w in (worlds[2], alone[2]):
                w.reset(1, 3)
        batch.step(worlds, 0.1, poses, [0.2] * 3)
        for w, pose in zip(alone, poses, strict=True):
            w.step(0.1, robot_pose=pose, robot_radius_m=0.2)
        for a, b in zip(worlds, alone, strict=True):
            assert _state(a) == _state(b), t
