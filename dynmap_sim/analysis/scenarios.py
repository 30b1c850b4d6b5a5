"""Scenario files as the analysis reads them: the engine's validation plus the expectations
only analysis can judge (required findings belong to the paper studies)."""

from __future__ import annotations

from pathlib import Path

from dynmap_sim.experiments.scenario import Scenario
from dynmap_sim.experiments.scenario import load_scenario as load_engine_scenario
from dynmap_sim.studies.study import all_studies


def findings_errors(scenario: Scenario) -> list[tuple[str, str]]:
    """Required findings that no study defines, and each study's own conditions on them."""
    studies = all_studies()
    known = [k for s in studies for k in s.finding_keys]
    errors = [
        (f"expectations.findings.{i}", f"unknown finding {key!r}; known: {', '.join(known)}")
        for i, key in enumerate(scenario.expectations.findings)
        if key not in known
    ]
    for study in studies:
        mine = [k for k in scenario.expectations.findings if k in study.finding_keys]
        if mine:
            errors += study.scenario_errors(scenario, mine)
    return errors


def load_scenario(path: str | Path) -> Scenario:
    """Load and validate a scenario file, required findings included (ScenarioFileError
    listing every problem with its field)."""
    return load_engine_scenario(path, checks=(findings_errors,))
