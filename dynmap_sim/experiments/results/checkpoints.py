"""The checkpoint a run leaves: the engine's state in the ``checkpoint`` row, each localizer
pickled to a file of its own.

The localizers go to ``checkpoint/loc<k>-<next index>.pkl`` next to ``results.db`` (written to
a temporary name, then renamed), not into the database: a large state (the dynamic maps are
tens of MB) rewritten after every run would churn the database's pages. The files are written
before the transaction that names them commits, and older ones are deleted after it, so a
process killed at any moment leaves either the whole run with its checkpoint or none of it.

The checksum (``v3:``) covers the row's fields (next run, scenario hash, seed), its blob and
``cover``: the digest of the experiment's metadata and of every stored run's rows
(:func:`~dynmap_sim.experiments.results.integrity.cover_digest`), so an edited ``next_index``,
seed or deleted run is refused like a flipped bit.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import sqlite3
from pathlib import Path
from typing import Any

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results.records import Checkpoint
from dynmap_sim.experiments.results.schema import CHECKPOINT_DIR

#: Modules that moved, old name to new: a state pickled before the move still loads.
MOVED_MODULES = {
    "dynmap_sim.agent.localizer": "dynmap_sim.agent.localization.localizer",
    "dynmap_sim.agent.dead_reckoning": "dynmap_sim.agent.localization.dead_reckoning",
}


class _StateUnpickler(pickle.Unpickler):
    """An unpickler that finds the classes of :data:`MOVED_MODULES` at their new place."""

    def find_class(self, module: str, name: str) -> Any:
        return super().find_class(MOVED_MODULES.get(module, module), name)


def load_state(blob: bytes) -> Any:
    """Unpickle the engine's own state (a checkpoint, a localizer), classes that moved
    found at their new module (:data:`MOVED_MODULES`)."""
    return _StateUnpickler(io.BytesIO(blob)).load()  # noqa: S301 - our own state


def checkpoint_digest(
    idx: Any, nd: Any, nr: Any, h: Any, seed: Any, blob: bytes, cover: str | None
) -> str:
    """The checkpoint's checksum: its fields, its blob and (``v3``) ``cover`` (``v2``: none,
    written before the checksum covered the stored rows)."""
    head = json.dumps([int(idx), int(nd), int(nr), str(h), int(seed)]).encode()
    if cover is None:
        return "v2:" + hashlib.sha256(head + b"\0" + blob).hexdigest()
    return "v3:" + hashlib.sha256(head + b"\0" + cover.encode() + b"\0" + blob).hexdigest()


class CheckpointStore:
    """The ``checkpoint`` row of connection ``con`` and the localizer files in ``folder``."""

    def __init__(self, con: sqlite3.Connection, path: Path) -> None:
        self.con = con
        self.path = path
        self.folder = path.parent / CHECKPOINT_DIR

    # ------------------------------------------------------------------ writing
    def write_localizer_files(self, cp: Checkpoint) -> list[tuple[str, str]]:
        """Write each pickled localizer atomically (temp file + rename); (name, sha256)s."""
        out: list[tuple[str, str]] = []
        if cp.localizers:
            self.folder.mkdir(exist_ok=True)
        for k, blob in enumerate(cp.localizers):
            name = f"loc{k}-{cp.next_index}.pkl"
            path = self.folder / name
            tmp = path.with_name(name + ".tmp")
            try:
                tmp.write_bytes(blob)
                os.replace(tmp, path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                self.remove_uncommitted_files([name for name, _ in out])
                raise
            out.append((name, hashlib.sha256(blob).hexdigest()))
        return out

    def remove_uncommitted_files(self, names: list[str]) -> None:
        """Remove localizer files of a write that failed (never those the stored
        checkpoint names)."""
        if not names:
            return
        keep: set[str] = set()
        try:
            row = self.con.execute("SELECT blob FROM checkpoint WHERE id = 1").fetchone()
            if row is not None and row[0] is not None:
                content = load_state(bytes(row[0]))
                keep = {name for name, _ in content.get("localizer_files", ())}
        except Exception:  # noqa: BLE001 - unreadable: keep every file but the new ones
            pass
        for name in names:
            if name not in keep:
                (self.folder / name).unlink(missing_ok=True)

    def remove_stale_files(self, keep: set[str]) -> None:
        if self.folder.is_dir():
            for f in self.folder.iterdir():
                if f.name not in keep and f.name.endswith((".pkl", ".pkl.tmp")):
                    f.unlink(missing_ok=True)

    def put(
        self,
        cp: Checkpoint,
        files: list[tuple[str, str]],
        scenario_hash: str,
        seed: int,
        cover: str,
    ) -> None:
        """Write the checkpoint row (in the open transaction)."""
        content = {"format": 2, "state": cp.state, "localizer_files": files}
        blob = pickle.dumps(content, protocol=pickle.HIGHEST_PROTOCOL)
        digest = checkpoint_digest(
            cp.next_index, cp.next_day, cp.next_run, scenario_hash, seed, blob, cover
        )
        self.con.execute(
            "INSERT OR REPLACE INTO checkpoint VALUES (1, ?, ?, ?, ?, ?, ?, ?, datetime('now'))",
            (cp.next_index, cp.next_day, cp.next_run, scenario_hash, seed, digest, blob),
        )

    # ------------------------------------------------------------------ reading
    def row(self) -> tuple[Any, ...] | None:
        try:
            return self.con.execute(
                "SELECT next_index, next_day, next_run, scenario_hash, seed, sha256, blob "
                "FROM checkpoint WHERE id = 1"
            ).fetchone()
        except sqlite3.DatabaseError as exc:
            raise InputError(f"{self.path}: cannot read the checkpoint ({exc})") from None

    def verify(self, row: tuple[Any, ...], cover: str | None) -> None:
        """Refuse a checkpoint ``row`` whose checksum does not match (``cover``: what a
        ``v3`` checksum covers besides the row)."""
        idx, nd, nr, h, s, digest, blob = row
        corrupt = InputError(
            f"{self.path}: the checkpoint is corrupt (checksum mismatch: its fields, its "
            "state, the metadata or the stored runs were changed); it cannot be resumed: "
            "start a new experiment with another --out"
        )
        if blob is None or not isinstance(digest, str):
            raise corrupt
        try:
            if digest.startswith("v3:"):
                if cover is None:
                    raise corrupt
                expected = checkpoint_digest(idx, nd, nr, h, s, bytes(blob), cover)
            elif digest.startswith("v2:"):  # covers the fields too
                expected = checkpoint_digest(idx, nd, nr, h, s, bytes(blob), None)
            else:  # written before the checksum covered the fields: the blob alone
                expected = hashlib.sha256(bytes(blob)).hexdigest()
        except (TypeError, ValueError):
            raise corrupt from None
        if expected != digest:
            raise corrupt

    def load(self, scenario_hash: str, seed: int, cover: str | None) -> Checkpoint | None:
        """The last checkpoint, verified; None when the experiment has none yet (see
        ``ResultsDB.load_checkpoint``)."""
        row = self.row()
        if row is None:
            return None
        idx, nd, nr, h, s, _, blob = row
        if h != scenario_hash:
            raise InputError(
                f"{self.path}: the checkpoint belongs to a different scenario or world file "
                "(their content changed); start a new experiment with another --out"
            )
        if s != seed:
            raise InputError(f"{self.path}: the checkpoint was made with seed {s}, not {seed}")
        self.verify(row, cover)
        try:
            content = load_state(bytes(blob))
        except Exception as exc:  # noqa: BLE001 - any failure means unusable
            raise InputError(f"{self.path}: the checkpoint cannot be loaded ({exc})") from None
        if not (isinstance(content, dict) and content.get("format") == 2):
            # the first format: everything (localizers included, as objects) in the blob
            state = dict(content)
            locs = tuple(
                pickle.dumps(x, pickle.HIGHEST_PROTOCOL) for x in state.pop("localizers", [])
            )
            return Checkpoint(int(idx), int(nd), int(nr), state, locs)
        return Checkpoint(
            int(idx), int(nd), int(nr), content["state"], self._localizer_files(content)
        )

    def _localizer_files(self, content: dict[str, Any]) -> tuple[bytes, ...]:
        locs = []
        for name, digest in content["localizer_files"]:
            path = self.folder / name
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise InputError(
                    f"{path}: cannot read the checkpoint's localizer ({exc})"
                ) from None
            if hashlib.sha256(data).hexdigest() != digest:
                raise InputError(f"{path}: the checkpoint is corrupt (checksum mismatch)")
            locs.append(data)
        return tuple(locs)
