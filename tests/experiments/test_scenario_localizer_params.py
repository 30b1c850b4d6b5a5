"""Bad localizer parameters in a scenario file are errors with the file and the field when the
scenario is loaded (they used to validate and then crash the run)."""

from __future__ import annotations

import pytest

from dynmap_sim.experiments.scenario import ScenarioFileError, load_scenario

HEAD = """
name = "x"
world = "apartment"
days = [1, 2]
"""


def errors_of(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(HEAD + text)
    with pytest.raises(ScenarioFileError) as ei:
        load_scenario(p)
    assert str(p) in str(ei.value)
    return dict(ei.value.errors)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ("overrides = { max_particles = -5 }", "max_particles must be an integer >= 1, got -5"),
        ('overrides = { max_particles = "many" }', "max_particles must be an integer, got 'many'"),
        ("overrides = { max_particles = 1.5 }", "max_particles must be an integer, got 1.5"),
        ("overrides = { max_particles = 1e9 }", "<= 1,000,000, got 1000000000"),
        ("overrides = { min_particles = 9000 }", "min_particles (9000) must be <= max_particles"),
        ("overrides = { sigma_hit = nan }", "sigma_hit must be a finite number > 0, got nan"),
        ("overrides = { alpha1 = -1 }", "alpha1 must be a finite number >= 0, got -1.0"),
        ("mapper_params = { resolution_m = 0 }", "resolution_m must be a finite number > 0"),
    ],
)
def test_static_mcl_params_are_checked_on_load(tmp_path, params, message):
    errs = errors_of(
        tmp_path,
        f'[[localizers]]\nname = "odometry"\n[[localizers]]\nname = "static-mcl"\n'
        f"params = {{ {params} }}\n",
    )
    assert list(errs) == ["localizers.1.params"]
    assert errs["localizers.1.params"].startswith("rejected by 'static-mcl': static-mcl: ")
    assert message in errs["localizers.1.params"]


def test_dynamic_map_params_are_checked_on_load(tmp_path):
    errs = errors_of(
        tmp_path, '[[localizers]]\nname = "dynamic-map"\nparams = { max_match_points = 0 }\n'
    )
    assert errs == {
        "localizers.0.params": "rejected by 'dynamic-map': dynamic-map: max_match_points must "
        "be an integer >= 1, got 0"
    }


def test_a_map_from_the_prior_walls_needs_a_prior_with_walls(tmp_path):
    loc = '[[localizers]]\nname = "static-mcl"\nparams = { map_source = "prior-walls" }\n'
    errs = errors_of(tmp_path, '[prior]\nmap = "none"\n' + loc)
    assert errs == {
        "localizers.0.params": "'static-mcl' makes its map from the prior's walls, but "
        "prior.map is 'none': set [prior] map = \"walls\" (or another map_source)"
    }
    p = tmp_path / "ok.toml"
    p.write_text(HEAD + '[prior]\nmap = "walls"\n' + loc)
    assert load_scenario(p).localizers[0].params == {"map_source": "prior-walls"}
