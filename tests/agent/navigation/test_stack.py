"""The navigation stack driving the real env (the apartment of H&W 2011): the goal reached
without a collision, the day-22 block passed by replanning with a new route learned, and a
wrong estimate stopped by the collision monitor. Dead reckoning steers (``static-mcl`` on the
walls-only prior loses the apartment within seconds, see the stack's closing note)."""

import pickle

import numpy as np
import pytest

from dynmap_sim.agent.control.corridor_follower import CorridorFollowerParams
from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.agent.navigation.policy import NavigationPolicy
from dynmap_sim.agent.navigation.route_memory import RouteMemory
from dynmap_sim.agent.navigation.route_tracking import RoutePosition
from dynmap_sim.agent.navigation.stack import NavigationStack, StackParams
from dynmap_sim.agent.planning.costmap import CostmapParams
from dynmap_sim.env import DynMapEnv
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan


def prior_of(env, day: int) -> Prior:
    """What a scenario grants: start pose, walls, bounds, the route (H&W Fig. 4)."""
    return env.unwrapped.world_facts().prior(day)


def drive(env, policy, day: int):
    """One run with ``policy``; returns (collision steps, last info, env terminated: the true
    robot reached the route's end)."""
    obs, info = env.reset(seed=0, options={"day": day})
    policy.reset(prior_of(env, day))
    collisions = 0
    terminated = truncated = False
    while not (terminated or truncated or policy.done):
        obs, _, terminated, truncated, info = env.step(policy.act(obs))
        collisions += int(info["collision"])
    policy.end_run()
    return collisions, info, terminated


def odometry_policy(env) -> NavigationPolicy:
    u = env.unwrapped
    loc = make_localizer("odometry", laser=u.laser_spec, rng=np.random.default_rng(0))
    return NavigationPolicy(loc, NavigationStack(u.laser_spec, u.robot_radius_m))


def test_day_1_reaches_the_routes_end_without_a_collision():
    env = DynMapEnv("apartment", people=False, max_episode_steps=1500)
    policy = odometry_policy(env)
    collisions, info, _ = drive(env, policy, 1)
    stack = policy.stack
    route_end = env.unwrapped.world_facts().route[-1]
    assert stack.done and not stack.gave_up
    assert collisions == 0
    assert info["route_progress"] > 0.95
    # dead reckoning drifts: the true pose is near the end, not on it
    assert np.hypot(*(info["truth"]["pose"][:2] - route_end)) < 0.6
    assert stack.replans == 0 and stack.recoveries == 0
    assert [k for _, k, _ in stack.events if k == "goal"] == ["goal"]
    # the route memory learned the travel times of the route (none learned at the start)
    prior_route = next(r for r in stack.route_memory.routes.values() if r.prior)
    assert np.isfinite(prior_route.wp[1:, 5]).mean() > 0.9
    again = pickle.loads(pickle.dumps(stack))  # checkpointed after every run
    np.testing.assert_equal(again.route_memory.to_dict(), stack.route_memory.to_dict())


def test_day_22_the_blocked_route_is_passed_by_replanning_and_learned():
    env = DynMapEnv("apartment", people=False, max_episode_steps=2500)
    policy = odometry_policy(env)
    collisions, info, terminated = drive(env, policy, 22)
    stack = policy.stack
    kinds = [k for _, k, _ in stack.events]
    assert (stack.done or terminated) and not stack.gave_up
    assert collisions == 0
    assert info["route_progress"] > 0.95
    assert "block" in kinds and "detour" in kinds and stack.replans >= 1
    mem = stack.route_memory
    new = [r for r in mem.routes.values() if not r.prior]
    assert len(new) == 1 and len(new[0].ids) >= 4  # the detour, recorded as a route
    assert mem.blocked  # the blocked stretch stays blocked until seen free
    # x of the block's centre (route_blocker at 5.9, 4.6): the new route passes it west
    near = np.abs(new[0].xy[:, 1] - 4.6) < 0.4
    assert near.any() and np.all(new[0].xy[near, 0] < 5.9 - 0.65)


def test_a_wrong_estimate_is_stopped_by_the_collision_monitor():
    """The estimate 0.3 m off (to the robot's left): the stack steers the true robot toward
    the things on its right; the monitor, from the raw scan, stops it before contact."""
    env = DynMapEnv("apartment", people=False, max_episode_steps=900)
    u = env.unwrapped
    stack = NavigationStack(u.laser_spec, u.robot_radius_m)
    obs, info = env.reset(seed=0, options={"day": 1})
    stack.begin_run(prior_of(env, 1))
    collisions = 0
    for k in range(900):
        truth = info["truth"]["pose"]
        est = truth + np.array([-0.3 * np.sin(truth[2]), 0.3 * np.cos(truth[2]), 0.0])
        t = k * 0.1
        cmd = stack.step(
            t,
            Odometry(obs["odom"].copy(), t),
            Scan(obs["scan"].copy(), t),
            PoseEstimate(est, np.eye(3) * 0.01),
        )
        obs, _, terminated, truncated, info = env.step(cmd)
        collisions += int(info["collision"])
        if terminated or truncated or stack.done or stack.gave_up:
            break
    assert collisions == 0
    assert stack.monitor_stops + stack.monitor_slowdowns > 0


