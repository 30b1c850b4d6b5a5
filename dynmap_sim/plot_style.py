"""The figures' shared style: one colour per localizer, the same in every figure.

A localizer is drawn in the colour of its position in the results folder's localizer table
(matplotlib's ten-colour cycle ``C0`` … ``C9``), whether or not a figure skips localizers
that have nothing to show, so a reader can follow one localizer across the figures of a
report. Used by the report (``analysis/``) and the studies alike, which is why it lives
outside both.
"""

from __future__ import annotations


def localizer_color(index: int) -> str:
    """The matplotlib colour of the localizer at ``index`` (0-based) of a results folder."""
    if index < 0:
        raise ValueError(f"a localizer index is >= 0, got {index}")
    return f"C{index % 10}"


def legend_columns(labels: list[str], fig_width_in: float, font_pt: float = 8.0) -> int:
    """How many columns a legend of ``labels`` below a figure ``fig_width_in`` inches wide can
    have without running past its edges (an entry is its text, about 0.55 em a character,
    plus 3 em for the handle and the gap), at most 4."""
    if not labels:
        return 1
    em_in = font_pt / 72.0
    entry_in = (0.55 * max(len(s) for s in labels) + 3.0) * em_in
    return max(1, min(len(labels), 4, int(fig_width_in // entry_in)))
