"""Hentschel & Wagner §7.3's findings, checked on an experiment's results with ground truth.

The paper reports (Figs. 6-8, §7.3): the semistatic share of the points falls over week 1
(23 % on day 1 to 3 % on day 7) and is higher in week 2 (9.5 %); the dynamic share rises in
week 3 (0.5 % to 9.2 %); week 4 is "fairly similar to the end of week one"; the mean
position error falls over week 1 (0.14 to 0.09 m), the largest error (0.48 m) is on day 9,
the robot is never lost; static MCL on the walls-only map has a higher error and "did not
provide any pose estimates on days 8, 9, 10, and 11"; the robot drove all 28 days
autonomously and passed the day-22 block by global replanning. The simulator has no
reflector error, so the shapes are checked, not the centimetres.

Verdict rules are the project's (:mod:`dynmap_sim.studies.biber_duckett.findings`): a trend
needs :data:`MIN_TREND_DAYS` days and both its fitted line and its last-vs-first change the
claimed way by :data:`MIN_TREND` (one percentage point for shares); ``holds`` None when a
finding cannot be measured (too few days, no such localizer), never tuned to pass.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from dynmap_sim.metrics import class_scores
from dynmap_sim.studies.biber_duckett.findings import (
    MIN_TREND,
    MIN_TREND_DAYS,
    Finding,
    _slope_per_day,
    _too_few_days,
    _trend_holds,
    findings_table,
)
from dynmap_sim.studies.hentschel_wagner.data import (
    SCORED_CLASSES,
    DaySeries,
    HWData,
    class_scores_per_day,
    dynamic_scores,
    semistatic_scores,
    week_of,
)

#: Keys of every finding, in report order (``[expectations] findings`` names them).
FINDING_KEYS = (
    "hw_semistatic_falls_week1",
    "hw_semistatic_higher_week2",
    "hw_dynamic_rises_week3",
    "hw_week4_like_end_of_week1",
    "hw_error_falls_week1",
    "hw_worst_day_in_week2",
    "hw_never_lost",
    "hw_static_mcl_tracks_week1",
    "hw_static_mcl_fails_days_8_11",
    "hw_goal_every_day",
    "hw_dynamic_points_scored",
)

#: Week 2's semistatic share against day 7's (paper 9.5 % vs 3 %: 3.2x): at least twice.
WEEK2_FACTOR = 2.0
#: Week 3's dynamic share against weeks 1-2 (paper 9.2 % vs 0.5 %: 18x): at least 5x.
WEEK3_FACTOR = 5.0
#: Week 4 "fairly similar to the end of week one": each share within half of day 7's, or
#: within one percentage point (shares near zero).
WEEK4_REL, WEEK4_ABS = 0.5, 0.01
#: Semistatic share on day 7 at most this share of day 1's (paper 3/23 = 0.13).
WEEK1_SEMI_RATIO = 0.5
#: The week-1 error falls when the fitted line and day 7 against day 1 both fall by at least
#: this share of day 1's mean error (paper: -36 %).
ERROR_FALL_SHARE = 0.10
#: Static MCL "tracks" in week 1: lost (error > 0.5 m) on at most this share of its scans.
TRACKS_LOST_MAX = 0.05
#: Static MCL "provides no pose" on a day: lost on at least this share of its scans.
FAILS_LOST_MIN = 0.5
#: The issue's goal for the dynamic class (precision, recall), over week 3.
DYNAMIC_GOAL = (0.95, 0.90)
FAIL_DAYS = (8, 9, 10, 11)


def _pct(v: float) -> str:
    return f"{100 * v:.1f} %" if np.isfinite(v) else "not measurable"


def _mean_share(data: HWData, cls: int, days: list[int]) -> float:
    s = data.shares
    if s is None:
        return float("nan")
    m = np.isin(s.days, days)
    return float(np.nanmean(s.fractions[m, cls])) if m.any() else float("nan")


def _week_days(data: HWData, week: int) -> list[int]:
    s = data.shares
    days = s.days.tolist() if s is not None else []
    return [d for d in days if week_of(d) == week]


def _share_findings(data: HWData) -> list[Finding]:
    s = data.shares
    out = []
    w1 = _week_days(data, 1)
    paper = (
        "the semistatic share falls over week 1, 23 % on day 1 to 3 % on day 7 (Fig. 6); here "
        f"on >= {MIN_TREND_DAYS} days of week 1 the fitted line and the last day against the "
        f"first both fall by >= {100 * MIN_TREND:.0f} point, to <= {WEEK1_SEMI_RATIO:.0%} of "
        "day 1's share"
    )
    if s is None or not w1:
        out.append(Finding(FINDING_KEYS[0], paper, "no point classes in week 1", None))
    else:
        days = np.array(w1)
        v = s.fractions[np.isin(s.days, days), 2]
        measured = f"{_pct(v[0])} on day {days[0]} → {_pct(v[-1])} on day {days[-1]}"
        if len(days) < MIN_TREND_DAYS:
            out.append(
                Finding(FINDING_KEYS[0], paper, f"{measured}; {_too_few_days(len(days))}", None)
            )
        else:
            ok, numbers = _trend_holds(days, v, -1)
            ok = ok and bool(v[-1] <= WEEK1_SEMI_RATIO * v[0])
            out.append(Finding(FINDING_KEYS[0], paper, f"{measured}: {numbers}", ok))
    # week 2 above the end of week 1
    day7 = [d for d in w1 if d == 7]
    w2 = _week_days(data, 2)
    paper = (
        "the semistatic share is higher in week 2, 9.5 % on average against 3 % on day 7 "
        f"(Fig. 6); here week 2's mean >= {WEEK2_FACTOR:g}x day 7's"
    )
    if not day7 or not w2:
        out.append(Finding(FINDING_KEYS[1], paper, "needs day 7 and week 2", None))
    else:
        a, b = _mean_share(data, 2, w2), _mean_share(data, 2, day7)
        out.append(
            Finding(
                FINDING_KEYS[1],
                paper,
                f"week 2 mean {_pct(a)} ({len(w2)} days), day 7 {_pct(b)}",
                bool(a >= WEEK2_FACTOR * b and a > b + MIN_TREND),
            )
        )
    # week 3's dynamic share
    w12 = _week_days(data, 1) + _week_days(data, 2)
    w3 = _week_days(data, 3)
    paper = (
        "the dynamic share rises in week 3, 0.5 % to 9.2 % (Fig. 6); here week 3's mean >= "
        f"{WEEK3_FACTOR:g}x that of weeks 1-2 and >= {100 * MIN_TREND:.0f} point above it"
    )
    if not w12 or not w3:
        out.append(Finding(FINDING_KEYS[2], paper, "needs weeks 1-2 and week 3", None))
    else:
        a, b = _mean_share(data, 1, w3), _mean_share(data, 1, w12)
        out.append(
            Finding(
                FINDING_KEYS[2],
                paper,
                f"week 3 mean {_pct(a)}, weeks 1-2 {_pct(b)}",
                bool(a >= WEEK3_FACTOR * b and a >= b + MIN_TREND),
            )
        )
    # week 4 like the end of week 1
    w4 = _week_days(data, 4)
    paper = (
        "week 4's shares are fairly similar to the end of week 1 (Fig. 6); here week 4's "
        f"mean dynamic and semistatic shares within {WEEK4_REL:.0%} of day 7's or within "
        f"{100 * WEEK4_ABS:.0f} point"
    )
    if not day7 or not w4:
        out.append(Finding(FINDING_KEYS[3], paper, "needs day 7 and week 4", None))
    else:
        parts, ok = [], True
        for cls, name in ((1, "dynamic"), (2, "semistatic")):
            a, b = _mean_share(data, cls, w4), _mean_share(data, cls, day7)
            ok &= bool(abs(a - b) <= max(WEEK4_REL * b, WEEK4_ABS))
            parts.append(f"{name} {_pct(a)} vs {_pct(b)}")
        out.append(Finding(FINDING_KEYS[3], paper, "week 4 vs day 7: " + ", ".join(parts), ok))
    return out


def _error_falls_finding(data: HWData, subj: DaySeries | None) -> list[Finding]:
    """H&W Fig. 7: the adaptive model's mean error falls over week 1."""
    out: list[Finding] = []
    paper = (
        "the adaptive model's mean error falls over week 1, 0.14 to 0.09 m (Fig. 7); here the "
        f"fitted line and day 7 against day 1 both fall by >= {ERROR_FALL_SHARE:.0%} of day 1's"
    )
    if subj is None:
        out.append(Finding(FINDING_KEYS[4], paper, "no adaptive-memory localizer", None))
    else:
        m = subj.days <= 7
        days, v = subj.days[m], subj.mean_error_m[m]
        if not len(days):
            out.append(Finding(FINDING_KEYS[4], paper, "no day of week 1", None))
        else:
            measured = f"{v[0]:.3f} m on day {days[0]} → {v[-1]:.3f} m on day {days[-1]}"
            if len(days) < MIN_TREND_DAYS:
                why = _too_few_days(len(days))
                out.append(Finding(FINDING_KEYS[4], paper, f"{measured}; {why}", None))
            else:
                fitted = _slope_per_day(days, v) * float(days[-1] - days[0])
                change = float(v[-1] - v[0])
                bar = ERROR_FALL_SHARE * float(v[0])
                out.append(
                    Finding(
                        FINDING_KEYS[4],
                        paper,
                        f"{measured}: change {change:+.3f} m, fitted {fitted:+.3f} m",
                        bool(fitted <= -bar and change <= -bar),
                    )
                )
    return out


