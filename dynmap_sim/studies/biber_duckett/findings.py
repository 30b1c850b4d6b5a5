"""Biber & Duckett's §5 findings, checked on an experiment's results (the lab replica).

The paper compares, on the same recorded data, the dynamic map against the map of the first
day used as a static map, with and without short-term memory (§5.3), and reports:

* Figs. 10–11: "a clear benefit in using the dynamic map" in the average likelihood of a
  reading and in the certainty ``λ_min``; "the static map performs better at the beginning
  than at the end, while the dynamic map improves performance with time";
* Fig. 12: "each timescale was actually used";
* Fig. 13: "the usage of the short-term memory map decreased with time, while usage of the
  long-term memory map increased";
* §4.3: safe mode "was activated in approximately 0.5 percent of all cases".

With ground truth we add what the paper could not measure: the dynamic map's position error
below static MCL's (each configuration that ran) in the weeks after the first; the
exhibition's share in each timescale (Fig. 9, :mod:`.exhibition`); and the share of λ5's
points on walls over the days (§5.2, :mod:`.map_structure`).

:func:`evaluate_findings` is a pure function of per-scan arrays; :func:`findings_from_db`
picks the localizers of a results database by their registry names (``dynamic-map``,
``static-map``, ``static-map+stm``, ``static-mcl``). Each :class:`Finding` says what the
paper reports, what was measured, and whether it holds here (None: not measurable, e.g. a
trend on fewer than :data:`MIN_TREND_DAYS` days); the report writes them to
``findings.md`` and ``findings.json`` so that runs can be compared and kept in CI.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.studies.biber_duckett.exhibition import exhibition_from_db
from dynmap_sim.studies.biber_duckett.figures import daily_means, selection_counts_per_day
from dynmap_sim.studies.biber_duckett.map_structure import (
    dynamic_map_snapshots,
    map_structure_from_db,
)

#: Share of days (after the first ones) on which the dynamic map must beat a static variant.
DAY_SHARE = 0.8
#: "Approximately 0.5 percent" (§4.3): we accept up to four times that.
SAFE_MODE_MAX = 0.02
#: A timescale chosen for less than this share of scans counts as unused (Fig. 12).
MIN_TIMESCALE_SHARE = 0.01
#: A trend of a share (Fig. 13's usage, §5.2's walls) counts when its fitted line and its
#: last day against its first both change it by at least this much the claimed way (one
#: percentage point), not for any sign of the slope (:func:`_trend_holds`).
MIN_TREND = 0.01
#: A trend over the days (the slopes of Figs. 10-11, the usage of Fig. 13, the walls of
#: §5.2) is judged only on at least this many days of data; with fewer its finding is not
#: measurable (``holds`` None). A line through two or three daily values follows one day's
#: noise: a 3-day lab run "found" λ1 usage falling at -39.9 %/day from its days 2 and 3, a
#: 2-day run λ5's walls emerging. Five days are one working week of the replica's calendar;
#: B&D read their trends off five weeks (Figs. 10-13, §5.4).
MIN_TREND_DAYS = 5


#: Keys of every finding, in the order a report lists them (scenario files name them in
#: ``[expectations] findings``).
FINDING_KEYS = (
    "likelihood_above_static",
    "certainty_above_static",
    "static_degrades_dynamic_does_not",
    "all_timescales_used",
    "stm_usage_falls",
    "ltm_usage_rises",
    "safe_mode_rare",
    "error_below_static_mcl",
    "exhibition_fades",
    "static_structure_emerges",
)


@dataclass(frozen=True)
class Finding:
    """One claim of the paper checked on an experiment (``holds`` None: not measurable)."""

    key: str
    paper: str
    measured: str
    holds: bool | None


def _slope_per_day(days: NDArray[np.integer], values: NDArray[np.floating]) -> float:
    """Least-squares slope of ``values`` against ``days`` (per day)."""
    if len(days) < 2:
        return float("nan")
    return float(np.polyfit(days.astype(float), values.astype(float), 1)[0])


def _num(value: float, spec: str) -> str:
    """``value`` formatted with ``spec``; "not measurable" when it is not finite (a verdict's
    text never shows ``nan``)."""
    return format(value, spec) if np.isfinite(value) else "not measurable"


def _too_few_days(n_days: int, what: str = "days") -> str:
    """The text of a trend that cannot be judged on ``n_days`` (< :data:`MIN_TREND_DAYS`)."""
    if n_days == 1:  # "1 day from day 3", "1 daily map"
        what = what.replace("days", "day", 1).replace("maps", "map", 1)
    return f"not measurable: only {n_days} {what} (a trend needs >= {MIN_TREND_DAYS})"


def _trend_holds(
    days: NDArray[np.integer], values: NDArray[np.floating], sign: int
) -> tuple[bool, str]:
    """Whether ``values`` (shares, on at least :data:`MIN_TREND_DAYS` days) rise (``sign``
    +1) or fall (-1), and the numbers that say so.

    Both the fitted line's change over the days and the change from the first day to the last
    must go the claimed way by at least :data:`MIN_TREND`. B&D §5.4 read the trends of
    Fig. 13 off the plot, from its beginning to its end ("decreased with time"): the fit alone
    can come from a bump in between while the last day is back above the first (the 28-day
    apartment: λ1 31.0 % on day 2, 34.5 % on day 28, fitted down), the two end points alone
    are two noisy days. When they disagree the claim is not borne out (``False``), and the
    text says why."""
    fitted = _slope_per_day(days, values) * float(days[-1] - days[0])
    change = float(values[-1] - values[0])
    text = f"change {100 * change:+.1f} points, fitted {100 * fitted:+.1f} points"
    ok_fit, ok_ends = sign * fitted >= MIN_TREND, sign * change >= MIN_TREND
    if np.sign(fitted) != np.sign(change):
        text += " (the fitted line and the first-vs-last comparison disagree)"
    return bool(ok_fit and ok_ends), text


def _compare_daily(
    name: str,
    what: str,
    dyn: dict[str, NDArray[Any]],
    statics: dict[str, dict[str, NDArray[Any]]],
    first_day: int,
) -> Finding:
    """The dynamic map's daily mean of ``what`` above each static variant's on most days."""
    parts, ok, n_compared = [], True, 0
    d_days, d_means = daily_means(dyn["day"], dyn[what])
    for label, s in statics.items():
        s_days, s_means = daily_means(s["day"], s[what])
        common = np.intersect1d(d_days[d_days >= first_day], s_days)
        if len(common) == 0:
            parts.append(f"{label}: no days from day {first_day}")
            continue
        n_compared += 1
        dm = d_means[np.searchsorted(d_days, common)]
        sm = s_means[np.searchsorted(s_days, common)]
        above = int(np.sum(dm > sm))
        ok &= above >= DAY_SHARE * len(common)
        parts.append(
            f"above {label} on {above}/{len(common)} days (mean {dm.mean():.3g} vs {sm.mean():.3g})"
        )
    return Finding(
        name,
        f"the dynamic map's daily {what} above the static variants' (Figs. 10-11), "
        f"here on >= {DAY_SHARE:.0%} of the days from day {first_day}",
        "; ".join(parts) or "no static variant ran",
        ok if n_compared else None,
    )


def _trend_finding(
    dynamic: dict[str, NDArray[Any]],
    statics: dict[str, dict[str, NDArray[Any]]],
    first_day: int,
) -> Finding:
    """The trends of Figs. 10-11: the static maps' daily mean likelihood falls from
    ``first_day`` while the dynamic map's does not."""
    trend = []
    ok_trend: bool | None = True if statics else None
    for label, s in {"dynamic-map": dynamic, **statics}.items():
        days, means = daily_means(s["day"], s["scan_loglik"])
        later = days >= first_day
        if later.sum() < MIN_TREND_DAYS:
            trend.append(f"{label} {_too_few_days(int(later.sum()), f'days from day {first_day}')}")
            ok_trend = None
            continue
        slope = _slope_per_day(days[later], means[later])
        trend.append(f"{label} {slope:+.4f}/day")
        if ok_trend is not None:
            ok_trend &= bool(slope >= 0) if s is dynamic else bool(slope < 0)
    return Finding(
        "static_degrades_dynamic_does_not",
        "the static map performs better at the beginning than at the end, the dynamic map "
        "improves with time (slope of the daily mean likelihood from day "
        f"{first_day}, on >= {MIN_TREND_DAYS} days)",
        ", ".join(trend),
        ok_trend,
    )


