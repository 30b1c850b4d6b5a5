"""The walls visible from a pose, and the anchored first run's back end on them."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper
from dynmap_sim.agent.mapping.keyframe_slam import Keyframe
from dynmap_sim.agent.mapping.loop_closure import LoopClosureConfig
from dynmap_sim.agent.mapping.wall_factors import WallPlan
from dynmap_sim.agent.params import ParamError
from dynmap_sim.types import Odometry, Scan


def test_the_far_face_of_a_partition_is_hidden():
    """A 0.2 m partition is two faces in the plan: from its south only the south face is
    seen, and both legs of a corner are seen from inside it."""
    plan = WallPlan.from_segments([[0, 0, 10, 0], [0, 0.2, 10, 0.2]], 0.05)
    seen = plan.visible_from([5.0, -2.0], 6.0)
    assert len(seen) and np.all(seen[:, 1] == 0.0)
    assert len(plan.visible_from([5.0, 2.0], 6.0)) == len(seen)  # the north face, mirrored
    assert np.all(plan.visible_from([5.0, 2.0], 6.0)[:, 1] == 0.2)
    corner = WallPlan.from_segments([[0, 0, 4, 0], [0, 0, 0, 4]], 0.1)
    inside = corner.visible_from([1.0, 1.0], 10.0)
    assert len(inside) == len(corner.points)
    assert len(corner.visible_from([1.0, 1.0], 1.5)) < len(inside)  # the reach bounds them


def test_the_walls_take_a_heading_error_out_of_the_keyframes(segments, laser, cast, path_fn):
    """Keyframes of a drifted front end (a heading error that grows to 2 degrees over the
    run, as in an open hall) are pulled back onto the walls they see: the finished map is
    within centimetres of the truth, the drift is gone."""
    rng = np.random.default_rng(1)
    truth = path_fn(laps=1)
    mapper = FirstRunMapper(laser, truth[0], walls=segments[:6])
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        mapper.update(Odometry(truth[k], 0.1 * k), Scan(r, 0.1 * k))
    slam = mapper.slam
    n = len(slam.keyframes)
    drift = np.radians(2.0) * np.arange(n) / (n - 1)
    start = slam.keyframes[0].pose
    for m, kf in enumerate(slam.keyframes):  # rotate each keyframe about the start
        turn = np.array([0.0, 0.0, drift[m]])
        rel = se2.between(start, kf.pose)
        moved = se2.compose(start, se2.compose(turn, rel))
        slam.keyframes[m] = Keyframe(moved, kf.ranges_m, kf.scan_index)
    idx = np.array([kf.scan_index for kf in slam.keyframes])
    before = np.hypot(*(np.array([kf.pose[:2] for kf in slam.keyframes]) - truth[idx, :2]).T)
    after = mapper.loop_closure.optimize_on_walls(slam)
    err = np.hypot(*(after[:, :2] - truth[idx, :2]).T)
    assert before.max() > 0.08
    assert mapper.loop_closure.stats["wall_factors"] > n // 2
    assert err.max() < 0.03
    assert np.all(after[0] == start)  # the known initial pose stays


def test_wall_factors_off_keeps_the_front_ends_poses(segments, laser, cast, path_fn):
    """``wall_factors = false``: the anchored first run's map is the front end's poses."""
    truth = path_fn(laps=1)[:200]
    config = FirstRunConfig(loops=LoopClosureConfig(wall_factors=False))
    mapper = FirstRunMapper(laser, truth[0], config, walls=segments[:6])
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m).astype(np.float32)
        mapper.update(Odometry(truth[k], 0.1 * k), Scan(r, 0.1 * k))
    poses = np.array([kf.pose for kf in mapper.slam.keyframes])
    smap = mapper.finish()
    assert np.array_equal(np.array([kf.pose for kf in smap.keyframes]), poses)


def _online_errors(segments, laser, cast, path_fn, odo_fn, every: int) -> np.ndarray:
    """Online errors [m] of four laps on drifting odometry with the walls granted."""
    rng = np.random.default_rng(0)
    truth = path_fn(laps=4)
    odo = odo_fn(truth, rng)
    config = FirstRunConfig(loops=LoopClosureConfig(wall_graph_every=every))
    mapper = FirstRunMapper(laser, truth[0], config, walls=segments[:6])
    est = []
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        est.append(mapper.update(Odometry(odo[k], 0.1 * k), Scan(r, 0.1 * k)).mean)
    return np.hypot(*(np.array(est)[:, :2] - truth[:, :2]).T)


def test_the_keyframes_are_optimized_on_the_walls_during_the_run(
    segments, laser, cast, path_fn, odo_fn
):
    """Every ``wall_graph_every`` keyframes the graph is optimized and the front end goes on
    from the corrected keyframes: its online error is smaller than with the graph only at
    the end (``wall_graph_every = 0``)."""
    at_end = _online_errors(segments, laser, cast, path_fn, odo_fn, every=0)
    online = _online_errors(segments, laser, cast, path_fn, odo_fn, every=10)
    assert np.sqrt(np.mean(online**2)) < 0.9 * np.sqrt(np.mean(at_end**2))
    assert online.max() < at_end.max()


def test_moving_the_keyframes_carries_the_pose_along(segments, laser, cast, path_fn):
    """``move_keyframes``: the current pose and the recent scans' poses keep their place in
    the newest keyframe's frame, and the steps between keyframes stay as measured."""
    truth = path_fn(laps=1)[:120]
    mapper = FirstRunMapper(laser, truth[0], walls=segments[:6])
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m).astype(np.float32)
        mapper.update(Odometry(truth[k], 0.1 * k), Scan(r, 0.1 * k))
    slam = mapper.slam
    steps = [s.copy() for s in slam.keyframe_steps]
    rel = se2.between(slam.keyframes[-1].pose, slam.pose)
    hist = [se2.between(slam.keyframes[-1].pose, p) for p, _ in slam._history]
    moved = np.array([se2.compose([0.1, -0.2, 0.02], kf.pose) for kf in slam.keyframes])
    slam.move_keyframes(moved)
    assert np.allclose(se2.between(slam.keyframes[-1].pose, slam.pose), rel, atol=1e-12)
    after = [se2.between(slam.keyframes[-1].pose, p) for p, _ in slam._history]
    assert np.allclose(after, hist, atol=1e-12)
    assert all(np.array_equal(a, b) for a, b in zip(steps, slam.keyframe_steps, strict=True))


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"wall_graph_every": -1}, "wall_graph_every must be an integer >= 0"),
        ({"wall_min_points": 0}, "wall_min_points must be an integer >= 1"),
        ({"wall_info_inflation": 0}, "wall_info_inflation must be a finite number > 0"),
        ({"wall_max_rmse_m": -0.01}, "wall_max_rmse_m must be a finite number > 0"),
        ({"wall_gate_m": [0.3, -1]}, "wall_gate_m"),
    ],
)
def test_bad_wall_parameters_are_refused_by_name(params, message):
    """A scenario's ``mapper_params`` with a wall parameter out of its range: an error that
    names the parameter."""
    with pytest.raises(ParamError, match=message):
        FirstRunConfig.from_params(**params)