def _worst_day_finding(data: HWData, subj: DaySeries | None) -> list[Finding]:
    """H&W Fig. 7: the largest error is in week 2."""
    out: list[Finding] = []
    paper = (
        "the largest error is in week 2 (0.48 m on day 9, Fig. 7): here the day of the "
        "largest max error"
    )
    if subj is None or len(subj.days) == 0:
        out.append(Finding(FINDING_KEYS[5], paper, "no adaptive-memory localizer", None))
    else:
        k = int(np.nanargmax(subj.max_error_m))
        km = int(np.nanargmax(subj.mean_error_m))
        weeks = {week_of(int(d)) for d in subj.days}
        out.append(
            Finding(
                FINDING_KEYS[5],
                paper,
                f"max error {subj.max_error_m[k]:.3f} m on day {subj.days[k]}; largest daily "
                f"mean {subj.mean_error_m[km]:.3f} m on day {subj.days[km]}",
                bool(week_of(int(subj.days[k])) == 2) if 2 in weeks else None,
            )
        )
    return out


def _never_lost_finding(data: HWData, subj: DaySeries | None) -> list[Finding]:
    """§7.3: the adaptive model never loses the robot."""
    out: list[Finding] = []
    paper = "the adaptive model never loses the robot (§7.3): here never > 0.5 m off"
    if subj is None or len(subj.days) == 0:
        out.append(Finding(FINDING_KEYS[6], paper, "no adaptive-memory localizer", None))
    else:
        worst = float(np.nanmax(subj.max_error_m))
        lost_days = [int(d) for d, f in zip(subj.days, subj.lost_fraction, strict=True) if f > 0]
        out.append(
            Finding(
                FINDING_KEYS[6],
                paper,
                f"max error {worst:.3f} m over {len(subj.days)} days; lost on days "
                f"{lost_days or 'none'}",
                not lost_days,
            )
        )
    return out