def test_a_loop_route_start_is_no_pass_of_every_waypoint():
    """H&W's route ends where it starts: a pose that locates on the last segment right after
    the first must not count as driving the whole route (no travel times, no unblocking)."""
    route = np.array([[0.0, 0.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0], [0.0, 0.0]])
    mem = RouteMemory.from_prior(route, 0.35, 0.35, 0.0)
    r = next(iter(mem.routes.values()))
    mem.block((int(r.ids[5]), int(r.ids[6])))
    mem.observe([0.0, 0.02, 1.57], 0.1)  # on the first segment
    mem.observe([0.01, 0.0, 1.57], 0.2)  # a hair nearer the last one
    assert mem.blocked
    assert not np.isfinite(r.wp[1:-1, 5]).any()


def test_bad_input_is_a_clear_error():
    u = DynMapEnv("apartment", people=False).unwrapped
    stack = NavigationStack(u.laser_spec, u.robot_radius_m)
    with pytest.raises(RuntimeError, match="begin_run"):
        stack.step(0.0, Odometry(np.zeros(3)), Scan(np.zeros(683, np.float32)), None)
    with pytest.raises(ValueError, match="prior.route"):
        stack.begin_run(Prior(initial_pose=np.zeros(3), bounds=(0, 0, 5, 5)))
    with pytest.raises(ValueError, match="prior.route"):
        stack.begin_run(Prior(np.zeros(3), bounds=(0, 0, 5, 5), route=np.zeros((1, 2))))
    with pytest.raises(ValueError, match="cut_offsets"):
        StackParams(cut_offsets=4)
    with pytest.raises(TypeError, match=r"StackParams.follower: unknown parameters \['nope'\]"):
        StackParams(follower={"nope": 1.0})
    with pytest.raises(
        ValueError, match="StackParams.follower: full_speed_clearance_m must be a finite number > 0"
    ):
        StackParams(follower={"full_speed_clearance_m": -1.0})
    with pytest.raises(ValueError, match="StackParams.follower: speed_mps set by the stack"):
        StackParams(follower={"speed_mps": 0.5})


def test_a_scenarios_tables_become_the_parts_parameters():
    """``[driver.params.follower]`` in a scenario is a mapping: the stack's part gets it as its
    dataclass, every other field at its default."""
    p = StackParams(follower={"full_speed_clearance_m": 0.56, "regulated_min_radius_m": 0})
    assert isinstance(p.follower, CorridorFollowerParams)
    assert p.follower.full_speed_clearance_m == 0.56
    assert p.follower.regulated_min_radius_m == 0.0
    assert p.follower.lookahead_m == CorridorFollowerParams().lookahead_m
    assert p.costmap == CostmapParams()


def test_a_loop_cut_in_two_by_forgetting_is_still_driven():
    """Regression (apartment-28d-autonomous, day 21 on): once forgetting cut the loop route
    in two, its start and end waypoints (one spot) belong to two routes and a zero-length
    join connects them; route A* went start -> join -> goal, a plan of no length, and the
    robot, not yet armed, stood still until the recovery gave up. The plan must leave."""
    laser = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
    loop = np.array([[0.0, 0.0], [0.0, 3.0], [3.0, 3.0], [3.0, 0.0], [0.0, 0.0]])

    def prior(day: int) -> Prior:
        return Prior(
            initial_pose=np.array([0.0, 0.0, np.pi / 2]),
            bounds=(-1.0, -1.0, 4.0, 4.0),
            day=day,
            run=1,
            first_run=day == 1,
            route=loop,
        )

    stack = NavigationStack(laser, 0.17)
    stack.begin_run(prior(1))
    mem = stack.route_memory
    r = next(iter(mem.routes.values()))
    # days later: the robot drove the loop daily but a detour instead of its east side
    day_s = 5 * 86_400.0
    mem.routes[r.route_id].wp[:, 4] = day_s
    east = np.flatnonzero((r.xy[:, 0] > 2.9) & (r.xy[:, 1] < 2.9) & (r.xy[:, 1] > 0.1))
    a, b = int(east[0]) - 1, int(east[-1]) + 1
    mem.routes[r.route_id].wp[a + 1 : b + 1, 4] = 0.0
    mem.add_route([r.xy[a], [2.0, 1.5], r.xy[b]], 0.2, 0.35, day_s, travel_time_s=[0, 5, 5])
    assert mem.forget(day_s) == b - a
    pieces = [q for q in mem.routes.values() if q.prior]
    assert len(pieces) == 2  # the loop's start and end now lie on two routes

    stack.begin_run(prior(5))
    free = Scan(np.full(laser.n_beams, np.inf, dtype=np.float32), 0.0)
    pose = np.array([0.0, 0.0, np.pi / 2])
    speeds = []
    for k in range(20):
        t = 36_000.0 + 0.1 * k
        cmd = stack.step(
            t, Odometry(pose.copy(), t), free, PoseEstimate(pose.copy(), np.eye(3) * 1e-4)
        )
        speeds.append(float(cmd[0]))
        pose = pose + 0.1 * cmd[0] * np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        pose[2] += 0.1 * cmd[1]
    path = stack.planned_path()
    # the plan leaves the start, up the west side to the loop's via point (5 m along)
    assert path is not None and np.sum(np.hypot(*np.diff(path, axis=0).T)) >= 4.5
    assert np.allclose(path[-1], [2.0, 3.0])
    assert max(speeds) > 0.2 and not stack.gave_up


