"""Helpers for users' own test suites: scenario files as regression tests.

In a pytest file::

    from dynmap_sim.testing import run_scenario

    def test_my_localizer_keeps_up():
        run_scenario("scenarios/my-ci.toml")   # raises AssertionError with the table on failure
"""

from __future__ import annotations

from pathlib import Path

from dynmap_sim.analysis.check import CheckResult, check_scenario


def run_scenario(
    path: str | Path, out_dir: str | Path | None = None, progress: bool = False
) -> CheckResult:
    """Run a scenario and check its expectations (same code path as ``dynmap-sim check``).

    Returns the :class:`CheckResult`; raises ``AssertionError`` with the pass/fail table when
    any expectation fails.
    """
    result = check_scenario(path, out_dir=out_dir, progress=progress)
    if not result.passed:
        raise AssertionError("scenario expectations failed\n" + result.table())
    return result