def _static_mcl_week1_finding(
    data: HWData, subj: DaySeries | None, base: DaySeries | None
) -> list[Finding]:
    """Fig. 7: static MCL on the walls tracks in week 1, with a higher error."""
    out: list[Finding] = []
    paper = (
        "static MCL on the walls-only map tracks in week 1 with a higher error than the "
        f"adaptive model (Fig. 7); here lost on <= {TRACKS_LOST_MAX:.0%} of its week-1 scans "
        "and its week-1 mean error above the adaptive model's"
    )
    if base is None or subj is None:
        why = "no static-mcl on the prior's walls" if base is None else "no adaptive-memory"
        out.append(Finding(FINDING_KEYS[7], paper, why, None))
    else:
        mb, ms = base.days <= 7, subj.days <= 7
        if not mb.any():
            out.append(Finding(FINDING_KEYS[7], paper, "no day of week 1", None))
        else:
            lost = float(np.mean(base.lost_fraction[mb]))
            eb, es = float(np.mean(base.mean_error_m[mb])), float(np.mean(subj.mean_error_m[ms]))
            out.append(
                Finding(
                    FINDING_KEYS[7],
                    paper,
                    f"`{base.label}` lost on {_pct(lost)} of week 1 (mean of days "
                    f"{int(base.days[mb][0])}-{int(base.days[mb][-1])}), mean error "
                    f"{eb:.3f} m vs {es:.3f} m",
                    bool(lost <= TRACKS_LOST_MAX and eb > es),
                )
            )
    return out