def test_a_loop_is_driven_round_although_a_recorded_route_joins_its_start_and_end():
    """Regression (office-autonomous: 0 of 20 runs went round): a route recorded on day 1
    joins the loop's first stretch to its last, next to the start; the goal (the start) was
    then reached over that shortcut after a few metres. Via points make the robot go round."""
    laser = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
    loop = np.array([[0.0, 0.0], [0.0, 3.0], [3.0, 3.0], [3.0, 0.0], [0.0, 0.0]])
    prior = Prior(
        initial_pose=np.array([0.0, 0.0, np.pi / 2]),
        bounds=(-1.0, -1.0, 4.0, 4.0),
        day=2,
        run=1,
        first_run=False,
        route=loop,
    )
    stack = NavigationStack(laser, 0.17)
    stack.begin_run(prior)
    stack.route_memory.add_route(  # the shortcut: first stretch -> last stretch
        [[0.0, 0.8], [0.8, 0.8], [0.8, 0.0]], 0.2, 0.35, 2 * 86_400.0, travel_time_s=[0, 3, 3]
    )
    stack.begin_run(prior)
    free = Scan(np.full(laser.n_beams, np.inf, dtype=np.float32), 0.0)
    pose = np.array([0.0, 0.0, np.pi / 2])
    driven = 0.0
    for k in range(1200):
        t = 36_000.0 + 0.1 * k
        cmd = stack.step(
            t, Odometry(pose.copy(), t), free, PoseEstimate(pose.copy(), np.eye(3) * 1e-4)
        )
        step = 0.1 * cmd[0] * np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        driven += float(np.hypot(*step[:2]))
        pose = pose + step
        pose[2] += 0.1 * cmd[1]
        if stack.done or stack.gave_up:
            break
    kinds = [kind for _, kind, _ in stack.events]
    assert stack.done and not stack.gave_up
    assert "via" in kinds and kinds.index("via") < kinds.index("goal")
    assert driven > 10.0  # round the 12 m loop, not over the 2.4 m shortcut


def test_via_points_behind_a_detour_are_passed_but_not_the_loop_seen_at_its_start():
    """A via point is passed when the robot is tracked on the prior route at most two via
    spacings beyond it (a detour round a block rejoined there), never when the tracked
    position is the loop's end, next to its start (lab, day 2: the stack took all 20 via
    points as passed 11 s into the run and stopped at the start)."""
    laser = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
    loop = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.0]])
    prior = Prior(np.array([0.0, 0.0, 0.0]), bounds=(-1, -1, 11, 11), route=loop, day=1, run=1)
    stack = NavigationStack(laser, 0.17)
    stack.begin_run(prior)
    vias = [wid for _, wid in stack.targets.vias]
    assert len(vias) == 7  # every 5 m of the 40 m loop, none within 2.5 m of its end
    prior_route = next(iter(stack.route_memory.routes.values()))

    def at(waypoint: int) -> None:
        k = int(np.flatnonzero(prior_route.ids == waypoint)[0])
        xy = prior_route.xy[k]
        stack._route_pos = RoutePosition(0, k + 1, waypoint, waypoint + 1, 0.1, 0.0, 0.0, 0.0,
                                         0.35, True, (float(xy[0]), float(xy[1])))  # fmt: skip
        stack.targets.armed = True
        stack._check_goal(0.0, np.array([*xy, 0.0]))

    at(int(prior_route.ids[-2]))  # the last segment, 0.5 m before the start
    assert stack.targets.via_k == 0
    at(vias[1] + 2)  # rejoined 1 m after the second via point
    assert stack.targets.via_k == 2


