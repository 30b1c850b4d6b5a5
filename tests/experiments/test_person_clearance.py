"""The episode's per-step person clearance is the metric's (``metrics.clearances``, legs
only), bit for bit, in its lean form."""

from types import SimpleNamespace

import numpy as np

from dynmap_sim.experiments.episode import EpisodeLoop
from dynmap_sim.metrics import clearances
from dynmap_sim.types import BeamClass


def _loop_with(circles: np.ndarray, classes: np.ndarray) -> SimpleNamespace:
    snap = SimpleNamespace(circles=circles, circle_class=classes)
    return SimpleNamespace(u=SimpleNamespace(obstacles=lambda: snap))


def test_person_clearance_is_the_metric_bit_for_bit():
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 40):
        circles = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(0.03, 0.3, n)])
        classes = rng.choice([BeamClass.PERSON, BeamClass.FURNITURE], n).astype(np.int8)
        classes[0] = BeamClass.PERSON
        legs = circles[classes == BeamClass.PERSON]
        for _ in range(20):
            pose = np.array([*rng.uniform(-6, 6, 2), rng.uniform(-np.pi, np.pi)])
            got = EpisodeLoop._person_clearance_m(_loop_with(circles, classes), pose, 0.19)
            want = clearances(pose[:2], 0.19, np.zeros((0, 4)), legs)[0]
            assert got == want  # exact


def test_person_clearance_without_people_is_infinite():
    loop = _loop_with(np.zeros((2, 3)), np.full(2, BeamClass.FURNITURE, dtype=np.int8))
    assert EpisodeLoop._person_clearance_m(loop, np.zeros(3), 0.2) == np.inf
    assert clearances(np.zeros(2), 0.2, np.zeros((0, 4)), np.zeros((0, 3)))[0] == np.inf
