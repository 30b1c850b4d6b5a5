"""Benchmarks over many worlds: one scenario template run on generated and given worlds.

A **suite** file names worlds — generator kinds × generator seeds, and/or world files — the
days, the run seeds and a scenario template (the driver, robot, sensor, prior and the
localizers every world's experiment runs). The benchmark writes each world file into
``OUT/worlds/`` and a scenario per world into ``OUT/scenarios/`` (so any one world re-runs
alone with ``dynmap-sim run OUT/scenarios/<world>.toml``), validates all of them before
anything runs, and runs them as the cells of a sweep (:mod:`.sweep`: a local process pool or
a Dask cluster, resumed after a kill by skipping finished cells) into ``OUT/runs/``. The
leaderboard (:mod:`dynmap_sim.analysis.leaderboard`) reads the cells.

Suite files (TOML, validated: file, field and message)::

    name = "generalization"
    days = "1-5"                 # of every world's calendar
    seeds = [0]                  # run seeds (noise, people) of every world; default [0]
    baseline = "static-mcl tuned"  # label the paired differences are taken against

    [worlds]
    kinds = ["apartment", "office", "lab", "hall"]
    seeds = "1000-1005"          # generator seeds, for every kind
    files = ["../../worlds/office.toml"]  # world files, relative to this file
    params = { people = 4 }      # generator parameters for every kind

    [scenario]                   # a scenario file's tables, without name, world and days
    driver = { kind = "tour" }
    prior = { map = "walls", initial_pose = "known" }
    [[scenario.localizers]]
    name = "static-mcl"
    label = "static-mcl tuned"
    params = { config = "tuned" }
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from dynmap_sim import toml_writer
from dynmap_sim.errors import FileError, InputError, pydantic_errors, read_toml
from dynmap_sim.experiments.scenario import ParamValue, Scenario, load_scenario
from dynmap_sim.experiments.sweep import (
    SweepOutcome,
    SweepSpec,
    parse_day_range,
    parse_seeds,
    run_sweep,
    seeds_text,
)

#: The benchmark's own record in its folder: the suite it runs and its worlds.
BENCHMARK_INDEX = "benchmark.json"
#: Layout of :data:`BENCHMARK_INDEX`.
BENCHMARK_FORMAT = 1
#: Most worlds one suite may name (a typo in a seed range should not generate a million).
MAX_WORLDS = 2_000
#: Scenario fields a suite's template may not set: the benchmark sets them per world.
PER_WORLD_FIELDS = ("name", "world", "days", "seeds")


class SuiteFileError(FileError):
    """All the problems of one suite file (file + dotted field path + message)."""


class _WorldsModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    kinds: list[str] = Field(default_factory=list, description="generator kinds")
    seeds: str | int | list[int] | None = Field(None, description="generator seeds, '0-5'")
    files: list[str] = Field(default_factory=list, description="world files (relative here)")
    params: dict[str, ParamValue] = Field(
        default_factory=dict, description="generator parameters for every kind"
    )


class _SuiteModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str | None = Field(None, min_length=1, description="the suite's name")
    description: str = ""
    days: str | int | list[int] = Field(description="days of every world, '1-5' or [1, 5]")
    seeds: str | int | list[int] = Field(default="0", description="run seeds of every world")
    baseline: str | None = Field(None, description="label of the paired differences' baseline")
    worlds: _WorldsModel
    scenario: dict[str, Any] = Field(description="the scenario template")

    @field_validator("days")
    @classmethod
    def _days(cls, v: Any) -> Any:
        parse_day_range(v)
        return v

    @field_validator("scenario")
    @classmethod
    def _template(cls, v: dict[str, Any]) -> dict[str, Any]:
        fixed = [k for k in PER_WORLD_FIELDS if k in v]
        if fixed:
            raise ValueError(f"{', '.join(fixed)}: set per world by the benchmark; leave out")
        return v


@dataclass(frozen=True)
class WorldRef:
    """One world of a suite: generated (``kind``, ``seed``, ``params``) or a ``file``."""

    name: str
    kind: str | None = None
    seed: int | None = None
    params: tuple[tuple[str, ParamValue], ...] = ()
    file: Path | None = None

    def record(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "seed": self.seed,
            "params": dict(self.params),
            "file": None if self.file is None else str(self.file),
        }


@dataclass(frozen=True)
class Suite:
    """A validated suite file."""

    name: str
    path: Path
    days: tuple[int, int]
    run_seeds: tuple[int, ...]
    baseline: str | None
    worlds: tuple[WorldRef, ...]
    template: dict[str, Any]
    description: str = ""

    def identity(self) -> str:
        """A hash of what the suite runs (its worlds, days, seeds and template)."""
        blob = json.dumps(
            {
                "days": list(self.days),
                "seeds": list(self.run_seeds),
                "worlds": [w.record() for w in self.worlds],
                "template": self.template,
            },
            sort_keys=True,
            default=str,
        )
        return hashlib.sha256(blob.encode()).hexdigest()


def load_suite(path: str | Path, kinds: tuple[str, ...] = ()) -> Suite:
    """A suite file (:class:`SuiteFileError` listing every problem with its field).
    ``kinds``: the generator kinds there are (an unknown one is an error of its field)."""
    p = Path(path)
    raw = read_toml(p, SuiteFileError)
    try:
        m = _SuiteModel.model_validate(raw)
    except ValidationError as exc:
        raise SuiteFileError(p, pydantic_errors(exc)) from None
    errors: list[tuple[str, str]] = []
    worlds: list[WorldRef] = []
    for i, kind in enumerate(m.worlds.kinds):
        if kinds and kind not in kinds:
            errors.append((f"worlds.kinds.{i}", f"no generator kind {kind!r}; kinds: {kinds}"))
    gen_seeds: tuple[int, ...] = ()
    if m.worlds.kinds and m.worlds.seeds is None:
        errors.append(("worlds.seeds", "generator kinds need seeds, e.g. '0-5'"))
    elif m.worlds.seeds is not None:
        try:
            gen_seeds = parse_seeds(seeds_text(m.worlds.seeds), "worlds.seeds")
        except InputError as exc:
            errors.append(("worlds.seeds", str(exc).removeprefix("worlds.seeds: ")))
    params = tuple(sorted(m.worlds.params.items()))
    for kind in m.worlds.kinds:
        worlds += [WorldRef(f"{kind}-{s}", kind, s, params) for s in gen_seeds]
    for i, ref in enumerate(m.worlds.files):
        f = Path(ref) if Path(ref).is_absolute() else p.parent / ref
        if not f.is_file():
            errors.append((f"worlds.files.{i}", f"no world file {ref!r} (looked for {f})"))
        worlds.append(WorldRef(f.stem, file=f.resolve()))
    names = [w.name for w in worlds]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        errors.append(("worlds", f"two worlds are named {', '.join(dupes)}"))
    if not worlds and not errors:
        errors.append(("worlds", "names no world: give kinds and seeds, or files"))
    if len(worlds) > MAX_WORLDS:
        errors.append(("worlds", f"{len(worlds)} worlds; at most {MAX_WORLDS} in one suite"))
    try:
        run_seeds = parse_seeds(seeds_text(m.seeds), "seeds")
    except InputError as exc:
        errors.append(("seeds", str(exc).removeprefix("seeds: ")))
        run_seeds = ()
    if errors:
        raise SuiteFileError(p, errors)
    return Suite(
        name=m.name or p.stem,
        path=p.resolve(),
        days=parse_day_range(m.days),
        run_seeds=run_seeds,
        baseline=m.baseline,
        worlds=tuple(worlds),
        template=dict(m.scenario),
        description=m.description,
    )


# ---------------------------------------------------------------------- the folder
#: Makes a generated world's file text: ``(kind, seed, params) -> TOML``.
WorldMaker = Callable[[str, int, dict[str, ParamValue]], str]


def _world_text(w: WorldRef, suite: Suite, make_world: WorldMaker) -> str:
    if w.file is not None:
        return w.file.read_text(encoding="utf-8")
    assert w.kind is not None and w.seed is not None
    params = {"days": suite.days[1], **dict(w.params)}
    return make_world(w.kind, w.seed, params)


def _scenario_text(w: WorldRef, suite: Suite) -> str:
    data = {
        "name": f"{suite.name}-{w.name}",
        "description": f"{suite.name}: {w.name}, days {suite.days[0]}-{suite.days[1]}",
        "world": f"../worlds/{w.name}.toml",
        "days": list(suite.days),
        "seeds": list(suite.run_seeds),
        **suite.template,
    }
    header = [f"Benchmark suite {suite.name} ({suite.path.name}), world {w.name}."]
    return toml_writer.dumps(data, header)


def _check_folder(out: Path, suite: Suite) -> dict[str, Any] | None:
    """The folder's benchmark record when it holds this suite; None when it is new or empty;
    InputError for a folder of anything else."""
    index = out / BENCHMARK_INDEX
    if index.is_file():
        try:
            old = json.loads(index.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{index}: unreadable ({exc}); choose another --out") from None
        if old.get("suite_hash") != suite.identity():
            raise InputError(
                f"{out} holds another benchmark ({old.get('name')!r}); this suite differs: "
                "choose another --out (the same command resumes a benchmark)"
            )
        return old
    if out.exists() and any(out.iterdir()):
        raise InputError(f"{out} is not empty and holds no benchmark; choose another --out")
    return None


def prepare_benchmark(suite: Suite, out_dir: str | Path, make_world: WorldMaker) -> list[Scenario]:
    """Write the suite's worlds and scenarios into ``out_dir`` (or check that the ones there
    are the same) and return the scenarios, every one validated before anything is kept: a
    world or scenario that does not validate leaves the folder as it was."""
    out = Path(out_dir)
    old = _check_folder(out, suite)
    texts = {
        w.name: (_world_text(w, suite, make_world), _scenario_text(w, suite)) for w in suite.worlds
    }
    if old is not None:
        for name, (world, scenario) in texts.items():
            for sub, text in (("worlds", world), ("scenarios", scenario)):
                f = out / sub / f"{name}.toml"
                if not f.is_file() or f.read_text(encoding="utf-8") != text:
                    raise InputError(
                        f"{f}: not what this suite makes now (the generator or the file "
                        "changed since the benchmark began): choose another --out"
                    )
        return [load_scenario(out / "scenarios" / f"{n}.toml") for n in texts]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {out}: {exc.strerror or exc}") from None
    staging = out / f".staging-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        for sub in ("worlds", "scenarios"):
            (staging / sub).mkdir(parents=True)
        for name, (world, scenario) in texts.items():
            (staging / "worlds" / f"{name}.toml").write_text(world, encoding="utf-8")
            (staging / "scenarios" / f"{name}.toml").write_text(scenario, encoding="utf-8")
        for name in texts:  # every scenario (and its world) validates, or nothing is kept
            _validate(staging / "scenarios" / f"{name}.toml", name, suite)
        for sub in ("worlds", "scenarios"):
            os.replace(staging / sub, out / sub)
        record = {
            "format": BENCHMARK_FORMAT,
            "name": suite.name,
            "suite": str(suite.path),
            "suite_hash": suite.identity(),
            "baseline": suite.baseline,
            "days": list(suite.days),
            "seeds": list(suite.run_seeds),
            "worlds": [w.record() for w in suite.worlds],
        }
        (out / BENCHMARK_INDEX).write_text(json.dumps(record, indent=1) + "\n")
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return [load_scenario(out / "scenarios" / f"{n}.toml") for n in texts]


def _validate(scenario: Path, world: str, suite: Suite) -> None:
    """A world's scenario as the benchmark wrote it loads; else the suite's error, naming
    the world and the field (the template's fields are the suite's ``scenario.*``)."""
    try:
        load_scenario(scenario)
    except FileError as exc:
        where = "scenario" if exc.path == str(scenario) else f"world {world}"
        raise SuiteFileError(
            suite.path,
            [(f"{where}.{f}".rstrip("."), f"{m} (world {world})") for f, m in exc.errors],
        ) from None


def read_benchmark(out_dir: str | Path) -> dict[str, Any]:
    """The record of a benchmark folder (InputError when it is not one)."""
    index = Path(out_dir) / BENCHMARK_INDEX
    if not index.is_file():
        raise InputError(f"{out_dir}: not a benchmark folder (no {BENCHMARK_INDEX})")
    try:
        return json.loads(index.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{index}: unreadable ({exc})") from None


def run_benchmark(
    suite: Suite,
    out_dir: str | Path,
    make_world: WorldMaker,
    workers: int | None = None,
    cluster: str | None = None,
    progress: bool = True,
    note: Callable[[str], None] | None = None,
) -> SweepOutcome:
    """Prepare ``out_dir`` (:func:`prepare_benchmark`) and run every world's experiment as a
    cell of a sweep in ``out_dir/runs`` (resuming the finished ones)."""
    scenarios = prepare_benchmark(suite, out_dir, make_world)
    spec = SweepSpec(scenarios=tuple(scenarios), seeds=suite.run_seeds, name=suite.name)
    return run_sweep(
        spec, Path(out_dir) / "runs", workers=workers, cluster=cluster, progress=progress, note=note
    )