def _loop_stack_without_its_end():
    """A stack on a 3 m x 3 m loop whose last stretch (and the goal waypoint, the loop's
    end) was forgotten: the route now ends 0.5 m before its start, and no other route
    joins the two. Returns the stack, the laser and the loop's prior for a day. Without via
    points, so that the first plan already heads for the goal over the gap."""
    laser = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
    loop = np.array([[0.0, 0.0], [0.0, 3.0], [3.0, 3.0], [3.0, 0.0], [0.0, 0.0]])

    def prior(day: int) -> Prior:
        return Prior(
            initial_pose=np.array([0.0, 0.0, np.pi / 2]),
            bounds=(-1.0, -1.0, 4.0, 4.0),
            day=day,
            run=1,
            first_run=day == 1,
            route=loop,
        )

    stack = NavigationStack(laser, 0.17, StackParams(loop_via_spacing_m=0.0))
    stack.begin_run(prior(1))
    mem = stack.route_memory
    r = next(iter(mem.routes.values()))
    r.ids, r.wp = r.ids[:-1], r.wp[:-1]  # the goal waypoint (0, 0) is gone
    mem.route_set.changed()
    return stack, laser, prior


def test_a_loop_whose_end_was_forgotten_is_still_driven():
    """Regression (apartment-28d-autonomous-mcl, days 22-28 stood still): forgetting had
    dropped the loop's goal waypoint and then the recorded route whose end joined both the
    loop's end and its start, so no route edge led back to the start (the goal). Route A*
    found nothing and the grid fallback, from the loop's start (= its goal), had nowhere to
    go: a zero command until the recovery gave up. The stack bridges the route graph's dead
    end to the goal with grid A* and drives the loop."""
    stack, laser, prior = _loop_stack_without_its_end()
    day_s = 5 * 86_400.0
    assert stack.route_memory.forget(day_s) == 0
    stack.begin_run(prior(5))
    free = Scan(np.full(laser.n_beams, np.inf, dtype=np.float32), 0.0)
    pose = np.array([0.0, 0.0, np.pi / 2])
    speeds = []
    for k in range(20):
        t = 36_000.0 + 0.1 * k
        cmd = stack.step(
            t, Odometry(pose.copy(), t), free, PoseEstimate(pose.copy(), np.eye(3) * 1e-4)
        )
        speeds.append(float(cmd[0]))
        pose = pose + 0.1 * cmd[0] * np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        pose[2] += 0.1 * cmd[1]
    path = stack.planned_path()
    assert path is not None and np.sum(np.hypot(*np.diff(path, axis=0).T)) > 10.0
    assert np.hypot(*(path[-1] - [0.0, 0.0])) < 0.05  # over the gap to the goal
    assert max(speeds) > 0.2 and not stack.gave_up
    assert any(kind == "bridge" for _, kind, _ in stack.events)
    assert not any(kind == "no_path" for _, kind, _ in stack.events)


def test_the_office_corridor_closed_is_passed_through_the_open_plan_office():
    """Office floor (a world the stack was not tuned for), day 6 run 1: a pallet closes the
    corridor, the way round is through the open-plan office, whose desks the prior does not
    hold. With the true pose as the estimate (navigation alone), the robot goes round and
    finishes the loop: the recovery's replan keeps the detour, and a detour whose nearest
    route point lies behind a wall reaches it on the grid (both failed here before)."""
    env = DynMapEnv("office", max_episode_steps=9000)
    u = env.unwrapped
    stack = NavigationStack(u.laser_spec, u.robot_radius_m)
    obs, info = env.reset(seed=0, options={"day": 6, "run": 1})
    stack.begin_run(prior_of(env, 6))
    collisions, terminated = 0, False
    for k in range(9000):
        t = k * 0.1
        truth = info["truth"]["pose"].copy()  # the test's oracle, never the agent's
        cmd = stack.step(
            t,
            Odometry(obs["odom"].copy(), t),
            Scan(obs["scan"].copy(), t),
            PoseEstimate(truth, np.eye(3) * 1e-4),
        )
        obs, _, terminated, truncated, info = env.step(cmd)
        collisions += int(info["collision"])
        if terminated or truncated or stack.done or stack.gave_up:
            break
    kinds = [k for _, k, _ in stack.events]
    assert terminated and not stack.gave_up and collisions == 0
    assert info["route_progress"] > 0.95
    assert "block" in kinds and "detour" in kinds
    assert sum(1 for r in stack.route_memory.routes.values() if not r.prior) >= 1
