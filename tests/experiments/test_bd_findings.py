"""B&D §5 findings evaluated on synthetic per-scan series with known trends."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np

from dynmap_sim.studies.biber_duckett.findings import (
    FINDING_KEYS,
    MIN_TREND_DAYS,
    evaluate_findings,
    structure_finding,
    weeks_of_days,
    write_findings,
)
from dynmap_sim.studies.biber_duckett.map_structure import MapStructure

N_DAYS, PER_DAY = 15, 200


def series(loglik, lam, err, ts_probs=None, safe=0.0, seed=0):
    """Per-scan arrays: daily values from the callables of the day, timescales drawn with the
    day's probabilities (None: no timescale), safe mode on a ``safe`` share of scans."""
    rng = np.random.default_rng(seed)
    day = np.repeat(np.arange(1, N_DAYS + 1), PER_DAY)
    ts = np.full(day.shape, np.nan)
    if ts_probs is not None:
        for d in range(1, N_DAYS + 1):
            m = day == d
            ts[m] = rng.choice(5, size=m.sum(), p=ts_probs(d))
    return {
        "day": day,
        "scan_loglik": np.array([loglik(d) for d in day]) + rng.normal(0, 0.01, day.size),
        "lambda_min": np.array([lam(d) for d in day]),
        "err_m": np.array([err(d) for d in day]),
        "timescale": ts,
        "safe_mode": (rng.random(day.size) < safe).astype(float) if ts_probs else ts,
    }


def paper_like():
    def probs(d):  # λ1 falls from 40 % to 12 %, λ5 rises from 10 % to 38 %
        f = (d - 1) / (N_DAYS - 1)
        p = np.array([0.4 - 0.28 * f, 0.25, 0.15, 0.1, 0.1 + 0.28 * f])
        return p / p.sum()

    dyn = series(lambda d: 1.8 + 0.005 * d, lambda d: 900 + d, lambda d: 0.1, probs, safe=0.004)
    static = series(lambda d: 1.9 - 0.05 * d, lambda d: 800 - 10 * d, lambda d: 0.2)
    stm = series(lambda d: 1.85 - 0.02 * d, lambda d: 850 - 5 * d, lambda d: 0.15)
    mcl = series(lambda d: -0.4, lambda d: 10.0, lambda d: 0.1 if d <= 5 else 0.3)
    nav2 = series(lambda d: -0.7, lambda d: 10.0, lambda d: 0.2)
    return dyn, {"static-map": static, "static-map+stm": stm}, {"tuned": mcl, "nav2": nav2}


WEEKS = {d: (d - 1) // 5 + 1 for d in range(1, N_DAYS + 1)}


def test_every_finding_holds_on_paper_like_series():
    dyn, statics, base = paper_like()
    findings = evaluate_findings(dyn, statics, base, WEEKS)
    found = {f.key: f for f in findings}
    # FINDING_KEYS (what scenario files may require) lists them in report order; the last
    # two come from the exhibition (Fig. 9) and the map structure (§5.2)
    assert [f.key for f in findings] == list(FINDING_KEYS[:8])
    assert FINDING_KEYS[8:] == ("exhibition_fades", "static_structure_emerges")
    assert all(f.holds for f in found.values()), [f for f in found.values() if not f.holds]
    assert "above static-map on 13/13 days" in found["likelihood_above_static"].measured
    assert "tuned: week 1: 0.100 vs 0.100 m, week 2: 0.100 vs 0.300 m" in (
        found["error_below_static_mcl"].measured
    )


def test_findings_fail_when_the_data_disagree():
    dyn, statics, base = paper_like()
    # static+stm as good as the dynamic map on every day: no benefit of the long-term maps
    statics["static-map+stm"]["scan_loglik"] = dyn["scan_loglik"] + 0.01
    # λ3 never chosen; λ1 usage rising instead of falling
    dyn["timescale"] = np.where(dyn["timescale"] == 2, 0, dyn["timescale"])
    late = dyn["day"] > 10
    dyn["timescale"][late & (dyn["timescale"] == 4)] = 0
    dyn["safe_mode"][:] = 0.0
    base["nav2"]["err_m"][:] = 0.05  # one static MCL better than the dynamic map
    found = {f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS)}
    assert not found["likelihood_above_static"].holds
    assert "above static-map+stm on 0/13 days" in found["likelihood_above_static"].measured
    assert not found["all_timescales_used"].holds
    assert not found["stm_usage_falls"].holds
    assert not found["ltm_usage_rises"].holds
    assert found["safe_mode_rare"].holds
    assert not found["error_below_static_mcl"].holds