def _static_mcl_fails_finding(
    data: HWData, subj: DaySeries | None, base: DaySeries | None
) -> list[Finding]:
    """§7.3: static MCL on the walls gives no pose on days 8-11."""
    out: list[Finding] = []
    paper = (
        "static MCL on the walls-only map gives no pose on days 8, 9, 10 and 11, where "
        f"obstacles hide most walls (§7.3); here lost on >= {FAILS_LOST_MIN:.0%} of the scans "
        "of each of these days"
    )
    if base is None:
        out.append(Finding(FINDING_KEYS[8], paper, "no static-mcl on the prior's walls", None))
    else:
        have = [d for d in FAIL_DAYS if d in base.days]
        cells = [f"day {d}: {_pct(base.on(d, 'lost_fraction'))}" for d in have]
        holds = (
            all(base.on(d, "lost_fraction") >= FAILS_LOST_MIN for d in have)
            if len(have) == len(FAIL_DAYS)
            else None
        )
        other = [d for d in base.days.tolist() if d not in FAIL_DAYS]
        rest = float(np.mean([base.on(d, "lost_fraction") for d in other])) if other else np.nan
        out.append(
            Finding(
                FINDING_KEYS[8],
                paper,
                f"`{base.label}` lost " + (", ".join(cells) or "(no such day)")
                + f"; other days {_pct(rest)} on average",
                holds,
            )
        )  # fmt: skip
    return out


def _error_findings(data: HWData) -> list[Finding]:
    subj = data.series.get(data.subject[1]) if data.subject else None
    walls = [b for b in data.baselines if b[2]]
    base = data.series.get(walls[0][1]) if walls else None
    return [
        *_error_falls_finding(data, subj),
        *_worst_day_finding(data, subj),
        *_never_lost_finding(data, subj),
        *_static_mcl_week1_finding(data, subj, base),
        *_static_mcl_fails_finding(data, subj, base),
    ]


def _nav_finding(data: HWData) -> Finding:
    paper = (
        "the robot drove itself every day (28/28) with no collision, and passed the day-22 "
        "block by global replanning (Fig. 8)"
    )
    if not data.nav:
        return Finding(FINDING_KEYS[9], paper, "no navigation measures", None)
    if data.driver_kind != "autonomous":
        why = f"not measurable: the robot was driven by `{data.driver_kind}`, not by itself"
        return Finding(FINDING_KEYS[9], paper, why, None)
    reached = sum(bool(n.goal_reached) for _, _, n in data.nav)
    coll = sum(int(n.collisions) for _, _, n in data.nav)
    d22 = [n for d, _, n in data.nav if d == 22]
    text = f"goal reached on {reached}/{len(data.nav)} runs, {coll} collisions"
    ok = reached == len(data.nav) and coll == 0
    if d22:
        text += f"; day 22: goal {'reached' if d22[0].goal_reached else 'NOT reached'}, "
        text += f"{int(d22[0].replans)} replans"
        ok = ok and bool(d22[0].replans > 0)
    return Finding(FINDING_KEYS[9], paper, text, ok)


