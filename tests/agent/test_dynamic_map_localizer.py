"""The ``dynamic-map`` localizer and its static variants (B&D §4.3–4.4, §5.3) on synthetic scans."""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest
from synthetic_scans import LASER, box, drifting_stream, polyline_path

from dynmap_sim import se2
from dynmap_sim.agent.localization.dynamic_map_localizer import (
    DynamicMapConfig,
    DynamicMapLocalizer,
    lambda_min,
    odometry_covariance,
    remap_degenerate,
)
from dynmap_sim.agent.localization.localizer import LOCALIZERS, make_localizer
from dynmap_sim.agent.localization.odometry_calibration import odometry_error_rates
from dynmap_sim.types import Odometry, Prior


def _world(cupboard: bool) -> np.ndarray:
    """An L-shaped 8 m x 6 m room with a pillar (and, on later days, a cupboard)."""
    pts = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    segs = [walls, box(2.0, 2.0, 2.4, 2.4), box(6.5, 0.0, 7.3, 0.6)]
    if cupboard:
        segs.append(box(1.5, 4.3, 3.5, 4.8))
    return np.concatenate(segs)


def _path() -> np.ndarray:
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [6.5, 1.5], [4.2, 1.2], [4.0, 3.8], [1.0, 3.6]])
    return polyline_path(corners, step_m=0.12, turn_step_rad=0.15)


def _stream(truth, segs, rng, person: bool = False):
    """(odometry, scan) pairs: drifting odometry and noisy scans (optionally a walking person)."""

    def walker(k):
        px = 1.0 + 3.0 * (k / len(truth))
        return box(px, 2.8, px + 0.3, 3.1)

    return drifting_stream(truth, segs, LASER, rng, walker if person else None)


def _run(loc, truth, segs, rng, day, run, first=False, person=False):
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=day, run=run, first_run=first))
    ests = [loc.update(o, s) for o, s in _stream(truth, segs, rng, person)]
    loc.end_run()
    err = np.array([np.hypot(*(e.mean[:2] - t[:2])) for e, t in zip(ests, truth, strict=True)])
    return ests, err


@pytest.fixture(scope="module")
def learned():
    """dynamic-map and static-map after day 1 (3 runs) in the static world."""
    rng = np.random.default_rng(0)
    truth = _path()
    locs = {
        name: make_localizer(name, laser=LASER, rng=np.random.default_rng(1))
        for name in ("dynamic-map", "static-map", "static-map+stm")
    }
    errs = {}
    for name, loc in locs.items():
        for run in (1, 2, 3):
            _, errs[name, run] = _run(loc, truth, _world(False), rng, 1, run, first=(run == 1))
        loc.end_day()
    return locs, errs, truth


def test_registered():
    assert {"dynamic-map", "static-map", "static-map+stm"} <= set(LOCALIZERS.names())


