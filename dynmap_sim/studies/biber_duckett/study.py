"""Biber & Duckett 2009 §5 as a :class:`~dynmap_sim.studies.study.Study`: the Figs. 10–13
look-alikes, the exhibition in the timescales (Fig. 9), the map structure against the truth
(§5.2) and the paper's findings checked on the experiment."""

from __future__ import annotations

from pathlib import Path

from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.scenario import Scenario
from dynmap_sim.studies.biber_duckett.exhibition import plot_exhibition
from dynmap_sim.studies.biber_duckett.figures import write_dynamic_figures
from dynmap_sim.studies.biber_duckett.findings import (
    FINDING_KEYS,
    findings_table,
    measure_findings,
    write_findings,
)
from dynmap_sim.studies.biber_duckett.map_structure import (
    plot_map_structure,
    write_map_structure_csv,
)
from dynmap_sim.studies.study import FindingCheck, Study, StudyReport, register_study

#: The localizers of the paper: the dynamic map and its two static baselines (§5.2).
SAMPLE_BASED = ("dynamic-map", "static-map", "static-map+stm")


@register_study("biber-duckett")
class BiberDuckett(Study):
    """B&D §5 (module doc). Its findings need a ``dynamic-map`` in the experiment."""

    finding_keys = FINDING_KEYS

    def scenario_errors(self, scenario: Scenario, required: list[str]) -> list[tuple[str, str]]:
        if "dynamic-map" in [loc.name for loc in scenario.localizers]:
            return []
        return [("expectations.findings", "the findings need a localizer named 'dynamic-map'")]

    def applies(self, db: ResultsDB) -> bool:
        names = {r[0] for r in db.query("SELECT name FROM localizers")}
        # or any localizer that selects timescales (Figs. 10-13 apply to it)
        return bool(names & set(SAMPLE_BASED)) or bool(
            db.query("SELECT 1 FROM estimates WHERE timescale >= 0 LIMIT 1")
        )

    def write(self, db: ResultsDB, out: Path) -> StudyReport:
        rep = StudyReport()
        # Figs. 10-13 per day and overall, for localizers that report those values
        rep.figures += write_dynamic_figures(out)
        # §5 claims, Fig. 9 and §5.2 against the truth, when a dynamic-map ran
        findings, exhibition, structure = measure_findings(db)
        if exhibition is not None:
            mem, snaps, geom, ex_days = exhibition
            rep.figures.append(plot_exhibition(mem, snaps, geom, ex_days, out / "exhibition.png"))
        if structure is not None:
            rep.figures.append(plot_map_structure(structure, out / "map_structure.png"))
            rep.files.append(write_map_structure_csv(structure, out / "map_structure.csv"))
        if findings is not None:
            rep.files += write_findings(findings, out)
            rep.summary_lines = [
                "## Biber & Duckett §5 findings (also in findings.md / findings.json)",
                "",
                *findings_table(findings, paper=False),
            ]
        return rep

    def check(self, db: ResultsDB, keys: list[str]) -> list[FindingCheck]:
        findings, _, _ = measure_findings(db)
        by_key = {f.key: f for f in findings or []}
        out = []
        for key in keys:
            f = by_key.get(key)
            out.append(
                FindingCheck(key, None if f is None else f.holds, "" if f is None else f.measured)
            )
        return out