def _timescales_used_finding(day_counts: NDArray[np.integer], every: bool) -> Finding:
    """Fig. 12: each timescale chosen for at least :data:`MIN_TIMESCALE_SHARE` of the
    selections; ``day_counts`` are the ``(n_days, 5)`` selection counts, ``every`` whether
    they count every selection or only each scan's first."""
    what = "every selection" if every else "first selection of each scan"
    counts = day_counts.sum(axis=0).astype(float)
    share = counts / max(counts.sum(), 1.0)
    return Finding(
        "all_timescales_used",
        f"each timescale was actually used (Fig. 12), here >= {MIN_TIMESCALE_SHARE:.0%} each",
        ", ".join(f"λ{i + 1} {100 * v:.1f} %" for i, v in enumerate(share)) + f" ({what})",
        bool(counts.sum() > 0 and np.all(share >= MIN_TIMESCALE_SHARE)),
    )


def _usage_trend_findings(
    days: NDArray[np.integer], day_counts: NDArray[np.integer]
) -> list[Finding]:
    """Fig. 13's trends from day 2 (day 1 maps the building, so its choices are special):
    λ1's daily share of the selections falls, λ5's rises (:func:`_trend_holds`)."""
    out = []
    usage = day_counts / np.maximum(day_counts.sum(axis=1, keepdims=True), 1)
    usage, days = usage[days >= 2], days[days >= 2]
    for key, level, sign, claim in (
        ("stm_usage_falls", 0, -1, "the usage of the short-term memory map (λ1) decreased"),
        ("ltm_usage_rises", 4, +1, "the usage of the most long-term map (λ5) increased"),
    ):
        paper = (
            f"{claim} with time (Fig. 13, §5.4); here its daily share from day 2, on >= "
            f"{MIN_TREND_DAYS} days: the fitted line and the last day against the first both "
            f"{'fall' if sign < 0 else 'rise'} by >= 1 percentage point"
        )
        if not len(days):
            out.append(Finding(key, paper, "no timescale choices", None))
            continue
        measured = f"λ{level + 1} share {100 * usage[0, level]:.1f} % on day {days[0]}" + (
            f", {100 * usage[-1, level]:.1f} % on day {days[-1]}" if len(days) > 1 else ""
        )
        if len(days) < MIN_TREND_DAYS:
            out.append(Finding(key, paper, f"{measured}; {_too_few_days(len(days))}", None))
            continue
        holds, numbers = _trend_holds(days, usage[:, level], sign)
        slope = 100 * _slope_per_day(days, usage[:, level])
        out.append(Finding(key, paper, f"{measured}: {numbers} ({slope:+.3f} %/day)", holds))
    return out


