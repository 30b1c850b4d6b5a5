"""Laser presets, truth labels, noise statistics and REP-117 encodings."""

from dataclasses import dataclass, field

import numpy as np
import pytest

from dynmap_sim.sensors.lidar import NOISELESS, LidarNoise, make_lidar
from dynmap_sim.types import BeamClass, LaserSpec


@dataclass
class FakeGeometry:
    segments: np.ndarray
    segment_object: np.ndarray
    segment_class: np.ndarray
    circles: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    circle_object: np.ndarray = field(default_factory=lambda: np.empty(0, np.int32))
    circle_class: np.ndarray = field(default_factory=lambda: np.empty(0, np.int8))
    object_ids: tuple = ("wall", "person")
    static_version: int = 0


def wall_ahead(distance_m=3.0, with_person=False):
    segs = np.array([[distance_m, -50.0, distance_m, 50.0]])
    g = FakeGeometry(segs, np.array([0], np.int32), np.array([BeamClass.WALL], np.int8))
    if with_person:
        g.circles = np.array([[1.5, 0.0, 0.1]])
        g.circle_object = np.array([1], np.int32)
        g.circle_class = np.array([BeamClass.PERSON], np.int8)
    return g


def test_presets():
    urg = make_lidar("urg-04lx").spec
    assert isinstance(urg, LaserSpec)
    assert urg.n_beams == 683 and urg.range_min_m == 0.02 and urg.range_max_m == 5.6
    assert urg.angle_increment_rad == pytest.approx(2 * np.pi / 1024)
    assert urg.angle_min_rad == pytest.approx(-2.0862) and urg.scan_period_s == 0.1
    lms = make_lidar("lms200", beams=181).spec
    assert lms.n_beams == 181 and lms.range_max_m == 8.19
    assert lms.angle_max_rad - lms.angle_min_rad == pytest.approx(np.pi)
    assert make_lidar("lms200", mode="cm").spec.range_max_m == 81.9
    assert make_lidar("urg-04lx", range_max_m=4.0).spec.range_max_m == 4.0
    with pytest.raises(ValueError, match="unknown laser scanner"):
        make_lidar("velodyne")
    with pytest.raises(ValueError, match="unknown laser parameter"):
        make_lidar("urg-04lx", beam_count=3)
    with pytest.raises(ValueError, match="probability"):
        LidarNoise(p_dropout=2.0)


def test_wall_at_three_metres_reads_three_metres_within_noise():
    lidar = make_lidar("urg-04lx")
    rng = np.random.default_rng(0)
    g = wall_ahead()
    centre = int(np.argmin(np.abs(lidar.spec.angles())))
    reads = np.array([lidar.scan(np.zeros(3), g, rng).ranges_m[centre] for _ in range(400)])
    true = 3.0 / np.cos(lidar.spec.angles()[centre])
    ok = np.isfinite(reads)
    assert ok.mean() > 0.98
    # sigma = 1 % of 3 m = 3 cm
    assert abs(np.median(reads[ok]) - true) < 0.006
    assert np.std(reads[ok][np.abs(reads[ok] - true) < 0.2]) == pytest.approx(0.03, rel=0.15)


def test_noise_statistics_urg_and_lms():
    rng = np.random.default_rng(1)
    true = np.linspace(0.3, 5.0, 683 * 30).reshape(30, 683)
    urg = make_lidar("urg-04lx", noise={"p_dropout": 0.0, "p_short": 0.0, "p_mixed": 0.0})
    err = urg.apply_noise(true, rng).astype(np.float64) - true
    sigma = np.maximum(0.01, 0.01 * true)
    z = err / sigma
    assert abs(z.mean()) < 0.05 and np.std(z) == pytest.approx(1.0, abs=0.05)
    lms = make_lidar("lms200", noise={"p_dropout": 0.0, "p_short": 0.0, "p_mixed": 0.0})
    n = lms.spec.n_beams
    t = np.full(n, 4.0)
    errs = lms.apply_noise(np.tile(t, (400, 1)), rng) - 4.0
    bias = errs.mean(axis=0)  # a fixed per-beam systematic error within +-15 mm
    assert np.all(np.abs(bias) < 0.015 + 0.002) and np.std(bias) > 0.005
    assert np.std(errs - bias, axis=0).mean() == pytest.approx(0.005, rel=0.1)


def test_dropouts_and_short_returns_rates():
    rng = np.random.default_rng(2)
    noise = LidarNoise(sigma_m=0.0, sigma_rel=0.0, p_dropout=0.05, p_short=0.1, p_mixed=0.0)
    lidar = make_lidar("urg-04lx", noise=noise)
    true = np.full((150, 683), 4.0)
    r = lidar.apply_noise(true, rng)
    assert np.mean(np.isposinf(r)) == pytest.approx(0.05, abs=0.005)
    short = np.isfinite(r) & (r < 3.999)
    assert np.mean(short) == pytest.approx(0.1, abs=0.01)
    assert np.all(r[short] >= lidar.spec.range_min_m)