def _scores_finding(data: HWData) -> Finding:
    paper = (
        "(ground truth) dynamic points found: precision >= "
        f"{DYNAMIC_GOAL[0]:.2f} and recall >= {DYNAMIC_GOAL[1]:.2f} over week 3 (the issue's "
        "goal; the paper gives none)"
    )
    s = data.shares
    w3 = _week_days(data, 3)
    if s is None or not w3:
        return Finding(FINDING_KEYS[10], paper, "no point classes in week 3", None)
    p, r, n = dynamic_scores(s, w3)
    every = s.pooled(s.days.tolist())
    sc = class_scores(every.confusion)
    sp, sr, sn = semistatic_scores(s, _week_days(data, 1) + _week_days(data, 2))
    measured = (
        f"week 3 dynamic precision {p:.3f}, recall {r:.3f} ({n} person points); weeks 1-2 "
        f"semistatic precision {sp:.3f}, recall {sr:.3f} ({sn} new or moved object points); "
        f"all days: semistatic precision {sc.precision[1]:.3f}, recall {sc.recall[1]:.3f}; "
        f"static precision {sc.precision[2]:.3f}, recall {sc.recall[2]:.3f}"
    )
    ok = bool(p >= DYNAMIC_GOAL[0] and r >= DYNAMIC_GOAL[1]) if np.isfinite([p, r]).all() else None
    return Finding(FINDING_KEYS[10], paper, measured, ok)


def evaluate(data: HWData) -> list[Finding]:
    """Every finding on ``data`` (:func:`~.data.load`)."""
    return [
        *_share_findings(data),
        *_error_findings(data),
        _nav_finding(data),
        _scores_finding(data),
    ]


def write_class_scores(data: HWData, path: Path) -> Path | None:
    """``hw_point_class_scores_per_day.csv``: per day, each class's share (the subject's and
    the truth's), the truth's and the subject's beam counts, precision and recall."""
    s = data.shares
    if s is None:
        return None
    sc = class_scores_per_day(s)
    cols = ["day", "week"]
    for name in SCORED_CLASSES:
        cols += [f"{name}_{c}" for c in ("share", "truth_share", "truth_points",
                                         "predicted_points", "precision", "recall")]  # fmt: skip
    lines = [",".join(cols)]
    for k, day in enumerate(s.days.tolist()):
        row = [str(day), str(week_of(day))]
        for c in range(3):
            row += [f"{s.fractions[k, c + 1]:.6f}", f"{s.truth[k, c + 1]:.6f}",
                    str(sc.truth_points[k, c]), str(sc.predicted_points[k, c]),
                    f"{sc.precision[k, c]:.6f}", f"{sc.recall[k, c]:.6f}"]  # fmt: skip
        lines.append(",".join(row))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_findings(findings: list[Finding], out_dir: Path, subject: str | None) -> list[Path]:
    """``hw_findings.md`` (a table) and ``hw_findings.json`` in ``out_dir``."""
    md = out_dir / "hw_findings.md"
    lines = [
        "# Hentschel & Wagner §7.3 findings on this experiment",
        "",
        f"Localizer under study: `{subject}`." if subject else "No adaptive-memory localizer.",
        "",
        *findings_table(findings),
    ]
    md.write_text("\n".join(lines) + "\n")
    js = out_dir / "hw_findings.json"
    js.write_text(json.dumps([asdict(f) for f in findings], indent=1, ensure_ascii=False) + "\n")
    return [md, js]
