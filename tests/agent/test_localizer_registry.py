"""The Localizer role: registry lookups, user classes by module:Class, dead reckoning."""

import pickle

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.agent.localization.localizer import LOCALIZERS, Localizer, make_localizer
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

LASER = LaserSpec("test", 3, -0.1, 0.1, 0.02, 5.6, 0.1, 0.0)


class ConstantLocalizer(Localizer):
    """A user's own localizer, loaded by 'module:Class' in the tests below."""

    def begin_run(self, prior: Prior) -> None:
        self.prior = prior

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        return PoseEstimate(mean=np.zeros(3), cov=np.eye(3))


def test_odometry_is_registered():
    assert "odometry" in LOCALIZERS.names()


def test_unknown_name_lists_known_ones():
    with pytest.raises(ValueError, match="unknown localizer 'nope'.*odometry"):
        LOCALIZERS.get("nope")


def test_user_class_by_module_path():
    cls = LOCALIZERS.get(f"{__name__}:ConstantLocalizer")
    assert cls is ConstantLocalizer
    with pytest.raises(ValueError, match="cannot load"):
        LOCALIZERS.get(f"{__name__}:Missing")
    with pytest.raises(ValueError, match="not a dynmap_sim"):
        LOCALIZERS.get("numpy:ndarray")


def test_unknown_parameter_is_rejected():
    with pytest.raises(TypeError, match="unknown parameters"):
        make_localizer("odometry", laser=LASER, rng=np.random.default_rng(0), bogus=1)


def test_dead_reckoning_composes_odometry_onto_the_prior():
    loc = make_localizer("odometry", laser=LASER, rng=np.random.default_rng(0))
    start = np.array([2.0, 1.0, np.pi / 2])
    loc.begin_run(Prior(initial_pose=start))
    scan = Scan(np.ones(3, np.float32))
    odom0 = np.array([5.0, 5.0, 0.3])  # odom frame origin is arbitrary
    est0 = loc.update(Odometry(odom0), scan)
    np.testing.assert_allclose(est0.mean, start, atol=1e-12)
    # drive 1 m straight ahead in the robot frame
    odom1 = se2.compose(odom0, [1.0, 0.0, 0.0])
    est1 = loc.update(Odometry(odom1), scan)
    np.testing.assert_allclose(est1.mean, [2.0, 2.0, np.pi / 2], atol=1e-12)
    assert est1.cov[0, 0] > est0.cov[0, 0]
    clone = pickle.loads(pickle.dumps(loc))
    np.testing.assert_allclose(clone.update(Odometry(odom1), scan).mean, est1.mean)


def test_a_name_registered_twice_is_an_error():
    from dynmap_sim.registry import DuplicateNameError

    class Other(ConstantLocalizer):
        pass

    with pytest.raises(DuplicateNameError, match="'odometry' is already taken by .*DeadReckoning"):
        LOCALIZERS.add("odometry", Other)
    assert LOCALIZERS.get("odometry").__name__ != "Other"
