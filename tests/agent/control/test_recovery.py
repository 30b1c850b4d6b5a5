"""Stuck detection and recovery (nav2 progress checker + behaviour-tree recovery): the walk
wait -> back up -> replan -> give up on a robot that never moves, the checks on the space
behind, the reset on progress, the ``blocked`` trigger."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast

sys.path.insert(0, str(Path(__file__).parent))
from control_world import HARD_M, SPEED_MPS, corridor, grid_of, seg_distance  # noqa: E402

from dynmap_sim.agent.control.collision_monitor import CollisionMonitor  # noqa: E402
from dynmap_sim.agent.control.corridor_follower import CorridorFollower  # noqa: E402
from dynmap_sim.agent.control.recovery import Recovery, RecoveryParams  # noqa: E402
from dynmap_sim.types import Scan  # noqa: E402

DT = 0.1
GO = np.array([0.3, 0.0])  # the controller keeps asking to drive
EMPTY = Scan(np.full(LASER.n_beams, np.inf, dtype=np.float32))


def recovery(**params) -> Recovery:
    return Recovery(LASER, robot_radius_m=0.2, **params)


def run(rec: Recovery, t0: float, pose, seconds: float, command=GO, blocked=False, scan=EMPTY):
    """Step ``rec`` with a robot standing at ``pose``; the actions returned."""
    out = []
    for k in range(int(round(seconds / DT))):
        out.append(rec.step(t0 + k * DT, pose, command, blocked, scan))
    return out


def drive_in(rec: Recovery, metres: float = 1.0) -> tuple[float, np.ndarray]:
    """The robot drives ``metres`` along +x at 0.3 m/s (progress); returns time and pose."""
    t, x = 0.0, 0.0
    while x < metres:
        assert rec.step(t, np.array([x, 0.0, 0.0]), GO, False, EMPTY) is None
        t, x = t + DT, x + 0.3 * DT
    return t, np.array([x, 0.0, 0.0])


def kinds(rec: Recovery) -> list[str]:
    return [k for _, k, _ in rec.events]


def test_a_robot_that_never_moves_walks_through_wait_backup_replan_give_up():
    rec = recovery(max_attempts=3)
    t, pose = drive_in(rec)  # it came from behind: the trail vouches for the blind part
    acts = run(rec, t, pose, 80.0)
    got = [a for a in acts if a is not None]
    seen = []
    for a in got:
        if not seen or seen[-1] != a.kind:
            seen.append(a.kind)
    assert seen == ["wait", "backup", "replan", "give_up"]
    assert kinds(rec) == [
        "stuck", "wait", "stuck", "backup", "backup_aborted", "stuck", "replan", "stuck",
        "give_up",
    ]  # fmt: skip
    waits = [a for a in got if a.kind == "wait"]
    backs = [a for a in got if a.kind == "backup"]
    assert all(np.all(a.command == 0.0) for a in waits)
    assert len(waits) == pytest.approx(rec.params.wait_s / DT, abs=1)
    assert all(a.command[0] == -rec.params.backup_mps and a.command[1] == 0.0 for a in backs)
    assert [a.command for a in got if a.kind == "replan"] == [None]
    assert rec.gave_up and rec.recoveries == 3
    # stuck first after the progress window, give-up is sticky and a zero command
    t_stuck = rec.events[0][0]
    # (the progress window restarted at most 0.2 m, i.e. 0.67 s, before it stopped)
    assert rec.params.movement_time_s - 1.0 < t_stuck - t <= rec.params.movement_time_s
    assert got[-1].kind == "give_up" and np.all(got[-1].command == 0.0)
    assert rec.stuck_s > 40.0


def test_a_backup_that_moves_the_robot_ends_after_the_distance_and_is_not_progress():
    rec = recovery()
    t, pose = drive_in(rec)
    run(rec, t, pose, 25.0 - DT)  # stuck, wait 5 s, stuck again: the back-up starts
    t += 25.0 - DT
    x = pose[0]
    a = rec.step(t, np.array([x, 0.0, 0.0]), GO, False, EMPTY)
    assert a is not None and a.kind == "backup"
    while a is not None and a.kind == "backup":  # follow the back-up commands
        t, x = t + DT, x + float(a.command[0]) * DT
        a = rec.step(t, np.array([x, 0.0, 0.0]), GO, False, EMPTY)
    assert pose[0] - x == pytest.approx(rec.params.backup_m, abs=0.01)
    assert "backup_aborted" not in kinds(rec) and rec.attempts == 2
    # driving back into the same spot is no progress: the next stuck runs the replan
    run(rec, t, pose, 11.0)
    assert kinds(rec)[-2:] == ["stuck", "replan"] and rec.attempts == 3


def test_no_backup_into_unseen_space_the_robot_did_not_come_from():
    rec = recovery()
    t, pose = drive_in(rec)
    turned = np.array([pose[0], 0.0, math.pi / 2])  # turned left on the spot since
    run(rec, t, turned, 25.0)
    assert kinds(rec)[-3:] == ["stuck", "backup_skipped", "replan"]
    assert "the robot did not come from there" in rec.events[-2][2]
    # policy "allow" trusts the blind part; "refuse" never backs into it
    allow, refuse = recovery(unknown_behind="allow"), recovery(unknown_behind="refuse")
    for r in (allow, refuse):
        run(r, 0.0, np.zeros(3), 26.0)
    assert kinds(allow)[-2:] == ["stuck", "backup"]
    assert kinds(refuse)[-3:] == ["stuck", "backup_skipped", "replan"]


def test_no_backup_when_the_scan_sees_something_behind():
    rec = recovery(unknown_behind="allow")
    # a wall 0.35 m behind the robot (blind), walls slanting from it into the laser's view
    segs = np.array([[-0.35, -0.6, -0.35, 0.6], [-0.35, 0.1, 0.0, 0.2], [-0.35, -0.1, 0.0, -0.2]])
    r = raycast(np.zeros(3), LASER.angles(), segs, LASER.range_max_m).astype(np.float32)
    behind = Scan(r)
    ok, why = rec.backup_allowed(np.zeros(3), behind)
    assert not ok and "scan returns in the space behind" in why
    assert rec.backup_allowed(np.zeros(3), EMPTY) == (True, "")
    assert rec.backup_allowed(np.zeros(3), None) == (False, "no scan")
    assert rec.blind_behind()  # the URG's 240 degrees do not cover the box behind


def test_progress_resets_the_recoveries():
    rec = recovery()
    t, pose = drive_in(rec)
    run(rec, t, pose, 15.0)  # stuck -> wait
    t += 15.0
    assert rec.attempts == 1 and kinds(rec) == ["stuck", "wait"]
    t2, x = t, pose[0]
    for _ in range(40):  # moves 1.2 m: away from where it was stuck
        assert rec.step(t2, np.array([x, 0.0, 0.0]), GO, False, EMPTY) is None
        t2, x = t2 + DT, x + 0.3 * DT
    assert rec.attempts == 0 and kinds(rec)[-1] == "progress"
    # stuck again: the cycle starts over with a wait
    run(rec, t2, np.array([x, 0.0, 0.0]), 10.5)
    assert kinds(rec)[-2:] == ["stuck", "wait"] and rec.attempts == 1


def test_a_blocked_controller_is_stuck_after_blocked_time():
    rec = recovery()
    acts = run(rec, 0.0, np.zeros(3), 2.5, command=np.zeros(2), blocked=True)
    first = next(k for k, a in enumerate(acts) if a is not None)
    assert first * DT == pytest.approx(rec.params.blocked_time_s, abs=DT)
    assert rec.events[0][1] == "stuck" and "blocked" in rec.events[0][2]


def test_standing_still_on_purpose_is_stuck_only_after_the_idle_time():
    rec = recovery()
    idle = rec.params.idle_time_s
    assert all(a is None for a in run(rec, 0.0, np.zeros(3), idle, command=np.zeros(2)))
    assert rec.events == [] and rec.stuck_s == 0.0
    a = rec.step(idle, np.zeros(3), np.zeros(2), False, EMPTY)
    assert a is not None and a.kind == "wait"
    assert rec.events[0][1] == "stuck" and "zero command" in rec.events[0][2]
    assert rec.stuck_s == pytest.approx(idle)


def test_reset_forgets_the_run_and_bad_params_are_refused():
    rec = recovery(max_attempts=0)
    run(rec, 0.0, np.zeros(3), 11.0)
    assert rec.gave_up
    rec.reset()
    assert not rec.gave_up and rec.attempts == 0
    assert run(rec, 20.0, np.zeros(3), 5.0) == [None] * 50
    with pytest.raises(ValueError, match="unknown_behind"):
        RecoveryParams(unknown_behind="maybe")


def composed(
    segs: np.ndarray, steps: int
) -> tuple[CorridorFollower, CollisionMonitor, Recovery, np.ndarray, float]:
    """follower -> collision monitor -> unicycle, with recovery watching: the composition the
    navigation stack uses (a replan hands the same path again here). Returns the stages, the
    final pose and the smallest true clearance met."""
    grid = grid_of(segs)
    path = np.array([[0.0, 0.0], [8.0, 0.0]])
    ctrl = CorridorFollower(SPEED_MPS, HARD_M, default_half_width_m=0.5)
    ctrl.set_path(path)
    mon = CollisionMonitor(LASER, robot_radius_m=0.2)
    rec = recovery(max_attempts=3)
    pose, t, clearance = np.zeros(3), 0.0, np.inf
    for _ in range(steps):
        if ctrl.done:
            break
        scan = Scan(raycast(pose, LASER.angles(), segs, LASER.range_max_m).astype(np.float32), t)
        cmd = ctrl.command(pose, grid)
        act = rec.step(t, pose, cmd, ctrl.blocked, scan)
        if act is not None and act.kind == "give_up":
            break
        if act is not None and act.kind == "replan":
            ctrl.set_path(path)
        elif act is not None:
            cmd = act.command
        v, w = (float(c) for c in mon.filter(cmd, scan, t))
        pose = pose + np.array([v * math.cos(pose[2]), v * math.sin(pose[2]), w]) * DT
        t += DT
        clearance = min(clearance, seg_distance(pose[:2], segs))
    return ctrl, mon, rec, pose, clearance


def test_the_three_stages_composed_pass_a_box_without_a_recovery():
    # a 1.4 m corridor, a box over 0.3 m of it: the gap beside it is 0.7 m
    ctrl, mon, rec, pose, clearance = composed(corridor(box(3.5, 0.0, 4.0, 0.3), 0.7), 2000)
    assert ctrl.done and rec.events == [] and not rec.gave_up
    assert mon.slowdown_count > 0 and mon.stop_count == 0  # slowed beside it, never stopped
    assert clearance >= HARD_M


def test_the_three_stages_composed_on_a_blocked_corridor_give_up_without_touching():
    segs = corridor(box(3.0, -1.0, 3.5, 1.0))
    ctrl, mon, rec, pose, clearance = composed(segs, 2000)
    assert rec.gave_up and "backup" in kinds(rec) and "replan" in kinds(rec), rec.events
    assert not ctrl.done and pose[0] < 3.0 - HARD_M and clearance >= HARD_M
