"""``adaptive-memory`` (H&W 2011 §3-4, §6.1): stores, tracker, long-term grids, semistatic
test and the localizer, on closed-form and synthetic scans, and a short apartment run."""

from __future__ import annotations

import dataclasses
import pickle
import textwrap

import numpy as np
import pytest
from synthetic_scans import LASER, box, drifting_stream, polyline_path, raycast, room_segments

from dynmap_sim.agent.grid import OCCUPIED
from dynmap_sim.agent.localization.adaptive_memory.localizer import (
    AdaptiveMemoryConfig,
    AdaptiveMemoryLocalizer,
    StaticPointFilter,
)
from dynmap_sim.agent.localization.adaptive_memory.ltm_map import (
    LTMMap,
    LTMParams,
    point_covariances,
)
from dynmap_sim.agent.localization.adaptive_memory.memory_stores import (
    LTMStore,
    SlotBuffer,
    slot_index,
)
from dynmap_sim.agent.localization.adaptive_memory.object_tracker import (
    DYNAMIC,
    STATIC,
    ObjectTracker,
    TrackerParams,
    point_classes_of,
    segment_scan,
)
from dynmap_sim.agent.localization.localizer import LOCALIZERS, make_localizer
from dynmap_sim.agent.localization.particle_filter import (
    AMCLFilter,
    information_lambda_min,
    regularized_covariance,
)
from dynmap_sim.types import Prior

WALLS = np.concatenate(
    [
        np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float),
        np.roll(np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float), -1, axis=0),
    ],
    axis=1,
)
MOUNT = np.zeros(3)


# ---------------------------------------------------------------- stores (§3, eq. 1)
def test_slot_index_is_eq_1():
    # LTM: 10 slots of 8640 s from midnight; 10:00 is slot floor(36000 / 8640) = 4, every day.
    assert slot_index(36000.0, 0.0, 8640.0, 10) == 4
    assert slot_index(86400.0 + 36000.0, 0.0, 8640.0, 10) == 4
    assert slot_index(8639.9, 0.0, 8640.0, 10) == 0 and slot_index(8640.0, 0.0, 8640.0, 10) == 1
    # STM: 100 slots of 0.1 s wrap after 10 s; times before t_s wrap backwards.
    assert slot_index(10.05, 0.0, 0.1, 100) == 0 and slot_index(-0.05, 0.0, 0.1, 100) == 99
    buf = SlotBuffer(0.1, 10)
    for k in range(15):
        buf.put(0.1 * k + 0.01, k)
    assert buf.latest() == 14 and buf.items() == list(range(5, 15))


def test_a_new_ltm_slot_starts_from_its_named_choice():
    made = []

    class Grid:
        def __init__(self, v):
            self.v = v

        def copy(self):
            return Grid(self.v)

    def new():
        made.append(1)
        return Grid(0)

    store = LTMStore(8640.0, 10, "copy_latest", new)
    assert store.activate(36000.0) == 4
    store.map().v = 7  # learned on day 1
    store.activate(36000.0 + 8640.0)  # next slot: a copy of the latest map
    assert store.current == 5 and store.map().v == 7 and store.map() is not store.map(4)
    literal = LTMStore(8640.0, 10, "prior_only", new)
    literal.activate(36000.0)
    literal.map().v = 7
    literal.activate(36000.0 + 86400.0)  # the same slot a day later is current already
    literal.activate(36000.0 + 8640.0)
    assert literal.map().v == 0
    with pytest.raises(ValueError, match="slot_init"):
        LTMStore(8640.0, 10, "bogus", new)


# ---------------------------------------------------------------- tracker (§4.2)
def _points_scan(pose, segs):
    return raycast(pose, LASER.angles(), segs, LASER.range_max_m)


