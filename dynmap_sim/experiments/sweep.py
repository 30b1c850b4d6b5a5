"""Sweeps: one experiment per cell of scenarios × seeds × localizer parameter values.

A sweep names scenario files, seeds, optionally a day range, the localizers to keep and
parameter values to try (``LABEL.KEY = [V1, V2]``: the parameter ``KEY`` of the localizer
labelled ``LABEL``). Every combination is a **cell**: a scenario resolved for one seed, the
days and one value of each parameter, validated like a scenario file before anything runs,
and keyed by the hash of that resolved configuration (:func:`~.runner.experiment_hash`: the
resolved scenario's content with the overridden parameters, its world file, the seed and the
days). Each cell writes its own results folder ``DIR/cells/<key[:16]>/`` (a ``results.db``
like ``dynmap-sim run``'s) and ``DIR/sweep.json`` indexes the cells with their status
(``done``, ``failed`` with the error, or ``pending``).

A sweep **resumes**: a cell whose results folder holds a complete experiment with its key is
skipped; an unfinished one continues from its last stored run (the runner's checkpoint), so a
killed sweep ends with exactly the numbers of an unbroken one. A failed cell is recorded and
the others go on; running the sweep again retries it.

Cells run on a :class:`concurrent.futures.Executor`: a local process pool by default, or a
Dask distributed cluster (``cluster="tcp://HOST:PORT"``, extra ``cluster``) through
``Client.get_executor(pure=False)`` (``pure=True``, Dask's default, would merge identical
calls). The cluster's workers need dynmap_sim installed and the scenario files and ``DIR``
at the same paths (a shared file system). Each cell runs its localizers in its own process
(``workers=1``): the cells are the parallelism.

Sweep files (TOML, validated like scenarios: file, field and message)::

    name = "apartment-week"
    scenarios = ["../scenarios/apartment-28d.toml"]   # relative to this file
    seeds = "0-3"                                     # or [0, 1, 2, 3]
    days = "1-7"                                      # default: each scenario's days
    localizers = ["static-mcl tuned", "dynamic-map"]  # keep only these labels (default: all)

    [set]                                             # LABEL.KEY = [values]
    "static-mcl tuned.config" = ["tuned", "nav2-default"]
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import os
import tempfile
import time
import tomllib
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from dynmap_sim.errors import FileError, InputError, pydantic_errors, read_toml
from dynmap_sim.experiments.localizer_pool import WORKER_THREAD_ENV
from dynmap_sim.experiments.results import DB_NAME, FolderLock, ResultsDB
from dynmap_sim.experiments.runner import experiment_hash, run_experiment
from dynmap_sim.experiments.scenario import (
    MAX_SEED,
    ParamValue,
    Scenario,
    ScenarioFileError,
    load_scenario,
    parse_scenario,
)

#: The sweep's index of cells in its folder.
SWEEP_INDEX = "sweep.json"
#: The folder of the cells' results folders (``cells/<key[:16]>``).
CELLS_DIR = "cells"
#: The layout of ``sweep.json``.
SWEEP_FORMAT = 1
#: Characters of the cell key in its folder name (64 bits: no collision in any sweep).
KEY_CHARS = 16
#: Most cells a sweep may have (a typo in a seed range should not queue a million runs).
MAX_CELLS = 10_000


class SweepFileError(FileError):
    """All the problems of one sweep file (file + dotted field path + message)."""


# ---------------------------------------------------------------------- arguments
def parse_value(text: str) -> ParamValue:
    """A parameter value from the command line: a TOML number or boolean, else the text as
    a string (``tuned``, ``0.5``, ``true``, ``200``)."""
    t = text.strip()
    try:
        v = tomllib.loads(f"v = {t}")["v"]
    except tomllib.TOMLDecodeError:
        return t
    if isinstance(v, bool | int | float | str):
        return v
    return t


@dataclass(frozen=True)
class Setting:
    """The values to try for one localizer parameter: ``LABEL.KEY = V1, V2, ...``."""

    label: str
    key: str
    values: tuple[ParamValue, ...]

    @property
    def name(self) -> str:
        return f"{self.label}.{self.key}"


def _split_name(name: str, where: str) -> tuple[str, str]:
    """``LABEL.KEY`` into its label and key (the key after the last dot: labels may hold
    dots and spaces, keys are identifiers)."""
    label, dot, key = name.rpartition(".")
    if not dot or not label.strip() or not key.isidentifier():
        raise InputError(
            f"{where}: expected LABEL.KEY (a localizer's label, a dot, a parameter name), "
            f"not {name!r}"
        )
    return label.strip(), key


def parse_set(text: str) -> Setting:
    """``--set LABEL.KEY=V1,V2``; InputError naming the argument."""
    where = f"--set {text}"
    name, eq, values = text.partition("=")
    if not eq:
        raise InputError(f"{where}: expected LABEL.KEY=V1,V2,... (no '=')")
    label, key = _split_name(name, where)
    parts = [v.strip() for v in values.split(",")]
    if not values.strip() or any(not p for p in parts):
        raise InputError(f"{where}: empty value; give comma-separated values, e.g. {name}=a,b")
    vals = tuple(parse_value(p) for p in parts)
    if len(set(map(repr, vals))) != len(vals):
        raise InputError(f"{where}: a value is given twice")
    return Setting(label, key, vals)


def parse_seeds(text: str, where: str = "--seeds") -> tuple[int, ...]:
    """Seeds as ``0-3`` (inclusive), ``0,2,5`` or ``7`` (each in 0..2**63-1, distinct)."""
    seeds: list[int] = []
    for part in text.split(","):
        a, dash, b = part.strip().partition("-")
        try:
            lo, hi = int(a), int(b if dash else a)
        except ValueError:
            raise InputError(f"{where}: seeds look like 0-3, 0,2,5 or 7, not {text!r}") from None
        if not 0 <= lo <= hi <= MAX_SEED:
            raise InputError(f"{where}: bad seed range {part.strip()!r} (0 <= first <= last)")
        if hi - lo >= MAX_CELLS:
            raise InputError(f"{where}: {part.strip()!r} holds over {MAX_CELLS} seeds")
        seeds += range(lo, hi + 1)
    if len(set(seeds)) != len(seeds):
        raise InputError(f"{where}: a seed is given twice in {text!r}")
    return tuple(seeds)


# ---------------------------------------------------------------------- the sweep
@dataclass(frozen=True)
class SweepSpec:
    """What to sweep: scenarios (loaded), seeds, days (None: each scenario's), parameter
    settings and the localizer labels to keep (None: all)."""

    scenarios: tuple[Scenario, ...]
    seeds: tuple[int, ...]
    days: tuple[int, int] | None = None
    settings: tuple[Setting, ...] = ()
    only: tuple[str, ...] | None = None
    name: str = "sweep"


@dataclass(frozen=True, eq=False)
class Cell:
    """One experiment of a sweep: a resolved scenario (its data, as validated), a seed and
    days, keyed by :func:`~.runner.experiment_hash` of them."""

    key: str
    scenario: str
    scenario_path: str | None
    seed: int
    days: tuple[int, int]
    overrides: tuple[tuple[str, ParamValue], ...]
    localizers: tuple[str, ...]
    data: dict[str, Any] = field(repr=False)

    @property
    def dir_name(self) -> str:
        return self.key[:KEY_CHARS]

    @property
    def variant(self) -> str:
        """The parameter values of this cell, ``LABEL.KEY=V; ...`` ('' when none)."""
        return "; ".join(f"{n}={_show(v)}" for n, v in self.overrides)

    def index_entry(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "dir": f"{CELLS_DIR}/{self.dir_name}",
            "scenario": self.scenario,
            "scenario_path": self.scenario_path,
            "seed": self.seed,
            "days": list(self.days),
            "variant": self.variant,
            "overrides": {n: v for n, v in self.overrides},
            "localizers": list(self.localizers),
        }


def _show(v: ParamValue) -> str:
    return v if isinstance(v, str) else json.dumps(v)


def _select(data: dict[str, Any], only: Sequence[str], where: str) -> dict[str, Any]:
    """The scenario data with only the localizers labelled ``only`` (and their
    expectations); the driver's localizer must stay."""
    locs = [c for c in data["localizers"] if (c.get("label") or c["name"]) in only]
    if not locs:
        raise InputError(f"{where}: keeps none of its localizers")
    kept = [c.get("label") or c["name"] for c in locs]
    steer = (data.get("driver") or {}).get("localizer")
    if steer is not None and steer not in kept:
        raise InputError(f"{where}: the driver steers on {steer!r}; keep that localizer too")
    exp = dict(data.get("expectations") or {})
    exp["localizers"] = {k: v for k, v in (exp.get("localizers") or {}).items() if k in kept}
    return {**data, "localizers": locs, "expectations": exp}


def _resolve_scenario(
    scn: Scenario, days: tuple[int, int], seeds: Sequence[int], only: Sequence[str] | None
) -> dict[str, Any]:
    """A scenario's data for the sweep: its days and seeds, the kept localizers, and the
    kidnappings of those days."""
    data = scn.model_dump(mode="json")
    if scn.source_path is None:  # built in code: the world by its resolved path
        data["world"] = str(scn.world_path)
    data["days"] = list(days)
    data["seeds"] = list(seeds)
    data["kidnappings"] = [k for k in data["kidnappings"] if days[0] <= k["day"] <= days[1]]
    if only is not None:
        data = _select(data, only, f"{_where(scn)} with --only {', '.join(only)}")
    return data


def _where(scn: Scenario) -> str:
    return str(scn.source_path) if scn.source_path is not None else scn.name


def _labels(data: dict[str, Any]) -> list[str]:
    return [c.get("label") or c["name"] for c in data["localizers"]]


def resolve_cells(spec: SweepSpec) -> list[Cell]:
    """Every cell of ``spec``, validated (InputError naming the argument or the file and
    field of what is wrong) and in a stable order: scenario, parameter values, seed.
    Parameters of a label a scenario lacks do not vary its cells; equal cells are one."""
    if not spec.scenarios:
        raise InputError("a sweep needs at least one scenario")
    if not spec.seeds:
        raise InputError("a sweep needs at least one seed")
    names = [s.name for s in spec.settings]
    for n in names:
        if names.count(n) > 1:
            raise InputError(f"--set {n}: given twice; list all its values in one --set")
    if spec.only is not None:
        every = {lab for scn in spec.scenarios for lab in scn.labels}
        for lab in spec.only:
            if lab not in every:
                raise InputError(
                    f"--only {lab}: no scenario has a localizer labelled {lab!r} "
                    f"(labels: {', '.join(sorted(every))})"
                )
    resolved = []
    for scn in spec.scenarios:
        days = spec.days or scn.days
        resolved.append((scn, days, _resolve_scenario(scn, days, spec.seeds, spec.only)))
    all_labels = {lab for _, _, d in resolved for lab in _labels(d)}
    for s in spec.settings:
        if s.label not in all_labels:
            raise InputError(
                f"--set {s.name}: no {'kept ' if spec.only else ''}localizer is labelled "
                f"{s.label!r} (labels: {', '.join(sorted(all_labels))})"
            )
    cells: dict[str, Cell] = {}
    combos = list(itertools.product(*[[(s, v) for v in s.values] for s in spec.settings]))
    if len(combos) * len(spec.seeds) * len(spec.scenarios) > MAX_CELLS:
        raise InputError(f"the sweep has over {MAX_CELLS} cells; sweep less at a time")
    for scn, days, base in resolved:
        labels = _labels(base)
        for combo in combos:
            applied = tuple((s, v) for s, v in combo if s.label in labels)
            data = json.loads(json.dumps(base))
            for s, v in applied:
                loc = data["localizers"][labels.index(s.label)]
                loc["params"] = {**(loc.get("params") or {}), s.key: v}
            resolved_scn = _validate(scn, data, applied)
            for seed in spec.seeds:
                one = resolved_scn.model_copy(update={"seeds": [seed]})
                key = experiment_hash(one, seed, days)
                if key in cells:
                    continue
                cells[key] = Cell(
                    key=key,
                    scenario=scn.name,
                    scenario_path=str(scn.source_path) if scn.source_path else None,
                    seed=int(seed),
                    days=(int(days[0]), int(days[1])),
                    overrides=tuple((s.name, v) for s, v in applied),
                    localizers=tuple(labels),
                    data={**data, "seeds": [int(seed)]},
                )
    return list(cells.values())


def _validate(
    scn: Scenario, data: dict[str, Any], applied: Sequence[tuple[Setting, ParamValue]]
) -> Scenario:
    """The resolved scenario, validated as a scenario file is; InputError naming the
    scenario and the parameter values on a problem."""
    try:
        return parse_scenario(data, scn.source_path or "<scenario>")
    except ScenarioFileError as exc:
        what = ", ".join(f"--set {s.name}={_show(v)}" for s, v in applied)
        raise InputError(f"{what}: {exc}" if what else str(exc)) from None


def sweep_hash(cells: Sequence[Cell]) -> str:
    """The identity of a sweep: its cells' keys."""
    return hashlib.sha256("\n".join(sorted(c.key for c in cells)).encode()).hexdigest()


# ---------------------------------------------------------------------- sweep files
class _SweepFileModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    name: str | None = Field(None, min_length=1, description="the sweep's name")
    scenarios: list[str] = Field(min_length=1, description="scenario files (relative here)")
    seeds: str | int | list[int] = Field(description="'0-3', 7 or [0, 1, 2, 3]")
    days: str | int | list[int] | None = Field(None, description="'1-7' or [1, 7]")
    localizers: list[str] | None = Field(None, min_length=1, description="labels to keep")
    settings: dict[str, ParamValue] = Field(
        default_factory=dict, alias="set", description="'LABEL.KEY' = [values]"
    )

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: Any) -> Any:
        text = seeds_text(v)
        try:
            parse_seeds(text, "seeds")
        except InputError as exc:
            raise ValueError(str(exc).removeprefix("seeds: ")) from None
        return v

    @field_validator("days")
    @classmethod
    def _days(cls, v: Any) -> Any:
        if v is not None:
            parse_day_range(v)
        return v