def test_safe_mode_share_and_missing_baseline():
    dyn, statics, _ = paper_like()
    dyn["safe_mode"][:] = (np.arange(dyn["day"].size) % 10 == 0).astype(float)
    found = {f.key: f for f in evaluate_findings(dyn, statics, {}, WEEKS)}
    assert not found["safe_mode_rare"].holds
    assert found["safe_mode_rare"].measured.startswith("10.000 %")
    assert found["error_below_static_mcl"].holds is None


def test_weeks_start_on_monday_and_findings_are_written(tmp_path):
    dates = {1: dt.date(2007, 10, 18), 2: dt.date(2007, 10, 19), 3: dt.date(2007, 10, 22)}
    assert weeks_of_days(dates) == {1: 1, 2: 1, 3: 2}  # Thu, Fri, next Mon
    dyn, statics, base = paper_like()
    paths = write_findings(evaluate_findings(dyn, statics, base, WEEKS), tmp_path)
    assert [p.name for p in paths] == ["findings.md", "findings.json"]
    rows = json.loads(paths[1].read_text())
    assert len(rows) == 8 and all(r["holds"] for r in rows)
    assert paths[0].read_text().count("| yes |") == 8


def test_counts_of_every_selection_take_precedence_over_the_first_choice():
    """Figs. 12-13 count every selection; the per-scan first choice only stands in."""
    dyn, statics, base = paper_like()
    days = np.arange(1, N_DAYS + 1)
    # every selection: λ5 rising from 10 to 38 of 100, λ1 falling, the rest constant
    counts = np.array([[40 - 2 * d, 25, 15, 10, 10 + 2 * d] for d in days])
    found = {
        f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS, selections=(days, counts))
    }
    assert found["ltm_usage_rises"].holds and found["stm_usage_falls"].holds
    assert found["all_timescales_used"].measured.endswith("(every selection)")
    # the same counts with λ5 falling fail, whatever the first choices say
    flipped = counts[:, ::-1]
    found = {
        f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS, selections=(days, flipped))
    }
    assert not found["ltm_usage_rises"].holds and not found["stm_usage_falls"].holds
    # no counts (older results): the first selection of each scan
    found = {f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS)}
    assert found["all_timescales_used"].measured.endswith("(first selection of each scan)")


def test_a_flat_usage_is_no_trend():
    """A slope of a few thousandths of a percentage point a day is no rise (Fig. 13)."""
    dyn, statics, base = paper_like()
    days = np.arange(1, N_DAYS + 1)
    flat = np.array([[30, 20, 20, 20, 10 + (d % 2)] for d in days])  # λ5 wobbles, no trend
    found = {
        f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS, selections=(days, flat))
    }
    assert not found["ltm_usage_rises"].holds and not found["stm_usage_falls"].holds


TRENDS = ("static_degrades_dynamic_does_not", "stm_usage_falls", "ltm_usage_rises")


def _first_days(series, last_day):
    return {k: v[series["day"] <= last_day] for k, v in series.items()}


def _structure(on_walls_l5):
    n = len(on_walls_l5)
    walls = np.column_stack([np.full(n, 0.5), np.asarray(on_walls_l5, float)])
    return MapStructure(
        days=tuple(range(1, n + 1)),
        levels=(1, 4),
        n_points=np.full((n, 2), 100),
        on_walls=walls,
        on_world=walls,
        median_dist_m=np.full((n, 2), 0.02),
        tol_m=0.05,
    )