def test_a_moving_box_is_dynamic_and_a_still_one_static():
    params = TrackerParams()
    tr = ObjectTracker(params)
    robot = np.array([1.0, 1.0, 0.0])
    walls = room_segments(cupboard=False)
    for k in range(12):
        person = box(3.0, 0.8 + 0.1 * k, 3.3, 1.1 + 0.1 * k)  # 1 m/s across the beam fan
        still = box(2.0, 4.0, 2.3, 4.3)
        segs = np.concatenate([walls, person, still])
        r = _points_scan(robot, segs)
        boxes = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, params)
        cls, speed = tr.update(boxes, np.array([5.0, -2.0, 0.3]), 0.1 * k)  # any odom origin
        pc = point_classes_of(boxes, cls)
    # beams that hit the person / the still box on the last scan
    hx = robot[0] + r * np.cos(LASER.angles())
    hy = robot[1] + r * np.sin(LASER.angles())
    on_person = (hx > 2.95) & (hx < 3.35) & (hy > 1.85) & (hy < 2.25)
    on_still = (hx > 1.95) & (hx < 2.35) & (hy > 3.95) & (hy < 4.35)
    assert on_person.sum() >= 3 and on_still.sum() >= 3
    assert np.all(pc[on_person] == DYNAMIC)
    assert np.all(pc[on_still] == STATIC)


def _walking_person_dynamic_share(params: TrackerParams, speed_mps: float) -> float:
    """The mean share of a walking person's beams called dynamic over scans 10-39: two legs
    (0.1 m squares, 0.2 m apart) whose centres swing 0.12 m fore and aft against each other
    over a 1.2 m stride while the body walks at ``speed_mps`` across the robot's view."""
    tr = ObjectTracker(params)
    robot = np.array([1.0, 1.0, 0.0])
    walls = room_segments(cupboard=False)
    shares = []
    for k in range(40):
        t = 0.1 * k
        body = np.array([3.5, 0.3 + speed_mps * t])
        swing = 0.12 * np.sin(2.0 * np.pi * speed_mps * t / 1.2)
        legs = [body + [0.1, swing], body + [-0.1, -swing]]
        segs = np.concatenate([walls] + [box(x - 0.05, y - 0.05, x + 0.05, y + 0.05)
                                         for x, y in legs])  # fmt: skip
        r = _points_scan(robot, segs)
        boxes = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, params)
        cls, _ = tr.update(boxes, np.array([5.0, -2.0, 0.3]), t)
        pc = point_classes_of(boxes, cls)
        hx = robot[0] + r * np.cos(LASER.angles())
        hy = robot[1] + r * np.sin(LASER.angles())
        on = np.hypot(hx - body[0], hy - body[1]) < 0.25
        if k >= 10:
            shares.append(np.mean(pc[on] == DYNAMIC))
    return float(np.mean(shares))


@pytest.mark.parametrize("speed_mps", [0.4, 0.6])
def test_a_walking_person_s_two_legs_are_one_dynamic_box(speed_mps):
    """Leg pairing: the legs' box moves with the body, while each leg alone stops at every
    step (below ``v_thres`` at these speeds) and is half the time hidden behind the other."""
    paired = _walking_person_dynamic_share(TrackerParams(leg_pair_m=0.5), speed_mps)
    legs_alone = _walking_person_dynamic_share(TrackerParams(leg_pair_m=0.0), speed_mps)
    assert paired >= 0.85
    assert paired > legs_alone + 0.1


def test_a_long_wall_seen_from_a_moving_robot_is_never_dynamic():
    """The sliding-wall trap: the visible part of a long wall moves with the robot."""
    params = TrackerParams()
    tr = ObjectTracker(params)
    wall = np.array([[0.0, 1.0, 20.0, 1.0]])  # a 20 m wall 1 m to the robot's left
    dyn = 0
    for k in range(40):
        robot = np.array([2.0 + 0.035 * k, 0.0, 0.0])  # 0.35 m/s
        r = _points_scan(robot, wall)
        boxes = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, params)
        cls, _ = tr.update(boxes, robot, 0.1 * k)  # exact odometry
        pc = point_classes_of(boxes, cls)
        dyn += int(np.sum(pc == DYNAMIC))
    assert dyn == 0
    assert np.mean(pc[np.isfinite(r)] == STATIC) > 0.9
    # Without the trap's guards the wall's box slides as fast as the robot and looks dynamic
    naive = TrackerParams(max_dynamic_length_m=1e9, occlusion_never_dynamic=False, v_thres=0.2)
    boxes = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, naive)
    assert boxes.never_dynamic.all()  # cut by the field of view at both ends: still guarded


