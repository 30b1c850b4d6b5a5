"""Localizer parameters are checked when the localizer is built (a scenario builds each one
when it is loaded): a bad value is an error naming the parameter and the value."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Annotated

import numpy as np
import pytest
from pydantic import TypeAdapter
from synthetic_scans import LASER

from dynmap_sim.agent.localization.dynamic_map_localizer import DynamicMapConfig
from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.agent.localization.particle_filter import TUNED, MCLConfig, StaticMCL
from dynmap_sim.agent.mapping.first_run import FirstRunConfig
from dynmap_sim.agent.params import (
    AsTuple,
    Fraction,
    NonNegative,
    NotNaN,
    int_range,
    params_dataclass,
)
from dynmap_sim.agent.params import build as build_params
from dynmap_sim.types import Prior


def build(name, **params):
    return make_localizer(name, laser=LASER, rng=np.random.default_rng(0), **params)


@pytest.mark.parametrize(
    ("overrides", "error", "message"),
    [
        ({"max_particles": -5}, ValueError, "max_particles must be an integer >= 1, got -5"),
        ({"max_particles": 0}, ValueError, "max_particles must be an integer >= 1, got 0"),
        ({"max_particles": "many"}, TypeError, "max_particles must be an integer, got 'many'"),
        ({"max_particles": 1.5}, TypeError, "max_particles must be an integer, got 1.5"),
        (
            {"max_particles": 1e9},
            ValueError,
            "max_particles must be an integer >= 1 and <= 1,000,000, got 1000000000",
        ),
        (
            {"min_particles": 9000},
            ValueError,
            "min_particles (9000) must be <= max_particles (8000)",
        ),
        ({"sigma_hit": 0}, ValueError, "sigma_hit must be a finite number > 0, got 0.0"),
        ({"sigma_hit": math.nan}, ValueError, "sigma_hit must be a finite number > 0, got nan"),
        ({"alpha1": math.nan}, ValueError, "alpha1 must be a finite number >= 0, got nan"),
        ({"alpha4": -1}, ValueError, "alpha4 must be a finite number >= 0, got -1.0"),
        ({"init_sigma_xy": math.inf}, ValueError, "init_sigma_xy must be a finite number >= 0"),
        (
            {"recovery_max_fraction": 2},
            ValueError,
            "recovery_max_fraction must be a number in [0, 1], got 2.0",
        ),
        ({"laser_model_type": "beam"}, ValueError, "laser_model_type must be one of"),
    ],
)
def test_static_mcl_overrides_are_checked(overrides, error, message):
    with pytest.raises(error) as ei:
        build("static-mcl", overrides=overrides)
    assert str(ei.value) == f"static-mcl: {message}" or str(ei.value).startswith(
        f"static-mcl: {message}"
    )


def test_static_mcl_map_and_flags_are_checked():
    for res in (0, -0.05):
        with pytest.raises(ValueError, match="mapper_params: resolution_m must be a finite"):
            build("static-mcl", mapper_params={"resolution_m": res})
    with pytest.raises(TypeError, match="global_localization must be true or false, got 'yes'"):
        build("static-mcl", global_localization="yes")
    # prior walls: the scenario is told (needs_prior_walls), the agent knows no scenario
    assert build("static-mcl", map_source="prior-walls").needs_prior_walls
    assert not build("static-mcl").needs_prior_walls


@pytest.mark.parametrize("name", ["dynamic-map", "static-map", "static-map+stm"])
@pytest.mark.parametrize(
    ("params", "error", "message"),
    [
        ({"max_match_points": 0}, ValueError, "max_match_points must be an integer >= 1, got 0"),
        ({"max_match_points": -3}, ValueError, "max_match_points must be an integer >= 1"),
        ({"sigma_max_m": math.nan}, ValueError, "sigma_max_m must be a finite number > 0, got nan"),
        ({"explained_density": -1}, ValueError, "explained_density must be a finite number >= 0"),
        ({"update_radius_m": -2.5}, ValueError, "update_radius_m must be a finite number > 0"),
        ({"min_update_dist_m": math.inf}, ValueError, "min_update_dist_m must be a finite"),
        ({"first_step_fills": "no"}, TypeError, "first_step_fills must be true or false"),
        ({"ltm_scans_per_run": "all"}, TypeError, "ltm_scans_per_run must be an integer"),
    ],
)
def test_dynamic_map_params_are_checked(name, params, error, message):
    with pytest.raises(error, match=f"^dynamic-map: {message}".replace("(", r"\(")):
        build(name, **params)


def test_dynamic_map_takes_the_first_runs_mapper_params():
    """``mapper_params`` reach the first run's SLAM of ``dynamic-map`` as of ``static-mcl``,
    checked when the localizer is built."""
    loc = build("dynamic-map", mapper_params={"anchored_local_map_radius_m": 0.0})
    assert loc.mapper_config.slam.anchored_local_map_radius_m == 0.0
    assert build("dynamic-map").mapper_config == FirstRunConfig()
    loc.begin_run(Prior(np.zeros(3), day=1, run=1, first_run=True))
    assert loc._mapper is not None and loc._mapper.config == loc.mapper_config
    with pytest.raises(TypeError, match=r"mapper_params: unknown parameters \['radius'\]"):
        build("dynamic-map", mapper_params={"radius": 3.0})
    with pytest.raises(ValueError, match="mapper_params: resolution_m must be a finite"):
        build("static-map", mapper_params={"resolution_m": -1.0})


def test_the_shipped_configs_and_defaults_pass_and_keep_their_types():
    assert MCLConfig() == MCLConfig(**{f: getattr(MCLConfig(), f) for f in vars(MCLConfig())})
    cfg = MCLConfig(max_particles=8000.0, sigma_hit=1)  # TOML 8000.0 and 1 (a benchmark's floats)
    assert type(cfg.max_particles) is int and type(cfg.sigma_hit) is float
    assert TUNED.recovery_floor_loglik == -0.5 and math.isinf(MCLConfig().recovery_floor_loglik)
    DynamicMapConfig()
    FirstRunConfig.from_params(resolution_m=0.1)
    assert isinstance(build("static-mcl", config="nav2-default"), StaticMCL)


def test_one_helper_checks_every_config():
    @params_dataclass("mine")
    class Cfg:
        n: int_range(1, 10) = 3
        x: NonNegative = 1.0
        share: Fraction = 0.5
        floor: NotNaN = -1.0
        flags: Annotated[tuple[bool, ...], AsTuple] = (True,)
        pair: Annotated[tuple[float, float], AsTuple] = (1.0, 2.0)

    cfg = Cfg(n=np.int64(4), x=np.float32(2), floor=-math.inf, flags=[True, False], pair=[1, 2])
    assert cfg.flags == (True, False) and cfg.pair == (1.0, 2.0) and type(cfg.pair[0]) is float
    assert type(cfg.n) is int and type(cfg.x) is float and replace(cfg, n=5.0).n == 5
    for kwargs, message in (
        ({"n": 0}, "mine: n must be an integer >= 1, got 0"),
        ({"n": 11}, "mine: n must be an integer >= 1 and <= 10, got 11"),
        ({"n": True}, "mine: n must be an integer, got True"),
        ({"x": -1e-9}, "mine: x must be a finite number >= 0, got -1e-09"),
        ({"x": "1"}, "mine: x must be a number, got '1'"),
        ({"share": 1.5}, "mine: share must be a number in [0, 1], got 1.5"),
        ({"floor": math.nan}, "mine: floor must be a number (not NaN), got nan"),
        ({"flags": "yes"}, "mine: flags must be a list, got 'yes'"),
        ({"flags": [2]}, "mine: flags must be true or false, got 2"),
        ({"nn": 1, "m": 2}, "mine: unknown parameters ['m', 'nn']; known: flags, floor, n, pair, "
         "share, x"),
    ):  # fmt: skip
        with pytest.raises((TypeError, ValueError)) as ei:
            Cfg(**kwargs)
        assert str(ei.value) == message
    with pytest.raises(ValueError, match="^theirs: n must be an integer >= 1"):
        build_params(Cfg, {"n": 0}, "theirs")
    schema = TypeAdapter(Cfg).json_schema()
    assert schema["additionalProperties"] is False
    assert schema["properties"]["n"] == {
        "default": 3, "maximum": 10, "minimum": 1, "title": "N", "type": "integer"
    }  # fmt: skip
