"""Kümmerle et al. 2009's relation error on closed-form cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.metrics.relation_error import (
    RelationError,
    Relations,
    read_relations,
    relation_error,
    relation_errors,
)


def _straight(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n, dtype=float)
    return t, np.column_stack([t, np.zeros(n), np.zeros(n)])


def _relations_of(t: np.ndarray, poses: np.ndarray, pairs: list[tuple[int, int]]) -> Relations:
    d = np.array([se2.between(poses[i], poses[j]) for i, j in pairs])
    return Relations(t[[i for i, _ in pairs]], t[[j for _, j in pairs]], d)


def test_perfect_trajectory_has_zero_error_and_is_frame_free() -> None:
    t, p = _straight()
    rel = _relations_of(t, p, [(0, 1), (1, 3), (0, 5)])
    # A global rigid motion of the estimate changes nothing: only relative poses count.
    moved = np.array([se2.compose([3.0, -2.0, 1.1], q) for q in p])
    r = relation_error(t, moved, rel)
    assert r.n_relations == 3 and r.n_unmatched == 0
    assert r.translation_mean_m == pytest.approx(0.0, abs=1e-12)
    assert r.rotation_mean_deg == pytest.approx(0.0, abs=1e-9)


def test_known_translation_and_rotation_errors() -> None:
    t, p = _straight(3)
    # Reference: 1 m straight ahead each step. Estimate: the 2nd step is 1.1 m, and the
    # robot at t=2 is turned by 10 degrees.
    est = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.1, 0.0, math.radians(10)]])
    rel = _relations_of(t, p, [(0, 1), (1, 2)])
    tr, ro, ok = relation_errors(t, est, rel)
    np.testing.assert_allclose(tr, [0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(np.degrees(ro), [0.0, 10.0], atol=1e-9)
    r = relation_error(t, est, rel)
    assert r.translation_mean_m == pytest.approx(0.05)
    assert r.translation_std_m == pytest.approx(0.05)  # population std of {0, 0.1}
    assert r.rotation_mean_deg == pytest.approx(5.0)
    assert r.rotation_std_deg == pytest.approx(5.0)
    assert r.translation_max_m == pytest.approx(0.1)


def test_error_is_expressed_in_the_frame_of_the_relation() -> None:
    # The estimate at t1 is turned by 90 deg: a correct relative motion (1 m ahead) expressed
    # in a wrong frame is a 1.41 m translation error (ahead vs. sideways) and 90 deg of rotation.
    t = np.array([0.0, 1.0])
    rel = Relations(t[:1], t[1:], np.array([[1.0, 0.0, 0.0]]))
    est = np.array([[0.0, 0.0, math.pi / 2], [1.0, 0.0, 0.0]])
    r = relation_error(t, est, rel)
    assert r.translation_mean_m == pytest.approx(math.sqrt(2))
    assert r.rotation_mean_deg == pytest.approx(90.0)


def test_length_restriction_and_unmatched_stamps() -> None:
    t, p = _straight(6)
    est = p.copy()
    est[5, 0] += 0.5  # only the long relation (0, 5) sees it
    rel = _relations_of(t, p, [(0, 1), (2, 3), (0, 5)])
    short = relation_error(t, est, rel, max_length_m=2.0)
    assert short.n_relations == 2 and short.translation_mean_m == 0.0
    long = relation_error(t, est, rel, min_length_m=2.0)
    assert long.n_relations == 1 and long.translation_mean_m == pytest.approx(0.5)
    missing = Relations(np.array([0.0, 0.5]), np.array([1.0, 2.0]), np.zeros((2, 3)))
    r = relation_error(t, est, missing)
    assert r.n_relations == 1 and r.n_unmatched == 1
    none = relation_error(t, est, Relations(np.zeros(0), np.zeros(0), np.zeros((0, 3))))
    assert none.n_relations == 0 and math.isnan(none.translation_mean_m)


def test_result_round_trips_json_and_file_is_read(tmp_path) -> None:  # noqa: ANN001
    f = tmp_path / "x.relations"
    f.write_text("# comment\n0.0 1.0 1.0 0.0 0.0 0.0 0.0 0.1\n\n1.0 2.0 0.5 0.2 0.3\n")
    rel = read_relations(f)
    np.testing.assert_allclose(rel.delta, [[1.0, 0.0, 0.1], [0.5, 0.2, 0.3]])
    np.testing.assert_allclose(rel.t2, [1.0, 2.0])
    r = relation_error([0.0, 1.0, 2.0], np.zeros((3, 3)), rel)
    assert RelationError.from_json(r.to_json()) == r
    (tmp_path / "bad").write_text("0 1 2 3\n")
    with pytest.raises(ValueError, match="line 1"):
        read_relations(tmp_path / "bad")
