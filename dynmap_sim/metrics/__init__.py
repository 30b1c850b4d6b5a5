"""Metrics: pure functions over arrays comparing estimates with ground truth.

No I/O and no simulator imports. Results are small frozen dataclasses that save to JSON and
load back equal (:class:`~.result.Result`). Every summary the experiments store and report
(per run, per day, overall) is computed in :mod:`.summaries`.
"""

from dynmap_sim.metrics.daily import GroupSummary, summarize, summarize_groups
from dynmap_sim.metrics.intervals import (
    CI_LEVEL,
    MeanInterval,
    mean_interval,
    paired_difference,
    t_quantile,
)
from dynmap_sim.metrics.lost import (
    LOST_THRESHOLD_M,
    LostStats,
    lost_episodes,
    lost_fraction,
    lost_stats,
)
from dynmap_sim.metrics.navigation import (
    NEAR_MISS_M,
    NavDaySummary,
    NavRunSummary,
    clearances,
    goal_reached,
    nav_day_summary,
    nav_run_summary,
    path_length_m,
    spl,
)
from dynmap_sim.metrics.point_classes import (
    BEAM_TO_POINT_CLASS,
    POINT_CLASSES,
    ClassScores,
    class_scores,
    confusion_matrix,
)
from dynmap_sim.metrics.pose_error import (
    RPE_UNITS,
    ErrorStats,
    RPEResult,
    ate,
    error_stats,
    heading_errors,
    position_errors,
    rpe,
    rpe_label,
    rpe_pairs,
)
from dynmap_sim.metrics.result import Result
from dynmap_sim.metrics.summaries import (
    RUN_RPE_DELTA,
    RUN_RPE_UNIT,
    DaySummary,
    OverallSummary,
    RunSummary,
    day_summary,
    mean_per_scan,
    n_onsets,
    overall_summary,
    run_summary,
    scan_errors,
)

__all__ = [
    "CI_LEVEL",
    "MeanInterval",
    "mean_interval",
    "paired_difference",
    "t_quantile",
    "NEAR_MISS_M",
    "NavDaySummary",
    "NavRunSummary",
    "clearances",
    "goal_reached",
    "nav_day_summary",
    "nav_run_summary",
    "path_length_m",
    "spl",
    "BEAM_TO_POINT_CLASS",
    "LOST_THRESHOLD_M",
    "POINT_CLASSES",
    "RPE_UNITS",
    "RUN_RPE_DELTA",
    "RUN_RPE_UNIT",
    "ClassScores",
    "DaySummary",
    "ErrorStats",
    "GroupSummary",
    "LostStats",
    "OverallSummary",
    "RPEResult",
    "Result",
    "RunSummary",
    "ate",
    "class_scores",
    "confusion_matrix",
    "day_summary",
    "error_stats",
    "heading_errors",
    "lost_episodes",
    "lost_fraction",
    "lost_stats",
    "mean_per_scan",
    "n_onsets",
    "overall_summary",
    "position_errors",
    "rpe",
    "rpe_label",
    "rpe_pairs",
    "run_summary",
    "scan_errors",
    "summarize",
    "summarize_groups",
]