# ---------------------------------------------------------------- LTM grids (§4.3, §4.4)
def _map(params):
    return LTMMap.from_prior(WALLS, np.array([1.0, 1.0]), 0.05, params)


def test_ltm_update_raises_hit_cells_and_free_space_lowers_the_ray():
    pose = np.array([1.0, 1.025, 0.0])
    ranges = np.array([2.025])  # ends at a cell centre
    for free in (True, False):
        p = LTMParams(free_space=free)
        m = _map(p)
        pts, covs = point_covariances(pose, np.diag([1e-4, 1e-4, 1e-5]), MOUNT, ranges,
                                      np.array([0.0]), 0.001, np.array([0.01]))  # fmt: skip
        np.testing.assert_allclose(pts, [[3.025, 1.025]])
        before = m.logodds.copy()
        m.update(pose[:2], pts, covs, p)
        ix, iy = m.cells(pts)
        assert m.logodds[iy[0], ix[0]] > before[iy[0], ix[0]] + 0.5
        jx, jy = m.cells(np.array([[2.0, 1.025]]))  # halfway along the beam
        if free:
            assert m.logodds[jy[0], jx[0]] == pytest.approx(p.l_free)
        else:
            assert m.logodds[jy[0], jx[0]] == 0.0
        # pinned walls stay at the clamp
        assert np.all(m.logodds[m.pinned] == p.l_max)


def test_points_not_marked_occupied_add_only_free_space():
    p = LTMParams()
    m = _map(p)
    pose = np.array([1.0, 1.025, 0.0])
    pts, covs = point_covariances(pose, np.diag([1e-4, 1e-4, 1e-5]), MOUNT,
                                  np.array([2.025, 2.025]), np.array([0.0, 0.3]), 0.001,
                                  np.array([0.01, 0.01]))  # fmt: skip
    m.update(pose[:2], pts, covs, p, occupied=np.array([False, True]))
    ix, iy = m.cells(pts)
    assert m.logodds[iy[0], ix[0]] <= 0.0 < m.logodds[iy[1], ix[1]]
    jx, jy = m.cells(np.array([[2.0, 1.025]]))  # the first beam still clears its ray
    assert m.logodds[jy[0], jx[0]] == pytest.approx(p.l_free)


def test_point_covariance_is_eq_13_14():
    pose = np.array([0.0, 0.0, 0.0])
    cov_p = np.diag([0.01, 0.04, 0.0])
    _, c = point_covariances(pose, cov_p, MOUNT, np.array([2.0]), np.array([np.pi / 2]),
                             0.0, np.array([0.1]))  # fmt: skip
    # beam along +y: range noise along y, pose x/y noise as is
    np.testing.assert_allclose(c[0], [[0.01, 0.0], [0.0, 0.04 + 0.01]], atol=1e-12)
    _, c = point_covariances(pose, np.diag([0, 0, 0.01]), MOUNT, np.array([2.0]),
                             np.array([0.0]), 0.0, np.array([0.0]))  # fmt: skip
    np.testing.assert_allclose(c[0], [[0.0, 0.0], [0.0, 4 * 0.01]], atol=1e-12)  # lever arm


def test_semistatic_test_flags_a_new_object_not_a_mapped_wall():
    p = LTMParams()
    m = _map(p)
    pts = np.array([[4.0, 0.0], [3.0, 2.0]])  # on the south wall / a new object in the room
    covs = np.broadcast_to(np.eye(2) * 0.02**2, (2, 2, 2)).copy()
    np.testing.assert_array_equal(m.explained(pts, covs, p), [True, False])
    m.update(np.array([1.0, 1.0]), pts[1:], covs[1:], p)
    assert not m.explained(pts, covs, p)[1]  # one stray point is no obstacle (l_occupied)
    for _ in range(8):  # seen again and again, the object enters long-term memory
        m.update(np.array([1.0, 1.0]), pts[1:], covs[1:], p)
    np.testing.assert_array_equal(m.explained(pts, covs, p), [True, True])