def test_mixed_pixels_lie_between_surfaces():
    rng = np.random.default_rng(3)
    noise = LidarNoise(sigma_m=0.0, sigma_rel=0.0, p_dropout=0.0, p_short=0.0, p_mixed=1.0)
    lidar = make_lidar("urg-04lx", noise=noise)
    true = np.where(np.arange(683) < 300, 1.0, 3.0)
    r = lidar.apply_noise(true, rng)
    assert 1.0 <= r[299] <= 3.0 and 1.0 <= r[300] <= 3.0
    assert r[299] != 1.0 and r[300] != 3.0
    np.testing.assert_array_equal(r[:299], 1.0)
    np.testing.assert_array_equal(r[301:], 3.0)


def test_rep117_encodings():
    rng = np.random.default_rng(4)
    lidar = make_lidar("urg-04lx", noise=NOISELESS)
    r = lidar.apply_noise(np.r_[0.01, 1.0, np.inf, 5.0, 6.0, np.full(678, 2.0)], rng)
    assert r.dtype == np.float32
    assert np.isneginf(r[0]) and r[1] == 1.0 and np.isposinf(r[2]) and r[3] == 5.0
    assert np.isposinf(r[4])
    # NaN only when asked for; never by default
    assert not np.any(np.isnan(make_lidar().apply_noise(np.full((80, 683), 2.0), rng)))
    bad = make_lidar("urg-04lx", noise={"p_invalid": 0.5, "p_mixed": 0.0}).apply_noise(
        np.full(683, 2.0), rng
    )
    assert 0.4 < np.mean(np.isnan(bad)) < 0.6


def test_truth_labels_and_mount_offset():
    g = wall_ahead(3.0, with_person=True)
    lidar = make_lidar("urg-04lx", noise=NOISELESS, mount_pose=(0.5, 0.0, 0.0))
    reading = lidar.scan(np.zeros(3), g, np.random.default_rng(0))
    centre = int(np.argmin(np.abs(lidar.spec.angles())))
    # the laser sits 0.5 m ahead of base_link: the person at 1.5 m is 0.9 m away (r = 0.1)
    assert reading.true_range_m[centre] == pytest.approx(0.9, abs=1e-9)
    assert reading.beam_class[centre] == BeamClass.PERSON and reading.beam_object[centre] == 1
    assert reading.beam_class[centre + 60] == BeamClass.WALL
    assert reading.beam_object[centre + 60] == 0
    behind = np.abs(lidar.spec.angles()) > np.pi / 2 + 0.2
    assert np.all(reading.beam_class[behind] == BeamClass.NONE)
    assert np.all(reading.beam_object[behind] == -1)
    assert np.all(np.isposinf(reading.ranges_m[behind]))


def test_same_seed_same_scan():
    g = wall_ahead(2.0, with_person=True)
    lidar = make_lidar("lms200")
    a = lidar.scan(np.array([0.1, 0.2, 0.3]), g, np.random.default_rng(9)).ranges_m
    b = lidar.scan(np.array([0.1, 0.2, 0.3]), g, np.random.default_rng(9)).ranges_m
    np.testing.assert_array_equal(a, b)


def test_pickled_lidar_scans_the_same():
    import pickle

    segs = np.array([[3.0, -5.0, 3.0, 5.0], [-2.0, -1.0, -2.0, 1.0]])

    class G:
        segments = segs
        segment_object = np.array([0, 1], np.int32)
        segment_class = np.array([1, 1], np.int8)
        circles = np.array([[0.0, 2.0, 0.1]])
        circle_object = np.array([2], np.int32)
        circle_class = np.array([5], np.int8)
        static_version = 0

    lidar = make_lidar("urg-04lx")
    pose = np.array([0.2, 0.1, 0.3])
    clone = pickle.loads(pickle.dumps(lidar))
    a = lidar.scan(pose, G, np.random.default_rng(3))
    b = clone.scan(pose, G, np.random.default_rng(3))
    np.testing.assert_array_equal(a.ranges_m, b.ranges_m)
    np.testing.assert_array_equal(a.beam_object, b.beam_object)


def test_a_batch_is_noised_scan_after_scan():
    """A batch of scans reads what the scans noised one after another from the same
    generator read."""
    lidar = make_lidar("lms200", noise={"p_invalid": 0.01, "p_short": 0.02})
    rng = np.random.default_rng(4)
    true = rng.uniform(0.5, 7.0, (4, lidar.spec.n_beams))
    true[:, ::7] = np.inf
    batch = lidar.apply_noise(true, np.random.default_rng(10))
    one = np.random.default_rng(10)
    for i in range(4):
        assert np.array_equal(batch[i], lidar.apply_noise(true[i], one), equal_nan=True)


@pytest.mark.parametrize("where", ["make_lidar", "env", "scenario"])
def test_the_old_backend_option_is_refused_in_one_line(where):
    from dynmap_sim.env import DynMapEnv
    from dynmap_sim.env_factory import SimSpec, SimSpecError, make_env, resolve_world

    with pytest.raises(ValueError, match="'backend' is gone") as err:
        if where == "make_lidar":
            make_lidar("urg-04lx", backend="numba")
        elif where == "env":
            DynMapEnv(world="apartment", sensor_options={"backend": "auto"})
        else:
            make_env(SimSpec(world=resolve_world("apartment"), sensor_overrides={"backend": "x"}))
    assert "\n" not in str(err.value)
    if where == "scenario":
        assert isinstance(err.value, SimSpecError) and err.value.field == "sensor"