def test_first_run_builds_initial_local_maps_and_later_runs_localize(learned):
    locs, errs, _ = learned
    dyn = locs["dynamic-map"]
    assert 3 <= len(dyn.dmap) <= 30
    centres = dyn.dmap.centres
    d = np.hypot(*(centres[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    assert d[np.triu_indices(len(centres), 1)].min() >= 2.0 - 1e-9  # spacing of the selection
    for name in locs:
        assert errs[name, 1].max() < 0.15  # first-run SLAM
        for run in (2, 3):
            assert np.mean(errs[name, run]) < 0.05, (name, run)
            assert errs[name, run].max() < 0.15, (name, run)


def test_extras_per_scan(learned):
    locs, _, truth = learned
    loc = locs["dynamic-map"]
    rng = np.random.default_rng(5)
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    ests = [loc.update(o, s) for o, s in _stream(truth[:40], _world(False), rng)]
    loc.end_run()
    for e in ests[1:]:
        x = e.extras
        assert np.isfinite(x["scan_loglik"]) and 0 < x["scan_lik"]
        assert x["lambda_min"] > 0
        assert x["lambda_min"] == pytest.approx(lambda_min(e.cov))
        assert x["timescale"] in range(5)
        assert set(x["timescales"]) <= set(range(5))
        assert isinstance(x["safe_mode"], bool)
    assert np.mean([e.extras["safe_mode"] for e in ests]) < 0.1


def test_dynamic_map_adapts_to_a_change_and_static_map_stays_frozen(learned):
    locs = {k: pickle.loads(pickle.dumps(v)) for k, v in learned[0].items()}  # picklable
    truth = learned[2]
    rng = np.random.default_rng(7)
    snap = {k: [s.samples_mm.copy() for s in v.dmap.local_maps[0].sub] for k, v in locs.items()}
    assert locs["static-map"].frozen and locs["static-map+stm"].frozen
    assert not locs["dynamic-map"].frozen
    res = {}
    for name, loc in locs.items():
        lik = []
        for day, run in ((2, 1), (2, 2), (3, 1)):
            ests, err = _run(loc, truth, _world(True), rng, day, run, person=True)
            assert np.mean(err) < 0.08, (name, day, run)
            lik.append(np.mean([e.extras["scan_loglik"] for e in ests[1:]]))
            if run == 2:
                loc.end_day()
        res[name] = lik
    lm = {k: v.dmap.local_maps[0].sub for k, v in locs.items()}
    for level in range(1, 5):  # the snapshot's long-term memory is frozen
        assert np.array_equal(lm["static-map"][level].samples_mm, snap["static-map"][level])
        assert np.array_equal(lm["static-map+stm"][level].samples_mm, snap["static-map+stm"][level])
    assert not np.array_equal(lm["dynamic-map"][4].samples_mm, snap["dynamic-map"][4])
    assert not np.array_equal(lm["static-map+stm"][0].samples_mm, snap["static-map+stm"][0])
    assert np.array_equal(lm["static-map"][0].samples_mm, snap["static-map"][0])
    # B&D Fig. 10: after the change the dynamic map explains the scans better than the snapshot
    assert res["dynamic-map"][-1] > res["static-map"][-1]
    # the map's own history: a λ2-λ5 snapshot after each learning day (day 1 and day 2);
    # the frozen variants only have the one of the day they froze on
    days = [d for d, _ in locs["dynamic-map"].day_snapshots]
    assert days == [1, 2]
    assert [d for d, _ in locs["static-map"].day_snapshots] == [1]
    first, second = (s for _, s in locs["dynamic-map"].day_snapshots)
    assert len(second.centres) >= len(first.centres)
    assert any(
        not np.array_equal(a[: len(b)], b)
        for a, b in zip(second.medians_mm, first.medians_mm, strict=True)
    )  # the changed world entered the long-term memory


def test_bad_mode_is_rejected():
    with pytest.raises(ValueError, match="mode"):
        DynamicMapLocalizer(LASER, np.random.default_rng(0), mode="frozen")


def test_params_build_the_config_and_unknown_ones_are_named():
    """A scenario's flat ``params`` become a DynamicMapConfig (typed like its defaults)."""
    loc = make_localizer("static-map", laser=LASER, rng=np.random.default_rng(0), kappa0=1)
    assert loc.config == replace(DynamicMapConfig(), kappa0=1.0)
    assert isinstance(loc.config.kappa0, float) and loc.mode == "static"
    with pytest.raises(TypeError, match=r"unknown parameters \['kapa0'\]"):
        make_localizer("dynamic-map", laser=LASER, rng=np.random.default_rng(0), kapa0=1.0)
    base = DynamicMapConfig(min_update_dist_m=0.1)
    loc = DynamicMapLocalizer(LASER, np.random.default_rng(0), config=base, kappa0=0.5)
    assert (loc.config.min_update_dist_m, loc.config.kappa0) == (0.1, 0.5)


def test_min_update_motion_skips_scans_with_odometry_prediction(learned):
    loc = pickle.loads(pickle.dumps(learned[0]["dynamic-map"]))
    loc.config = replace(loc.config, min_update_dist_m=0.3, min_update_angle_rad=0.3)
    truth = learned[2]
    rng = np.random.default_rng(9)
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    ests = [loc.update(o, s) for o, s in _stream(truth, _world(False), rng)]
    loc.end_run()
    skipped = np.array([e.extras.get("skipped", False) for e in ests])
    assert 0.3 < skipped.mean() < 0.95
    err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
    assert err.mean() < 0.05
    assert all("timescale" not in e.extras for e in np.array(ests)[skipped])


def test_a_standing_robot_learns_its_scan_once(learned):
    """``learn_min_dist_m``: while the odometry stands still (the robot waits behind a
    person), λ1 learns no scan and none is stored for λ2; with both thresholds 0 every scan
    is, as in the paper."""
    truth = learned[2]
    stand = 40
    truth = np.concatenate([truth[:30], np.repeat(truth[30:31], stand, axis=0), truth[31:]])
    stream = _stream(truth, _world(False), np.random.default_rng(4))
    still = stream[30][0]
    stream[30 : 30 + stand] = [
        (Odometry(still.pose, o.stamp_s), s) for o, s in stream[30 : 30 + stand]
    ]
    stored = {}
    for rule in ((0.01, 0.01), (0.0, 0.0)):
        loc = pickle.loads(pickle.dumps(learned[0]["dynamic-map"]))
        loc.config = replace(loc.config, learn_min_dist_m=rule[0], learn_min_angle_rad=rule[1])
        loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
        ests = [loc.update(o, s) for o, s in stream]
        stored[rule] = len(loc._run_poses)
        err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
        assert err.max() < 0.1
    assert stored[0.0, 0.0] == len(truth)
    # the standing scans after the first, and at most one short step at a corner
    assert len(truth) - stand <= stored[0.01, 0.01] <= len(truth) - (stand - 1)


def test_long_term_maps_fill_by_u_n_per_step(learned):
    """§3.1 filling, §5.4: after one day (one step of λ3–λ5) a λ5 ray holds its seed (the
    keyframe scan that made the local map, §4.4: a few samples) plus u·n = 5, λ4 seed + 20;
    λ2 after 3 runs of u·n = 8 is full (10)."""
    dmap = learned[0]["dynamic-map"].dmap
    l5 = max(int(lm.sub[4].count.max()) for lm in dmap.local_maps)
    l4 = max(int(lm.sub[3].count.max()) for lm in dmap.local_maps)
    assert 5 < l5 <= 5 + 3
    assert 20 < l4 <= 20 + 3
    assert max(int(np.sum(lm.sub[1].count == 10)) for lm in dmap.local_maps) > 50


def test_long_term_anchor_overrides_a_short_term_slide_only(learned):
    """``ltm_anchor_tol_m``: the match against λ2–λ5 alone replaces the pose when the two
    lie further apart than the tolerance, and never otherwise; in the learned room it keeps
    the accuracy and is rarely needed."""
    loc = pickle.loads(pickle.dumps(learned[0]["dynamic-map"]))
    loc.config = replace(loc.config, ltm_anchor_tol_m=0.05)
    truth = learned[2]
    rng = np.random.default_rng(11)
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    stream = list(_stream(truth, _world(False), rng))
    ests = [loc.update(o, s) for o, s in stream[:30]]
    # the long-term current map is now synthesized at the estimate of scan 29
    o, s = stream[30]
    pts = se2.scan_to_points(np.asarray(s.ranges_m, float), LASER.angles())
    pred = truth[30].copy()
    c_o = np.diag([0.02**2, 0.02**2, 0.01**2])
    slid = pred + [0.3, 0.0, 0.0]  # where a sliding short-term match would have put it
    pose, cov = loc._anchor(pts, pred, c_o, slid)
    assert np.hypot(*(pose[:2] - truth[30][:2])) < 0.05
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert loc._anchor(pts, pred, c_o, pose + [0.01, 0.0, 0.0]) is None  # within tolerance
    ests += [loc.update(o, s) for o, s in stream[30:]]
    loc.end_run()
    err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
    assert err.mean() < 0.05
    anchored = np.mean([e.extras.get("anchored", False) for e in ests])
    assert anchored < 0.2
    # off by default: the paper has no anchor
    assert DynamicMapConfig().ltm_anchor_tol_m == 0


def test_odometry_covariance_grows_with_the_motion_from_a_small_floor():
    """``C_O`` (eq. 9): std ``sigma0 + k (d + a/2)`` in x, y and ``sigma0 + k (a + d/2)`` in
    theta; at rest the floors. With the defaults, eq. 9's two-sigma gate lets one match move a
    3.5 cm step (10 Hz, 0.35 m/s) by 2.6 mm at most, where 1 cm + 10 % allowed 2.7 cm."""
    c = DynamicMapConfig()
    np.testing.assert_allclose(
        odometry_covariance(np.zeros(3), *c.odom_params),
        np.diag([c.odom_sigma_xy0_m**2] * 2 + [c.odom_sigma_th0_rad**2]),
    )
    cov = odometry_covariance(np.array([0.03, 0.0, 0.2]), 0.001, 0.02, 0.01, 0.1)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), [0.0036, 0.0036, 0.0315])
    step = np.array([0.035, 0.0, 0.0])
    assert 2 * np.sqrt(odometry_covariance(step, *c.odom_params)[0, 0]) == pytest.approx(0.00256)
    assert 2 * np.sqrt(odometry_covariance(step, 0.01, 0.1, 0.01, 0.1)[0, 0]) == pytest.approx(
        0.027
    )


def test_odometry_covariance_is_acquired_from_a_given_maps_run():
    """``odom_calibration`` (B&D §4.3: ``C_O`` "acquired experimentally"): a map given with
    the poses (NaN: unknown) and odometry of its run sets ``C_O``'s rates to the odometry's
    error rates against those poses; a map without them, a first run mapped by the
    localizer's own SLAM, or the option off leave the configured rates."""
    truth = _path()
    stream = _stream(truth, _world(False), np.random.default_rng(3))
    odo = np.array([o.pose for o, _ in stream])
    ranges = [s.ranges_m for _, s in stream]
    ref = truth.copy()
    ref[::7] = np.nan
    c = DynamicMapConfig()
    assert c.odom_calibration

    def localizer(**params):
        return make_localizer("dynamic-map", laser=LASER, rng=np.random.default_rng(1), **params)

    loc = localizer()
    loc.set_map_from_scans(truth[::10], ranges[::10], ref, odo)
    rates = loc.odom_rates
    assert rates == odometry_error_rates(
        odo, ref, c.odom_calibration_window, c.odom_calibration_quantile
    )
    # the stream's odometry: 2 % long, 3 % heading scale plus 3 % of the distance
    assert 0.01 < rates.k_xy < 0.1 and 0.02 < rates.k_th < 0.3
    assert loc._odom_params() == (c.odom_sigma_xy0_m, rates.k_xy, c.odom_sigma_th0_rad, rates.k_th)
    with pytest.raises(ValueError, match="run_poses and run_odometry together"):
        loc.set_map_from_scans(truth[::10], ranges[::10], truth)
    off = localizer(odom_calibration=False)
    off.set_map_from_scans(truth[::10], ranges[::10], ref, odo)
    bare = localizer()
    bare.set_map_from_scans(truth[::10], ranges[::10])
    own = localizer()
    own.begin_run(Prior(initial_pose=truth[0].copy(), day=1, run=1, first_run=True))
    for o, s in stream[:30]:
        own.update(o, s)
    own.end_run()
    for other in (off, bare, own):
        assert other.odom_rates is None and other._odom_params() == c.odom_params


def _before_scan_30(learned):
    """A copy of the learned ``dynamic-map`` after 30 scans of a day-2 run: the localizer,
    the path, scan 30's points (robot frame) and the current map it is matched against."""
    loc = pickle.loads(pickle.dumps(learned[0]["dynamic-map"]))
    truth = learned[2]
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    stream = list(_stream(truth, _world(False), np.random.default_rng(11)))
    for o, s in stream[:30]:
        loc.update(o, s)
    pts = se2.scan_to_points(np.asarray(stream[30][1].ranges_m, float), LASER.angles())
    target = loc._current_point_map()
    return loc, truth, pts, target


def test_kappa_first_fuses_the_odometry_prior_from_the_first_match(learned):
    """``kappa_first`` (not B&D, whose §4.3 scheme starts at κ = 0 and is the default): the
    first match already minimises ``E_S + κ E_O``, so a prediction inside the two-sigma
    region pulls the result towards it, where B&D's scheme returns the scan's own match."""
    assert DynamicMapConfig().kappa_first == 0
    loc, truth, pts, target = _before_scan_30(learned)
    c_o = np.diag([0.02**2, 0.02**2, 0.01**2])
    pred = truth[30] + [0.027, 0.013, 0.0]  # Mahalanobis 1.5: inside two sigma
    alone, _, kappa_alone, _, _ = loc._match(pts, pred, c_o, target)
    loc.config = replace(loc.config, kappa_first=1.0)
    fused, _, kappa_fused, _, _ = loc._match(pts, pred, c_o, target)
    assert (kappa_alone, kappa_fused) == (0.0, 1.0)
    assert np.hypot(*(alone[:2] - truth[30][:2])) < 0.01
    pull = fused[:2] - alone[:2]
    assert np.hypot(*pull) > 1e-4 and pull @ (pred[:2] - alone[:2]) > 0


def test_a_heading_slip_beyond_c_o_takes_the_scans_heading_never_its_position(learned):
    """``slip_fit_ratio`` (not B&D; on by default): odometry whose heading slipped far beyond
    ``C_O`` (a wheel on a door sill) makes eq. 9 force the match to a pose that fits the map
    visibly worse than the scan alone; the scan's heading is then taken (B&D's scheme, the
    option at 0, keeps the slipped heading). A prediction off in position only (a match
    sliding along a corridor) gains nothing: the position stays bound to the odometry."""
    assert DynamicMapConfig().slip_fit_ratio == 1.25
    loc, truth, pts, target = _before_scan_30(learned)
    c_o = np.diag([0.01**2, 0.01**2, 0.005**2])
    slipped = truth[30] + [0.0, 0.0, 0.08]  # 16 sigma in heading
    pose, _, _, _, slip = loc._match(pts, slipped, c_o, target)
    assert slip
    assert abs(se2.wrap_angle(pose[2] - truth[30][2])) < 0.01
    assert np.hypot(*(pose[:2] - truth[30][:2])) < 0.02
    slid = truth[30] + [0.1, 0.0, 0.0]  # 10 sigma in x
    pose_slid, _, _, _, _ = loc._match(pts, slid, c_o, target)
    assert np.hypot(*(pose_slid[:2] - slid[:2])) < 2.5 * 0.01
    loc.config = replace(loc.config, slip_fit_ratio=0.0)  # B&D's scheme
    pose_bd, _, kappa, _, slip_bd = loc._match(pts, slipped, c_o, target)
    assert not slip_bd and kappa > 0
    assert abs(se2.wrap_angle(pose_bd[2] - truth[30][2])) > 0.05


def test_remap_degenerate_keeps_the_prediction_only_where_the_scan_is_blind():
    """``degenerate_sigma_m`` (not B&D; off by default): along a corridor (x) the scan term
    pins y and the heading but not x, so the match's move in x is dropped, y and θ kept."""
    assert DynamicMapConfig().degenerate_sigma_m == 0
    pred = np.array([5.0, 1.0, 0.1])
    pose = np.array([5.3, 1.02, 0.12])
    corridor = np.diag([1.0, 1e5, 1e4])  # sigma_x 1 m, sigma_y 3 mm
    out = remap_degenerate(pose, pred, corridor, sigma_max_m=0.05)
    np.testing.assert_allclose(out, [5.0, 1.02, 0.12], atol=1e-12)
    # rotated by 30°: the blind direction is the corridor's, not an axis
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = remap_degenerate(pose, pred, rot @ corridor @ rot.T, sigma_max_m=0.05)
    along = np.array([c, s])
    assert abs(along @ (out[:2] - pred[:2])) < 1e-12
    across = np.array([-s, c])
    assert across @ (out[:2] - pred[:2]) == pytest.approx(across @ (pose[:2] - pred[:2]))
    # a room: both directions pinned, nothing changes
    room = np.diag([1e5, 1e5, 1e4])
    np.testing.assert_array_equal(remap_degenerate(pose, pred, room, 0.05), pose)