def _safe_mode_finding(dynamic: dict[str, NDArray[Any]]) -> Finding:
    """§4.3: safe mode on at most :data:`SAFE_MODE_MAX` of the dynamic map's scans after
    day 1."""
    sm = dynamic["safe_mode"]
    later = (dynamic["day"] > 1) & np.isfinite(sm)
    frac = float(np.mean(sm[later] > 0.5)) if later.any() else float("nan")
    return Finding(
        "safe_mode_rare",
        f"safe mode in approximately 0.5 % of the cases (§4.3), here <= {SAFE_MODE_MAX:.0%}",
        f"{100 * frac:.3f} % of the scans after day 1"
        if np.isfinite(frac)
        else "not measurable: no scans after day 1",
        bool(frac <= SAFE_MODE_MAX) if np.isfinite(frac) else None,
    )


def _error_finding(
    dynamic: dict[str, NDArray[Any]],
    baselines: dict[str, dict[str, NDArray[Any]]],
    week_of_day: dict[int, int],
) -> Finding:
    """Ground truth: the dynamic map's weekly mean position error (m) below each static MCL
    run's in every week after the first."""
    if not baselines:
        return Finding("error_below_static_mcl", "(ground truth)", "no static-mcl localizer", None)
    weeks = sorted({week_of_day[int(d)] for d in np.unique(dynamic["day"])})
    parts, ok, measurable = [], True, len(weeks) > 1
    for b_label, base in baselines.items():
        cells = []
        for w in weeks:
            days_w = [d for d, k in week_of_day.items() if k == w]
            e_d = np.nanmean(dynamic["err_m"][np.isin(dynamic["day"], days_w)])
            e_b = np.nanmean(base["err_m"][np.isin(base["day"], days_w)])
            if not (np.isfinite(e_d) and np.isfinite(e_b)):
                cells.append(f"week {w}: not measurable")
                measurable &= w == weeks[0]
                continue
            if w > weeks[0]:
                ok &= bool(e_d < e_b)
            cells.append(f"week {w}: {e_d:.3f} vs {e_b:.3f} m")
        parts.append(f"{b_label}: " + ", ".join(cells))
    return Finding(
        "error_below_static_mcl",
        "(new, from ground truth) the dynamic map's mean position error below static "
        "MCL's (every configuration that ran) in every week after the first",
        "; ".join(parts),
        ok if measurable or not ok else None,
    )