def seeds_text(v: str | int | list[int]) -> str:
    """A file's ``seeds`` (``'0-3'``, ``7`` or ``[0, 1]``) as :func:`parse_seeds` reads them."""
    return ",".join(map(str, v)) if isinstance(v, list) else str(v)


def parse_day_range(v: Any) -> tuple[int, int]:
    """A file's ``days`` (``'1-7'``, ``3`` or ``[1, 7]``) as the day range ``(first, last)``,
    both counted from 1; ValueError when it is not one (sweep and benchmark files share it)."""
    if isinstance(v, list):
        if len(v) != 2:
            raise ValueError(f"days must look like '1-7' or [1, 7], not {v!r}")
        a, b = v
    elif isinstance(v, int) and not isinstance(v, bool):
        a = b = v
    else:
        a, _, b = str(v).partition("-")
        try:
            a, b = int(a), int(b or a)
        except ValueError:
            raise ValueError(f"days must look like '1-7' or [1, 7], not {v!r}") from None
    if not 1 <= a <= b:
        raise ValueError(f"days must be 1 <= first <= last, not {v!r}")
    return int(a), int(b)


def load_sweep_file(path: str | Path, load: Any = load_scenario) -> SweepSpec:
    """A sweep file as a :class:`SweepSpec` (:class:`SweepFileError` listing every problem
    with its field; a scenario's own problems as its :class:`ScenarioFileError`). ``load``
    loads a scenario file (the CLI passes the analysis' loader, which checks findings)."""
    p = Path(path)
    raw = read_toml(p, SweepFileError)
    try:
        m = _SweepFileModel.model_validate(raw)
    except ValidationError as exc:
        raise SweepFileError(p, pydantic_errors(exc)) from None
    errors: list[tuple[str, str]] = []
    settings = []
    for name, values in m.settings.items():
        vals = values if isinstance(values, list) else [values]
        try:
            label, key = _split_name(name, "")
        except InputError as exc:
            errors.append((f"set.{name}", str(exc).removeprefix(": ")))
            continue
        if not vals or len(set(map(repr, vals))) != len(vals):
            errors.append((f"set.{name}", "give distinct values, e.g. ['a', 'b']"))
            continue
        settings.append(Setting(label, key, tuple(vals)))
    files = []
    for i, ref in enumerate(m.scenarios):
        f = Path(ref) if Path(ref).is_absolute() else p.parent / ref
        if not f.is_file():
            errors.append((f"scenarios.{i}", f"no scenario file {ref!r} (looked for {f})"))
        files.append(f)
    if errors:
        raise SweepFileError(p, errors)
    return SweepSpec(
        scenarios=tuple(load(f) for f in files),
        seeds=parse_seeds(seeds_text(m.seeds), f"{p}: seeds"),
        days=None if m.days is None else parse_day_range(m.days),
        settings=tuple(settings),
        only=None if m.localizers is None else tuple(m.localizers),
        name=m.name or p.stem,
    )