# ---------------------------------------------------------------- localizer (§6.1)
def test_registered_and_params_checked():
    assert LOCALIZERS.get("adaptive-memory") is AdaptiveMemoryLocalizer
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="^adaptive-memory: u must be a number in"):
        make_localizer("adaptive-memory", laser=LASER, rng=rng, u=1.5)
    with pytest.raises(ValueError, match="^adaptive-memory: v_thres must be"):
        make_localizer("adaptive-memory", laser=LASER, rng=rng, v_thres=-1)
    with pytest.raises(TypeError, match="unknown parameters \\['bogus'\\]"):
        make_localizer("adaptive-memory", laser=LASER, rng=rng, bogus=1)
    with pytest.raises(ValueError, match="mcl_overrides"):
        AdaptiveMemoryConfig(mcl_overrides={"nope": 1})
    assert AdaptiveMemoryConfig(ltm_slots=10.0).ltm_slots == 10


def _run(loc, truth, segs, rng, day, person=None):
    loc.begin_run(Prior(initial_pose=truth[0].copy(), walls=WALLS, day=day, run=1))
    ests = [loc.update(o, s) for o, s in drifting_stream(truth, segs, LASER, rng, person)]
    loc.end_run()
    loc.end_day()
    err = np.array([np.hypot(*(e.mean[:2] - t[:2])) for e, t in zip(ests, truth, strict=True)])
    return ests, err


def test_tracks_a_synthetic_run_learns_the_furniture_and_reports_its_diagnostics():
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [6.5, 1.5], [4.2, 1.2], [4.0, 3.8], [1.0, 3.6]])
    truth = polyline_path(corners, step_m=0.05, turn_step_rad=0.15)
    segs = room_segments(cupboard=True)
    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1))
    rng = np.random.default_rng(0)
    ests, err1 = _run(loc, truth, segs, rng, day=1)
    assert err1.max() < 0.2 and err1.mean() < 0.08
    semi1 = np.mean([e.extras["n_semistatic"] for e in ests])
    ests, err2 = _run(loc, truth, segs, rng, day=2)
    semi2 = np.mean([e.extras["n_semistatic"] for e in ests])
    assert err2.max() < 0.2
    assert semi2 < 0.5 * semi1  # the furniture is in long-term memory on day 2
    e = ests[-1]
    names = {d.name for d in AdaptiveMemoryLocalizer.diagnostics}
    assert {"n_dynamic", "n_semistatic", "n_static", "ltm_slot", "static_points_used",
            "scan_loglik", "n_tracked_objects"} <= names  # fmt: skip
    assert names <= set(e.extras)
    pc = e.extras["point_classes"]
    assert (
        pc.dtype == np.int8 and pc.shape == (LASER.n_beams,) and set(np.unique(pc)) <= {0, 1, 2, 3}
    )
    n_valid = int(np.sum(np.isfinite(ests[-1].extras["point_classes"]) & (pc > 0)))
    assert e.extras["n_dynamic"] + e.extras["n_semistatic"] + e.extras["n_static"] == n_valid
    assert e.extras["ltm_slot"] == 4 and e.extras["static_points_used"] > 20
    art = loc.day_artifacts()["ltm"]
    assert art["logodds"].ndim == 2 and art["origin_m"].shape == (2,)
    assert float(art["resolution_m"]) == 0.05 and int(art["ltm_slot"]) == 4
    clone = pickle.loads(pickle.dumps(loc))
    assert np.array_equal(clone.ltm.map().logodds, loc.ltm.map().logodds)


