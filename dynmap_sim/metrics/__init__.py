"""Metrics: pure functions over arrays comparing estimates with ground truth (DESIGN.md §6).

No I/O and no simulator imports; results are small frozen dataclasses with ``to_dict``.
"""

from dynmap_sim.metrics.daily import GroupSummary, summarize, summarize_groups
from dynmap_sim.metrics.lost import LOST_THRESHOLD_M, LostStats, lost_episodes, lost_stats
from dynmap_sim.metrics.point_classes import (
    BEAM_TO_POINT_CLASS,
    POINT_CLASSES,
    ClassScores,
    class_scores,
    confusion_matrix,
)
from dynmap_sim.metrics.pose_error import (
    ErrorStats,
    RPEResult,
    ate,
    error_stats,
    heading_errors,
    position_errors,
    rpe,
)

__all__ = [
    "BEAM_TO_POINT_CLASS",
    "LOST_THRESHOLD_M",
    "POINT_CLASSES",
    "ClassScores",
    "ErrorStats",
    "GroupSummary",
    "LostStats",
    "RPEResult",
    "ate",
    "class_scores",
    "confusion_matrix",
    "error_stats",
    "heading_errors",
    "lost_episodes",
    "lost_stats",
    "position_errors",
    "rpe",
    "summarize",
    "summarize_groups",
]
