"""Export trajectories of a results folder in the TUM format (for ``evo``, Sturm et al. 2012).

Each line is ``timestamp tx ty tz qx qy qz qw``. The timestamp is seconds since midnight of the
experiment's first date, so it increases over the whole experiment (day after day); z is 0
and the quaternion a rotation about z by the heading.

A ``replay`` folder holds two passes over one log: ``<label>.tum`` is the localization pass
and ``<label>-mapping.tum`` the mapping pass, both stamped with the log's own clock (so they
line up with anything else made from the log), and ``truth.tum`` the reference poses matched
to the scans (``replay --reference``; the scans without one are left out) when there are any.
"""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB


def write_tum(path: str | Path, t_s: ArrayLike, poses: ArrayLike) -> Path:
    """Write planar poses ``(N, 3)`` at times ``t_s`` [s] as a TUM trajectory file."""
    t = np.asarray(t_s, dtype=np.float64).ravel()
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(t) != len(p):
        raise ValueError(f"{len(t)} timestamps for {len(p)} poses")
    half = 0.5 * p[:, 2]
    zeros = np.zeros(len(p))
    table = np.column_stack([t, p[:, 0], p[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)])
    out = Path(path)
    np.savetxt(out, table, fmt="%.9f", delimiter=" ")
    return out


def _safe(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label)


def export_tum(out_dir: str | Path, tum_dir: str | Path, force: bool = False) -> list[Path]:
    """Write ``truth.tum`` and ``<label>.tum`` for each localizer of a results folder into
    ``tum_dir`` (created with its parents). Files already there are refused, all before any
    is written, unless ``force``."""
    dst = Path(tum_dir)
    try:
        dst.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {dst}: {exc.strerror or exc}") from None
    with ResultsDB.open(out_dir) as db:
        meta = db.meta()
        if not db.query("SELECT 1 FROM runs LIMIT 1"):
            raise InputError(f"{out_dir}: no finished run to export")
        tables = _replay_tables(db, meta) if "log_path" in meta else _run_tables(db, meta)
    there = [name for name, _, _ in tables if (dst / name).exists()]
    if there and not force:
        raise InputError(
            f"--tum {dst}: {', '.join(there)} already there; pass --force to replace "
            f"{'them' if len(there) > 1 else 'it'} or choose another folder"
        )
    return [write_tum(dst / name, stamps, poses) for name, stamps, poses in tables]


#: One TUM file to write: its name, time stamps [s] and poses ``(N, 3)``.
TumTable = tuple[str, np.ndarray, np.ndarray]


def _run_tables(db: ResultsDB, meta: dict[str, Any]) -> list[TumTable]:
    """The TUM tables of an experiment folder: stamps are seconds since the first run's date."""
    first_date = meta.get("first_date")
    if first_date is None:  # not written by run: the first run's date
        first_date = db.query("SELECT min(date) FROM runs")[0][0]
    first = dt.date.fromisoformat(first_date)
    dates = {
        (int(a), int(b)): dt.date.fromisoformat(c)
        for a, b, c in db.query("SELECT day, run, date FROM runs")
    }
    tables: list[TumTable] = []
    for k, label in enumerate(db.labels()):
        d = db.per_scan(k)
        offset = np.array(
            [
                (dates[(a, b)] - first).days * 86400.0
                for a, b in zip(d["day"], d["run"], strict=True)
            ]
        )
        stamps = offset + d["t_s"]
        if k == 0:
            tables.append(("truth.tum", stamps, d["truth"]))
        tables.append((f"{_file_stem(label, k, tables)}.tum", stamps, d["estimate"]))
    return tables


def _file_stem(label: str, k: int, tables: list[TumTable]) -> str:
    """``label`` made a safe file stem, ``-k`` appended where it would clash with ``truth`` or
    with a file already planned (two labels that sanitize alike keep separate files)."""
    name = _safe(label)
    if name == "truth" or any(Path(t[0]).stem == name for t in tables):
        name = f"{name}-{k}"
    return name


def _replay_tables(db: ResultsDB, meta: dict[str, Any]) -> list[TumTable]:
    """The TUM tables of a replay folder (see the module doc)."""
    t0 = float(meta.get("log_start_s") or 0.0)
    tables: list[TumTable] = []
    for k, label in enumerate(db.labels()):
        name = _file_stem(label, k, tables)
        for day, suffix in ((2, ""), (1, "-mapping")):
            d = db.per_scan(k, day=day)
            if not len(d["t_s"]):
                continue
            if k == 0 and day == 2 and meta.get("has_reference"):
                ok = np.isfinite(d["truth"]).all(axis=1)  # scans with a reference pose
                tables.append(("truth.tum", t0 + d["t_s"][ok], d["truth"][ok]))
            tables.append((f"{name}{suffix}.tum", t0 + d["t_s"], d["estimate"]))
    return tables