def test_eq_1s_clock_runs_from_the_runs_first_scan_whatever_the_stamps_origin():
    """The experiment's stream is stamped in seconds since midnight (10:00 = 36,000 s), a
    replay's in its log's clock: either way a 10:00 run lands in slot 4 (run_clock_s) for
    its whole length, two days fill no second slot, and the estimates are the same as with
    stamps from 0. (Adding the stamps to run_clock_s put each run at 20:00, slot 8, beside a
    slot 4 copied at the run's start: a second map for §6.1's selection every day.)"""
    from dynmap_sim.types import Scan

    truth = polyline_path(np.array([[1.0, 1.0], [4.0, 1.0], [4.0, 3.5]]), 0.05, 0.15)
    segs = room_segments(cupboard=True)
    out = {}
    for origin_s in (0.0, 36000.0):
        loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1))
        stream = drifting_stream(truth, segs, LASER, np.random.default_rng(0))
        ests = []
        for day in (1, 2):
            loc.begin_run(Prior(initial_pose=truth[0].copy(), walls=WALLS, day=day, run=1))
            for o, sc in stream:
                ests.append(loc.update(o, Scan(sc.ranges_m, sc.stamp_s + origin_s)))
                assert loc.ltm.current == 4
            loc.end_run()
            loc.end_day()
        assert loc.ltm.filled() == [4]
        out[origin_s] = np.array([e.mean for e in ests])
    assert np.array_equal(out[0.0], out[36000.0])


def test_points_on_the_prior_walls_do_not_redraw_them():
    """``ltm_learn_prior_walls``: by default a point the walls prior explains adds free
    space only, so the long-term map learns the furniture but no second, shifted or
    thickened copy of the walls (which let the pose drift with the map, issue 11)."""
    from scipy.ndimage import distance_transform_edt

    corners = np.array([[1.0, 1.0], [4.2, 1.0], [6.5, 1.5], [4.2, 1.2], [4.0, 3.8], [1.0, 3.6]])
    truth = polyline_path(corners, step_m=0.05, turn_step_rad=0.15)
    segs = room_segments(cupboard=True)
    near = {}
    for learn in (False, True):
        loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1),
                             ltm_learn_prior_walls=learn)  # fmt: skip
        rng = np.random.default_rng(0)
        _, err = _run(loc, truth, segs, rng, day=1)
        assert err.mean() < 0.08
        m = loc.ltm.map()
        learned = (m.logodds >= LTMParams().l_occupied) & ~m.pinned
        wall_dist = distance_transform_edt(~m.pinned) * m.resolution
        near[learn] = int(np.sum(learned & (wall_dist <= 0.15)))
        if not learn:  # the box, the cupboard and the sofa are learned
            assert learned.sum() > 100
            bx, by = m.cells(np.array([[2.2, 2.0], [6.9, 0.6], [1.4, 4.5]]))
            assert np.all(learned[by, bx] | learned[by - 1, bx] | learned[by + 1, bx])
    assert near[False] <= 10 < 500 < near[True]


def test_runs_on_the_shipped_apartment(tmp_path):
    """A short tour of the shipped apartment through the experiment engine."""
    from dynmap_sim.testing import run_scenario

    scn = tmp_path / "ci-apartment-adaptive.toml"
    scn.write_text(
        textwrap.dedent("""
        name = "ci-apartment-adaptive"
        world = "apartment"
        days = [1, 1]
        seeds = [0]
        [sensor]
        preset = "urg-04lx"
        [driver]
        kind = "tour"
        speed_mps = 0.35
        max_run_s = 12.0
        [prior]
        map = "walls"
        initial_pose = "known"
        [[localizers]]
        name = "adaptive-memory"
        label = "adaptive-memory"
        [expectations.localizers.adaptive-memory]
        mean_error_m = 0.1
        max_error_m = 0.25
        lost_fraction = 0.0
    """)
    )
    run_scenario(scn, out_dir=tmp_path / "out")


