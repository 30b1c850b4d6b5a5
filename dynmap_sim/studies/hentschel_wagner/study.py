"""Hentschel & Wagner 2011 §7 as a :class:`~dynmap_sim.studies.study.Study`: the long-term
map after day 7 (Fig. 5) and after day 22 with the route memory (Fig. 8), the point-class
shares per day (Fig. 6), the error per day against static MCL (Fig. 7), and §7.3's findings
checked with ground truth (``hw_findings.md``, ``hw_findings.json``; named apart from
Biber & Duckett's ``findings.md``, since both studies apply when a ``dynamic-map`` rides
along)."""

from __future__ import annotations

from pathlib import Path

from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.scenario import Scenario
from dynmap_sim.studies.biber_duckett.findings import findings_table
from dynmap_sim.studies.hentschel_wagner.data import find_subject, load, ltm_day, ltm_grid
from dynmap_sim.studies.hentschel_wagner.figures import (
    plot_class_scores,
    plot_error_per_day,
    plot_ltm,
    plot_point_shares,
    route_memory_after,
    week_label,
)
from dynmap_sim.studies.hentschel_wagner.findings import (
    FINDING_KEYS,
    evaluate,
    write_class_scores,
    write_findings,
)
from dynmap_sim.studies.study import FindingCheck, Study, StudyReport, register_study

#: The days of the long-term map figures: after week 1 (Fig. 5) and after the block (Fig. 8).
LTM_DAYS = (7, 22)


@register_study("hentschel-wagner")
class HentschelWagner(Study):
    """H&W §7 (module doc). Applies when an ``adaptive-memory`` ran, or any localizer
    reported point classes (the first such is then the one under study)."""

    finding_keys = FINDING_KEYS

    def scenario_errors(self, scenario: Scenario, required: list[str]) -> list[tuple[str, str]]:
        if "adaptive-memory" in [loc.name for loc in scenario.localizers]:
            return []
        return [("expectations.findings", "the findings need a localizer named 'adaptive-memory'")]

    def applies(self, db: ResultsDB) -> bool:
        return find_subject(db) is not None

    def write(self, db: ResultsDB, out: Path) -> StudyReport:
        rep = StudyReport()
        data = load(db)
        for fig in (
            plot_point_shares(data, out / "hw_point_shares_per_day.png"),
            plot_error_per_day(data, out / "hw_error_per_day.png"),
            plot_class_scores(data, out / "hw_point_class_scores_per_day.png"),
        ):
            if fig is not None:
                rep.figures.append(fig)
        if data.subject is not None:
            loc, label = data.subject
            for day, fig_no in zip(LTM_DAYS, (5, 8), strict=True):
                d = ltm_day(db, loc, day)
                grid = ltm_grid(db, loc, day, data.bounds) if d is not None else None
                if grid is None or d is None or (day == 22 and d < 22):
                    continue
                geom = db.query(
                    "SELECT max(run) FROM runs WHERE day=?", (d,)
                )  # the day's last run's obstacles
                walls = db.geometry(d, int(geom[0][0])) if geom and geom[0][0] else None
                mem = route_memory_after(db, d) if fig_no == 8 else None
                rep.figures.append(
                    plot_ltm(
                        grid,
                        out / f"hw_ltm_day{day}.png",
                        f"{label}: long-term map after {week_label(d)}"
                        + (" with the route memory" if mem else "")
                        + f" (cf. H&W Fig. {fig_no})",
                        walls=None if walls is None else walls[0],
                        route_memory=None if mem is None else mem[1],
                    )
                )
        findings = evaluate(data)
        scores = write_class_scores(data, out / "hw_point_class_scores_per_day.csv")
        if scores is not None:
            rep.files.append(scores)
        rep.files += write_findings(findings, out, data.subject[1] if data.subject else None)
        rep.summary_lines = [
            "## Hentschel & Wagner §7.3 findings (also in hw_findings.md / hw_findings.json)",
            "",
            *findings_table(findings, paper=False),
        ]
        return rep

    def check(self, db: ResultsDB, keys: list[str]) -> list[FindingCheck]:
        by_key = {f.key: f for f in evaluate(load(db))}
        out = []
        for key in keys:
            f = by_key.get(key)
            out.append(
                FindingCheck(key, None if f is None else f.holds, "" if f is None else f.measured)
            )
        return out