# ---------------------------------------------------------------------- running a cell
def cell_finished(folder: Path, key: str) -> bool:
    """Whether ``folder`` holds the complete experiment ``key``."""
    if not (folder / DB_NAME).is_file():
        return False
    try:
        with ResultsDB.open(folder) as db:
            meta = db.meta()
    except (InputError, OSError):
        return False
    return bool(meta.get("complete")) and meta.get("experiment_hash") == key


@contextlib.contextmanager
def _cell_lock(folder: Path) -> Iterator[None]:
    """Wait for the cell's folder: a cell of a killed sweep may still be running on a
    worker (a Dask worker finishes a task whose client went away); its results are then
    resumed, not written twice."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    fd = os.open(folder / ".cell.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def run_cell(cell: Cell, cells_dir: str) -> dict[str, Any]:
    """Run one cell into ``cells_dir/<key[:16]>`` (resuming what is there); its outcome:
    ``{"key", "status": "done" | "failed", "error", "traceback", "wall_s", "host"}``.
    Never raises for the cell's own errors: a failed cell is reported, the sweep goes on."""
    t0 = time.perf_counter()
    out = Path(cells_dir) / cell.dir_name
    result: dict[str, Any] = {"key": cell.key, "host": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        out.mkdir(parents=True, exist_ok=True)
        with _cell_lock(out):
            if not cell_finished(out, cell.key):
                scn = parse_scenario(cell.data, cell.scenario_path or "<scenario>")
                if experiment_hash(scn, cell.seed, cell.days) != cell.key:
                    raise InputError(
                        f"{cell.scenario_path or cell.scenario}: the scenario or its world "
                        "file changed since the sweep began; start the sweep again"
                    )
                run_experiment(
                    scn, out, cell.days, cell.seed, resume=True, progress=False, workers=1
                )
    except Exception as exc:  # a cell's failure is its result
        result |= {
            "status": "failed",
            "error": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
        }
    else:
        result |= {"status": "done", "error": None, "traceback": None}
    result["wall_s"] = time.perf_counter() - t0
    return result


# ---------------------------------------------------------------------- executors
@contextlib.contextmanager
def _thread_env() -> Iterator[None]:
    """One native thread per cell process (inherited by the pool's spawned processes)."""
    added = {k: v for k, v in WORKER_THREAD_ENV.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


@contextlib.contextmanager
def make_executor(
    n_cells: int, workers: int | None = None, cluster: str | None = None
) -> Iterator[Executor]:
    """The executor of a sweep's cells: a Dask cluster's (``cluster``: its scheduler's
    address) or a local pool of ``workers`` spawned processes (None: one per core), at most
    one per cell. Pending cells are cancelled when the block ends by an exception."""
    if cluster is not None:
        try:
            import distributed
        except ImportError:
            raise InputError(
                "--cluster needs Dask distributed: pip install 'dynmap-sim[cluster]'"
            ) from None
        try:
            client = distributed.Client(cluster, timeout="15s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--cluster {cluster}: cannot connect ({exc})") from None
        try:
            executor = client.get_executor(pure=False)
            try:
                yield executor
            except BaseException:
                executor.shutdown(wait=False)
                raise
        finally:
            client.close()
        return
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, not {workers}")
    n = max(1, min(workers or os.cpu_count() or 1, n_cells))
    import multiprocessing as mp

    with _thread_env():
        pool = ProcessPoolExecutor(n, mp_context=mp.get_context("spawn"))
        try:
            yield pool
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


# ---------------------------------------------------------------------- the index
def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")  # noqa: UP017


def read_index(out_dir: str | Path) -> dict[str, Any]:
    """A sweep folder's ``sweep.json`` (InputError when there is none or it is unreadable)."""
    path = Path(out_dir) / SWEEP_INDEX
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{out_dir}: not a sweep folder (no {SWEEP_INDEX})") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: unreadable sweep index ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("cells"), list):
        raise InputError(f"{path}: not a sweep index (no cells)")
    if data.get("format") != SWEEP_FORMAT:
        raise InputError(f"{path}: sweep format {data.get('format')}, this version reads 1")
    return data


def _write_index(out_dir: Path, index: dict[str, Any]) -> None:
    """Write ``sweep.json`` atomically (a killed sweep leaves the old or the new one)."""
    fd, tmp = tempfile.mkstemp(prefix=".sweep-", suffix=".json", dir=out_dir)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(index, fh, indent=1, default=str)
            fh.write("\n")
        os.replace(tmp, out_dir / SWEEP_INDEX)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@dataclass
class SweepOutcome:
    """What a sweep did: the folder, its cells, and which ran, were skipped or failed."""

    out_dir: Path
    n_cells: int
    skipped: list[str] = field(default_factory=list)
    done: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def complete(self) -> bool:
        return not self.failed and len(self.skipped) + len(self.done) == self.n_cells


def _open_sweep(out: Path, spec: SweepSpec, cells: Sequence[Cell]) -> dict[str, Any]:
    """The index to continue: the folder's own when it holds this sweep, a fresh one when
    the folder is new or empty; InputError for a folder of anything else."""
    ident = sweep_hash(cells)
    if (out / SWEEP_INDEX).exists():
        old = read_index(out)
        if old.get("sweep_hash") != ident:
            raise InputError(
                f"{out} holds another sweep ({old.get('name')!r}, {len(old['cells'])} cells, "
                f"made {old.get('created')}); this one has {len(cells)} cells of its own: choose "
                "another --out (the same command resumes a sweep)"
            )
        return old
    if out.exists() and any(p.name != ".results.lock" for p in out.iterdir()):
        raise InputError(
            f"{out} is not empty and holds no sweep ({SWEEP_INDEX}); choose another --out"
        )
    return {
        "format": SWEEP_FORMAT,
        "name": spec.name,
        "sweep_hash": ident,
        "created": _now(),
        "definition": {
            "scenarios": [_where(s) for s in spec.scenarios],
            "seeds": list(spec.seeds),
            "days": None if spec.days is None else list(spec.days),
            "set": {s.name: list(s.values) for s in spec.settings},
            "only": None if spec.only is None else list(spec.only),
        },
        "cells": [c.index_entry() | {"status": "pending", "error": None} for c in cells],
    }


def run_sweep(
    spec: SweepSpec,
    out_dir: str | Path,
    workers: int | None = None,
    cluster: str | None = None,
    progress: bool = True,
    executor: Executor | None = None,
    note: Callable[[str], None] | None = None,
) -> SweepOutcome:
    """Run the cells of ``spec`` into ``out_dir`` (see the module doc); skip finished cells.

    ``executor``: run the cells there (the caller's; else :func:`make_executor` with
    ``workers`` and ``cluster``). ``note(text)`` is told what is resumed. The sweep's
    folder is locked: one sweep process per folder.
    """
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    cells = resolve_cells(spec)  # every cell validated before anything is written
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {out}: {exc.strerror or exc}") from None
    lock = FolderLock(out)
    try:
        index = _open_sweep(out, spec, cells)
        entries = {e["key"]: e for e in index["cells"]}
        cells_dir = out / CELLS_DIR
        cells_dir.mkdir(exist_ok=True)
        outcome = SweepOutcome(out, len(cells))
        todo = []
        for c in cells:
            if cell_finished(cells_dir / c.dir_name, c.key):
                outcome.skipped.append(c.key)
                if entries[c.key]["status"] != "done":
                    entries[c.key] |= {"status": "done", "error": None}
            else:
                todo.append(c)
                entries[c.key] |= {"status": "pending", "error": None}
        _write_index(out, index)
        if note is not None and outcome.skipped:
            note(f"resuming {out}: {len(outcome.skipped)} of {len(cells)} cells are done")
        bar = tqdm(
            total=len(cells),
            initial=len(outcome.skipped),
            disable=not progress,
            desc=spec.name,
            unit="cell",
        )
        try:
            if todo:
                with contextlib.ExitStack() as stack:
                    ex = executor or stack.enter_context(make_executor(len(todo), workers, cluster))
                    _run_cells(ex, todo, str(cells_dir), out, index, entries, outcome, bar)
        finally:
            bar.close()
    finally:
        lock.release()
    outcome.wall_s = time.perf_counter() - t0
    return outcome


def _run_cells(
    ex: Executor,
    todo: Sequence[Cell],
    cells_dir: str,
    out: Path,
    index: dict[str, Any],
    entries: dict[str, dict[str, Any]],
    outcome: SweepOutcome,
    bar: Any,
) -> None:
    """Submit the cells and record each as it ends (the index is rewritten each time)."""
    futures: dict[Future[dict[str, Any]], Cell] = {
        ex.submit(run_cell, c, cells_dir): c for c in todo
    }
    for fut in as_completed(futures):
        cell = futures[fut]
        try:
            res = fut.result()
        except Exception as exc:  # the executor lost the cell (a worker died, ...)
            res = {
                "key": cell.key,
                "status": "failed",
                "error": f"{type(exc).__name__}: {exc}",
                "traceback": None,
                "wall_s": math.nan,
            }
        entry = entries[cell.key]
        entry |= {
            "status": res["status"],
            "error": res.get("error"),
            "traceback": res.get("traceback"),
            "wall_s": None if not math.isfinite(res.get("wall_s", math.nan)) else res["wall_s"],
            "host": res.get("host"),
            "finished": _now(),
        }
        if res["status"] == "done":
            outcome.done.append(cell.key)
        else:
            outcome.failed[cell.key] = str(res.get("error"))
        _write_index(out, index)
        bar.update(1)
        if outcome.failed:
            bar.set_postfix_str(f"{len(outcome.failed)} failed")