def test_a_walking_person_is_dynamic_and_the_room_is_not():
    """The localizer's point classes: a person walking 0.6 m/s across the room is dynamic
    (eqs. 10-11), the walls and furniture seen from the moving robot are not."""
    truth = np.column_stack([np.linspace(1.0, 3.0, 70), np.full(70, 1.0), np.zeros(70)])
    segs = room_segments(cupboard=True)

    def person(k):
        x = 0.6 + 0.06 * k  # in front of the far north wall (y = 6)
        return box(x, 3.5, x + 0.3, 3.8)

    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1))
    loc.begin_run(Prior(initial_pose=truth[0].copy(), walls=WALLS, day=1, run=1))
    stream = drifting_stream(truth, segs, LASER, np.random.default_rng(0), person)
    on_person = on_room = dyn_person = dyn_room = 0
    for k, (o, s) in enumerate(stream):
        pc = loc.update(o, s).extras["point_classes"]
        if k < 10:
            continue  # tracks are confirmed after a few scans
        r0 = raycast(truth[k], LASER.angles(), segs, LASER.range_max_m)
        r1 = raycast(truth[k], LASER.angles(), np.concatenate([segs, person(k)]), 5.6)
        hit_p = r1 < r0 - 0.05
        room = np.isfinite(r0) & ~hit_p
        on_person += hit_p.sum()
        dyn_person += np.sum(pc[hit_p] == 1)
        on_room += room.sum()
        dyn_room += np.sum(pc[room] == 1)
    assert on_person > 100
    assert dyn_person / on_person > 0.7
    assert dyn_room / on_room < 0.005


def test_held_beams_and_the_cached_covariance_change_no_estimate(monkeypatch):
    """The beams picked once a scan (``hold_beams``) and the reported covariance computed once
    per filter estimate give the estimates of picking and computing them at every use."""
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [4.0, 3.8]])
    truth = polyline_path(corners, step_m=0.05, turn_step_rad=0.15)
    segs = room_segments(cupboard=True)
    runs = []
    for cached in (True, False):
        if not cached:
            monkeypatch.setattr(StaticPointFilter, "hold_beams", lambda self, r: None)
            monkeypatch.setattr(
                AdaptiveMemoryLocalizer,
                "_reported_cov",
                lambda self: (rc := regularized_covariance(self._cov), information_lambda_min(rc)),
            )
        loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1))
        runs.append(_run(loc, truth, segs, np.random.default_rng(0), day=1)[0])
    for a, b in zip(*runs, strict=True):
        assert a.mean.tobytes() == b.mean.tobytes() and a.cov.tobytes() == b.cov.tobytes()
        assert a.extras["scan_loglik"] == b.extras["scan_loglik"] or np.isnan(
            a.extras["scan_loglik"]
        )
        assert a.extras["lambda_min"] == b.extras["lambda_min"]
        assert a.extras["static_points_used"] == b.extras["static_points_used"]


def test_the_mcl_grid_is_rebuilt_only_when_the_map_cells_change():
    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(0))
    loc.begin_run(Prior(initial_pose=np.array([1.0, 1.0, 0.0]), walls=WALLS, day=1, run=1))
    f, slot = loc.filter, loc.used_slot
    grid, table = f.grid, f.table
    loc._use_map(slot)  # same cells: the same grid and likelihood field stay
    assert f.grid is grid and f.table is table
    m = loc.ltm.map(slot)
    ix, iy = m.cells(np.array([2.0, 2.0]))  # a new obstacle in the room
    assert m.ternary(loc.lp)[iy, ix] != OCCUPIED
    m.logodds[iy, ix] = loc.lp.l_max
    loc._use_map(slot)
    assert f.grid is not grid
    np.testing.assert_array_equal(f.grid.occupancy, m.ternary(loc.lp))
    fresh = m.occupancy_grid(loc.lp)
    assert f.grid.dist_m.tobytes() == fresh.dist_m.tobytes()
    np.testing.assert_array_equal(f.table.logp, AMCLFilter(fresh, LASER, loc.mcl).table.logp)


def test_the_odometry_increment_is_se2s_bit_for_bit():
    """The single-pose ``compose(a, between(b, c))`` on floats the localizer applies
    (:func:`dynmap_sim.se2.apply_increment`) gives the array code's numbers exactly (angles
    around ±pi, large and tiny ones)."""
    from dynmap_sim import se2

    rng = np.random.default_rng(7)
    for _ in range(20000):
        a, b, c = (np.array([*rng.normal(0, 10, 2), th]) for th in rng.uniform(-4, 4, 3))
        if rng.random() < 0.2:
            b[2], c[2] = np.pi, -np.pi + rng.normal(0, 1e-12)
        ref = se2.compose(a, se2.between(b, c))
        assert se2.apply_increment(a, b, c).tobytes() == ref.tobytes()