def evaluate_findings(
    dynamic: dict[str, NDArray[Any]],
    statics: dict[str, dict[str, NDArray[Any]]],
    baselines: dict[str, dict[str, NDArray[Any]]],
    week_of_day: dict[int, int],
    first_day: int = 3,
    selections: tuple[NDArray[np.integer], NDArray[np.integer]] | None = None,
) -> list[Finding]:
    """Check the §5 findings on per-scan arrays.

    Each series is a dict of equal-length arrays ``day``, ``err_m``, ``scan_loglik``,
    ``lambda_min``, ``timescale`` (0-based index, NaN or negative: none) and ``safe_mode``
    (1/0/NaN), as :meth:`ResultsDB.per_scan` returns them. ``statics`` maps labels of the
    static variants to their series, ``baselines`` labels of static MCL runs to theirs,
    ``week_of_day`` the 1-based week of every day. ``first_day``: the comparisons of
    Figs. 10–11 start there (the maps of day 1 are the static maps themselves).
    ``selections``: days and ``(n_days, 5)`` counts of every timescale selection (what
    Figs. 12–13 count); without them the first selection of each scan stands in.
    """
    days, day_counts, every = selection_counts_per_day(
        dynamic["day"], dynamic["timescale"], selections
    )
    return [
        _compare_daily("likelihood_above_static", "scan_loglik", dynamic, statics, first_day),
        _compare_daily("certainty_above_static", "lambda_min", dynamic, statics, first_day),
        _trend_finding(dynamic, statics, first_day),
        _timescales_used_finding(day_counts, every),
        *_usage_trend_findings(days, day_counts),
        _safe_mode_finding(dynamic),
        _error_finding(dynamic, baselines, week_of_day),
    ]