def test_trends_are_not_measurable_below_their_minimum_of_days():
    """A 3-day run once said "λ1 usage falls" from two days and showed ``+nan/day``: each
    trend needs MIN_TREND_DAYS days of data, else it says "not measurable" (never nan)."""
    dyn, statics, base = paper_like()
    for last_day in (2, 3, 6):  # usage counts from day 2, the likelihood slopes from day 3
        short = [
            _first_days(dyn, last_day),
            {k: _first_days(v, last_day) for k, v in statics.items()},
            {k: _first_days(v, last_day) for k, v in base.items()},
        ]
        found = {f.key: f for f in evaluate_findings(*short, WEEKS)}
        assert all("nan" not in f.measured for f in found.values()), found
        slopes = found["static_degrades_dynamic_does_not"]
        assert slopes.holds is None
        n_from_3 = {2: "0 days", 3: "1 day", 6: "4 days"}[last_day]
        assert f"dynamic-map not measurable: only {n_from_3} from day 3 " in slopes.measured
        for key in ("stm_usage_falls", "ltm_usage_rises"):
            if last_day - 1 < MIN_TREND_DAYS:
                assert found[key].holds is None
                assert found[key].measured.endswith(
                    f"; not measurable: only {last_day - 1} day"
                    f"{'s' if last_day > 2 else ''} (a trend needs >= 5)"
                )
            else:  # days 2-6: enough to judge
                assert found[key].holds is not None and "not measurable" not in found[key].measured
    # days 3-7 for the slopes, 2-7 for the usage: every trend is judged, and holds
    days = np.arange(1, 8)
    counts = np.array([[40 - 2 * d, 25, 15, 10, 10 + 2 * d] for d in days])
    found = {
        f.key: f
        for f in evaluate_findings(
            _first_days(dyn, 7),
            {k: _first_days(v, 7) for k, v in statics.items()},
            {k: _first_days(v, 7) for k, v in base.items()},
            WEEKS,
            selections=(days, counts),
        )
    }
    assert all(found[k].holds is True for k in TRENDS), [found[k] for k in TRENDS]
    # §5.2's walls: daily maps, from day 1
    few = structure_finding(_structure([0.50, 0.60]))
    assert few.holds is None and few.measured.endswith(
        "; not measurable: only 2 daily maps (a trend needs >= 5)"
    )
    assert "fitted" not in few.measured
    enough = structure_finding(_structure([0.50, 0.52, 0.55, 0.57, 0.60]))
    assert enough.holds is True
    assert enough.measured.endswith("; λ5 change +10.0 points, fitted +10.0 points")


def test_a_trend_agrees_with_its_own_first_and_last_day():
    """The 28-day apartment said "λ1 usage falls" while its own text showed λ1 at 31.0 % on
    day 2 and 34.5 % on day 28: a trend holds only when the fitted line and the last day
    against the first both go the claimed way by >= 1 percentage point."""
    dyn, statics, base = paper_like()
    days = np.arange(1, N_DAYS + 1)
    # λ1 high in the middle days, low after, back up on the last day: the fitted line falls,
    # the last day is above the first
    l1 = np.array([40, 31, 45, 45, 45, 40, 30, 25, 25, 25, 20, 20, 20, 20, 35])
    ten = np.full(N_DAYS, 10)
    counts = np.column_stack([l1, 100 - l1 - 30, ten, ten, ten])
    found = {
        f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS, selections=(days, counts))
    }
    stm = found["stm_usage_falls"]
    assert stm.holds is False
    assert stm.measured.startswith("λ1 share 31.0 % on day 2, 35.0 % on day 15: change +4.0 points")
    assert "(the fitted line and the first-vs-last comparison disagree)" in stm.measured
    # the same with the last day below the first by at least one point holds
    counts[-1] = [20, 40, 10, 10, 20]
    stm = {
        f.key: f for f in evaluate_findings(dyn, statics, base, WEEKS, selections=(days, counts))
    }["stm_usage_falls"]
    assert stm.holds is True and "disagree" not in stm.measured
    # a rise of the end points by less than one point is no rise, whatever the fit says
    walls = structure_finding(_structure([0.50, 0.58, 0.60, 0.60, 0.505]))
    assert walls.holds is False and "change +0.5 points, fitted +1.2 points" in walls.measured