def test_a_pickled_localizer_goes_on_the_same_bit_for_bit():
    """Two days with a person walking: the localizer pickled after day 1 gives day 2's
    estimates, extras and long-term grid byte for byte as the one it was copied from; the
    free cells listed lazily are the grid's."""
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [6.5, 1.5], [4.2, 1.2], [4.0, 3.8]])
    truth = polyline_path(corners, step_m=0.05, turn_step_rad=0.15)
    segs = room_segments(cupboard=True)

    def person(k: int) -> np.ndarray:
        x = 0.5 + (0.1 * k) % 4.0
        return box(x, 4.0, x + 0.3, 4.3)

    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1))
    _run(loc, truth, segs, np.random.default_rng(0), day=1, person=person)
    twin = pickle.loads(pickle.dumps(loc))
    runs = [_run(x, truth, segs, np.random.default_rng(5), day=2, person=person)[0]
            for x in (loc, twin)]  # fmt: skip
    assert loc.ltm.map().logodds.tobytes() == twin.ltm.map().logodds.tobytes()
    assert twin.filter.free_xy.tobytes() == twin.filter.grid.free_points().tobytes()
    assert sum(e.extras["n_dynamic"] for e in runs[0]) > 0
    for ea, eb in zip(*runs, strict=True):
        assert ea.mean.tobytes() == eb.mean.tobytes() and ea.cov.tobytes() == eb.cov.tobytes()
        for k in ea.extras:
            assert np.asarray(ea.extras[k]).tobytes() == np.asarray(eb.extras[k]).tobytes(), k


@pytest.mark.parametrize("masked", [False, True])
def test_mcl_uses_the_valid_readings_among_the_masked_beams(masked):
    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(0))
    loc.begin_run(Prior(initial_pose=np.array([1.0, 1.0, 0.0]), walls=WALLS, day=1, run=1))
    f = loc.filter
    f.config = dataclasses.replace(f.config, max_beams=0)  # 0: every masked beam
    rng = np.random.default_rng(3)
    r = rng.uniform(0.0, 7.0, LASER.n_beams)
    r[rng.random(len(r)) < 0.2] = np.nan
    f.point_mask = rng.random(len(r)) < 0.5 if masked else None
    got, ang = f._beams_of(r)
    keep = [i for i in range(len(r)) if np.isfinite(r[i]) and f.range_min <= r[i] < f.range_max
            and r[i] > 0 and (not masked or f.point_mask[i])]  # fmt: skip
    np.testing.assert_array_equal(got, r[keep])
    np.testing.assert_array_equal(ang, LASER.angles()[keep])


@pytest.mark.parametrize("semistatic_map", ["run_start", "current"])
def test_a_new_object_is_semistatic_all_day_against_the_run_start_map(semistatic_map):
    """§4.4 against the long-term memory as the run began (``run_start``): the furniture the
    walls prior lacks stays semistatic through day 1 and is static on day 2; against the
    slot being written (``current``) it leaves the class within the first run."""
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [6.5, 1.5], [4.2, 1.2], [4.0, 3.8], [1.0, 3.6]])
    truth = polyline_path(corners, step_m=0.05, turn_step_rad=0.15)
    segs = room_segments(cupboard=True)
    loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(1),
                         semistatic_map=semistatic_map)  # fmt: skip
    rng = np.random.default_rng(0)
    day1 = np.array([e.extras["n_semistatic"] for e in _run(loc, truth, segs, rng, day=1)[0]])
    day2 = np.array([e.extras["n_semistatic"] for e in _run(loc, truth, segs, rng, day=2)[0]])
    late = day1[len(day1) // 2 :].mean()
    if semistatic_map == "run_start":
        assert late > 20 and day2.mean() < 0.1 * late
    else:
        assert late < 0.2 * day1[:20].mean()