def exhibition_finding(mem: Any, exhibition_days: list[int]) -> Finding:
    """Fig. 9: the exhibition in λ2/λ3 on its last day (>= 50 % of the exhibit rays), gone
    from them three days after its removal (<= 20 %), never in λ5 (<= 30 %); ``mem`` is an
    :class:`~dynmap_sim.studies.biber_duckett.exhibition.ExhibitMemory`."""
    paper = (
        "the exhibition enters the short timescales and fades after its removal while λ5 "
        "stays stable (Fig. 9); here the share of the exhibit rays of the local map that sees "
        "it best whose median is on the exhibit: λ2 or λ3 >= 50 % on its last day, both "
        "<= 20 % three days after, λ5 <= 30 % on every day"
    )
    last = max(exhibition_days)
    days = list(mem.days)
    during = [d for d in days if min(exhibition_days) <= d <= last]
    after = [d for d in days if d >= last + 3]
    lv = list(mem.levels)
    if not during or not after or not {1, 2, 4} <= set(lv):
        return Finding("exhibition_fades", paper, "no snapshots around the exhibition", None)
    sh = mem.share
    d_on, d_off = days.index(during[-1]), days.index(after[0])
    on = np.nanmax(sh[d_on, [lv.index(1), lv.index(2)]])
    off = np.nanmax(sh[d_off, [lv.index(1), lv.index(2)]])
    l5 = np.nanmax(sh[:, lv.index(4)])
    measured = (
        f"day {during[-1]}: λ2 {_num(100 * sh[d_on, lv.index(1)], '.0f')} %, "
        f"λ3 {_num(100 * sh[d_on, lv.index(2)], '.0f')} %; day {after[0]}: "
        f"λ2 {_num(100 * sh[d_off, lv.index(1)], '.0f')} %, "
        f"λ3 {_num(100 * sh[d_off, lv.index(2)], '.0f')} %; "
        f"λ5 at most {_num(100 * l5, '.0f')} % (local map at "
        f"{np.round(mem.centre, 1).tolist()}, {mem.n_exhibit_rays[4]} exhibit rays of 1440)"
    )
    holds = bool(on >= 0.5 and off <= 0.2 and l5 <= 0.3)
    return Finding(
        "exhibition_fades", paper, measured, holds if np.isfinite([on, off, l5]).all() else None
    )


def structure_finding(ms: Any) -> Finding:
    """§5.2 (ground truth): the share of λ5's points on walls rises by at least
    :data:`MIN_TREND` over at least :data:`MIN_TREND_DAYS` daily maps (fitted line and last
    day against the first, :func:`_trend_holds`); ``ms`` is a
    :class:`~dynmap_sim.studies.biber_duckett.map_structure.MapStructure`."""
    paper = (
        "the accuracy of the local maps increased over time: static parts like walls emerge "
        "while moving objects like chairs disappear (§5.2, seen in the maps; measured here "
        f"from ground truth: the share of λ5's points within {100 * ms.tol_m:.0f} cm of a "
        f"wall, on >= {MIN_TREND_DAYS} days: the fitted line and the last day against the "
        "first both rise by >= 1 percentage point)"
    )
    days = np.asarray(ms.days)
    if 4 not in ms.levels or not len(days):
        return Finding("static_structure_emerges", paper, "no daily maps of λ5", None)
    b5 = list(ms.levels).index(4)
    parts = [
        f"λ{level + 1} {_num(100 * ms.on_walls[0, b], '.1f')} % → "
        f"{_num(100 * ms.on_walls[-1, b], '.1f')} %"
        for b, level in enumerate(ms.levels)
    ]
    measured = (
        f"points on walls, day {days[0]} → day {days[-1]}: " + ", ".join(parts)
        + "; median distance of λ5's points to the true world "
        f"{_num(1000 * ms.median_dist_m[0, b5], '.0f')} → "
        f"{_num(1000 * ms.median_dist_m[-1, b5], '.0f')} mm"
    )  # fmt: skip
    walls = ms.on_walls[:, b5]
    if len(days) < MIN_TREND_DAYS or not np.all(np.isfinite(walls)):
        why = _too_few_days(len(days), "daily maps") if len(days) < MIN_TREND_DAYS else (
            "not measurable: λ5 holds no points on some days"
        )  # fmt: skip
        return Finding("static_structure_emerges", paper, f"{measured}; {why}", None)
    holds, numbers = _trend_holds(days, walls, +1)
    return Finding("static_structure_emerges", paper, f"{measured}; λ5 {numbers}", holds)


