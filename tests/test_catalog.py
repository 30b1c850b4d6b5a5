"""`dynmap-sim list`: what ships, one line each."""

from __future__ import annotations

import pytest

from dynmap_sim import cli
from dynmap_sim.agent.localization.localizer import LOCALIZERS
from dynmap_sim.catalog import SECTIONS, catalog, catalog_text
from dynmap_sim.registration import WORLDS_DIR


def test_every_shipped_world_scenario_and_registered_name_is_listed_with_a_line() -> None:
    got = catalog()
    assert tuple(got) == SECTIONS == cli.LIST_SECTIONS
    assert [e.name for e in got["worlds"]] == sorted(p.stem for p in WORLDS_DIR.glob("*.toml"))
    assert {"ci-apartment", "apartment-28d"} <= {e.name for e in got["scenarios"]}
    assert [e.name for e in got["localizers"]] == LOCALIZERS.names()
    assert {"tour", "autonomous"} <= {e.name for e in got["drivers"]}
    for section, entries in got.items():
        assert entries, section
        for e in entries:  # one plain line: no reST markup, no line breaks
            assert e.summary and "\n" not in e.summary and "``" not in e.summary, (section, e)
            assert ":class:" not in e.summary


def test_sections_are_chosen_by_name_and_a_bad_one_is_refused(capsys) -> None:
    assert cli.main(["list", "planners"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("planners:\n") and "grid-astar" in out and "worlds:" not in out
    with pytest.raises(SystemExit) as exc:
        cli.main(["list", "bogus"])
    assert exc.value.code == 2
    assert "no section 'bogus'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown section"):
        catalog(("bogus",))
    assert catalog_text({}) == ""
