"""The seen-before truth of H&W's point classes (§4.4): an object is semi-static until the
robot has seen it at its current place in an earlier run; people are dynamic, walls static."""

import numpy as np

from dynmap_sim.metrics import (
    PointClassTally,
    SeenPlaces,
    class_scores,
    object_places,
    point_confusion,
    seen_before_point_classes,
)
from dynmap_sim.types import BeamClass

W, F, P, N = BeamClass.WALL, BeamClass.FURNITURE, BeamClass.PERSON, BeamClass.NONE
IDS = ("wall", "box", "chair", "person")


def places_with_box_at(x: float) -> list[np.ndarray]:
    """Objects 0..3: a wall, a box (one segment) at ``x``, a chair (a circle), a person."""
    segs = np.array([[0.0, 0.0, 5.0, 0.0], [x, 1.0, x + 0.5, 1.0]])
    circles = np.array([[3.0, 2.0, 0.2], [4.0, 3.0, 0.1]])
    return object_places(4, segs, [0, 1], circles, [2, 3])


def run(seen: SeenPlaces, places, beam_class, beam_object, hit):
    """One 'run': the truth of one scan against earlier runs, then remember what was hit."""
    mask = seen.seen_before(IDS, places)
    truth = seen_before_point_classes(beam_class, beam_object, mask)
    seen.remember(IDS, places, hit)
    return truth.tolist()


def test_moved_object_is_semistatic_on_its_first_sighting_at_the_new_place_then_static():
    seen = SeenPlaces()
    cls = np.array([W, F, F, P, N])
    obj = np.array([0, 1, 2, 3, -1])
    box_and_wall = np.array([True, True, False, False])  # the chair is never hit
    # run 1: nothing seen before: the box and the chair are semi-static
    assert run(seen, places_with_box_at(1.0), cls, obj, box_and_wall) == [3, 2, 2, 1, 0]
    # run 2, box at the same place: seen there in run 1 -> static; the chair was not hit
    assert run(seen, places_with_box_at(1.0), cls, obj, box_and_wall) == [3, 3, 2, 1, 0]
    # run 3, box moved by 0.5 m: semi-static at its first sighting at the new place
    assert run(seen, places_with_box_at(1.5), cls, obj, box_and_wall) == [3, 2, 2, 1, 0]
    # run 4, still there: static; run 5, back at its first place (seen there): static
    assert run(seen, places_with_box_at(1.5), cls, obj, box_and_wall) == [3, 3, 2, 1, 0]
    assert run(seen, places_with_box_at(1.0), cls, obj, box_and_wall) == [3, 3, 2, 1, 0]
    # a nudge within one 50 mm grid cell is no move
    assert run(seen, places_with_box_at(1.03), cls, obj, box_and_wall) == [3, 3, 2, 1, 0]


def test_an_object_not_hit_is_not_remembered_and_shape_changes_count_as_moves():
    seen = SeenPlaces()
    pl = places_with_box_at(1.0)
    seen.remember(IDS, pl, [False, False, True, False])
    assert seen.seen_before(IDS, pl).tolist() == [False, False, True, False]
    other = [*pl[:2], np.array([3.0, 2.0, 0.3]), pl[3]]  # the chair grew: another place
    assert seen.seen_before(IDS, other).tolist() == [False, False, False, False]


def test_tally_shares_of_valid_readings_and_scores_against_the_truth():
    t = PointClassTally()
    ranges = np.array([1.0, 2.0, np.inf, 3.0, np.nan])
    # predicted: dynamic, semi-static, (no reading), static, (no reading)
    t.add([1, 2, 0, 3, 0], ranges, truth=[1, 3, 0, 3, 0])
    t.add([1, 1, 0, 3, 0], ranges, truth=[1, 2, 0, 3, 0])
    assert t.n_scans == 2
    np.testing.assert_allclose(t.fractions(), [0, 1 / 2, 1 / 6, 1 / 3])
    sc = class_scores(t.confusion)
    assert sc.precision[0] == 2 / 3 and sc.recall[0] == 1.0  # dynamic
    assert sc.precision[1] == 0.0 and sc.recall[1] == 0.0  # semi-static
    assert np.isnan(PointClassTally().fractions()).all()
    np.testing.assert_array_equal(point_confusion([3, 2], [3, 3])[3], [0, 0, 0, 1])


def test_add_scans_is_add_of_each_row_bit_for_bit():
    """The batched tally (the bench scores held scans at once) has the per-scan sums: the
    confusion counts and the shares added in the same order, scans without valid readings
    and out-of-range classes included."""
    rng = np.random.default_rng(5)
    for with_truth in (True, False):
        one, many = PointClassTally(), PointClassTally()
        pred = rng.integers(-1, 5, (300, 50))
        ranges = rng.uniform(0.1, 5.0, (300, 50)).astype(np.float32)
        ranges[rng.random((300, 50)) < 0.3] = np.inf
        ranges[7] = np.nan  # a scan without a valid reading
        truth = rng.integers(0, 4, (300, 50)).astype(np.int8) if with_truth else None
        for k in range(300):
            one.add(pred[k], ranges[k], None if truth is None else truth[k])
        many.add_scans(pred[:120], ranges[:120], None if truth is None else truth[:120])
        many.add_scans(pred[120:], ranges[120:], None if truth is None else truth[120:])
        assert one.n_scans == many.n_scans == 299
        assert one.fraction_sum.tobytes() == many.fraction_sum.tobytes()
        np.testing.assert_array_equal(one.confusion, many.confusion)