def weeks_of_days(dates: dict[int, dt.date]) -> dict[int, int]:
    """1-based calendar week (Monday to Sunday) of each day, counted from the first day's."""
    first = min(dates.values())
    monday = first - dt.timedelta(days=first.weekday())
    return {d: (date - monday).days // 7 + 1 for d, date in dates.items()}


def findings_from_db(
    db: Any, exhibition: Any = None, structure: Any = None
) -> list[Finding] | None:
    """:func:`evaluate_findings` on a :class:`ResultsDB`, plus :func:`exhibition_finding`
    when ``exhibition`` (the result of
    :func:`~dynmap_sim.studies.biber_duckett.exhibition.exhibition_from_db`) is given and
    :func:`structure_finding` when ``structure`` (a
    :class:`~dynmap_sim.studies.biber_duckett.map_structure.MapStructure`) is; None without a
    ``dynamic-map``."""
    rows = db.query("SELECT idx, label, name, params FROM localizers ORDER BY idx")
    by_name: dict[str, list[tuple[int, str, dict[str, Any]]]] = {}
    for idx, label, name, params in rows:
        by_name.setdefault(name, []).append((int(idx), label, json.loads(params or "{}")))
    if "dynamic-map" not in by_name:
        return None
    dyn = db.per_scan(by_name["dynamic-map"][0][0])
    statics = {
        label: db.per_scan(idx)
        for name in ("static-map", "static-map+stm")
        for idx, label, _ in by_name.get(name, [])[:1]
    }
    baselines = {label: db.per_scan(idx) for idx, label, _ in by_name.get("static-mcl", [])}
    dates = {int(s[0]): dt.date.fromisoformat(s[2]) for s in db.meta().get("slots", [])}
    sel = db.timescale_counts_per_day(by_name["dynamic-map"][0][0])
    out = evaluate_findings(dyn, statics, baselines, weeks_of_days(dates), selections=sel)
    if exhibition is not None:
        out.append(exhibition_finding(exhibition[0], exhibition[3]))
    if structure is not None:
        out.append(structure_finding(structure))
    return out


def measure_findings(db: Any) -> tuple[list[Finding] | None, Any, Any]:
    """(findings, exhibition, map structure) of a :class:`ResultsDB`: the ``dynamic-map``'s
    daily snapshots are read once for :func:`~.exhibition.exhibition_from_db` (Fig. 9) and
    :func:`~.map_structure.map_structure_from_db` (§5.2), then :func:`findings_from_db`.
    Each is None when it cannot be measured (no ``dynamic-map``, no exhibition, ...)."""
    snaps = dynamic_map_snapshots(db)
    exhibition = exhibition_from_db(db, snaps)
    structure = map_structure_from_db(db, snaps)
    return findings_from_db(db, exhibition, structure), exhibition, structure


def findings_table(findings: list[Finding], paper: bool = True) -> list[str]:
    """Markdown table lines: finding, (what the paper says,) measured, holds."""
    head = ["finding", *(["the paper"] if paper else []), "measured here", "holds"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for f in findings:
        holds = "n/a" if f.holds is None else ("yes" if f.holds else "**no**")
        cells = [f"`{f.key}`", *([f.paper] if paper else []), f.measured, holds]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def write_findings(findings: list[Finding], out_dir: Path) -> list[Path]:
    """``findings.md`` (a table) and ``findings.json`` in ``out_dir``."""
    md = out_dir / "findings.md"
    lines = ["# Biber & Duckett §5 findings on this experiment", "", *findings_table(findings)]
    md.write_text("\n".join(lines) + "\n")
    js = out_dir / "findings.json"
    js.write_text(json.dumps([asdict(f) for f in findings], indent=1, ensure_ascii=False) + "\n")
    return [md, js]
