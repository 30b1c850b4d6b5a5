"""The headline table ``run`` and ``replay`` print (the numbers: tests/test_cli.py)."""

import pytest

from dynmap_sim.analysis.headline import text_table


@pytest.mark.parametrize(
    "rows,lines",
    [
        ([("a",)], ["a"]),
        (
            [("localizer", "ATE [m]"), ("mcl", "0.123"), ("dynamic-map-long", "12.000")],
            ["localizer         ATE [m]", "mcl                 0.123", "dynamic-map-long   12.000"],
        ),
        ([("x", "y", "z"), ("long", "1", "22")], ["x     y   z", "long  1  22"]),
    ],
)
def test_the_first_column_is_left_aligned_and_the_others_right(rows, lines):
    assert text_table(rows) == lines
