"""The results store: one SQLite database per experiment.

``results.db`` in the results folder holds, in WAL mode with one transaction per run (results
format 4, ``results_format`` in ``meta``; the layout in :mod:`.schema`):

* ``meta`` — scenario (JSON), its content hash, seed, day range, laser spec, results format,
  and ``checksums``: the SHA-256 of every other value (:mod:`.integrity`);
* ``localizers`` — index, label, class name, parameters;
* ``diagnostics`` — what each localizer declared it reports
  (:class:`~dynmap_sim.types.Diagnostic`: name, per scan or per run, dtype, shape, doc);
* ``scans`` — per scan: day, run, step, time of day [s], true pose, collision flag;
* ``estimates`` — per scan and localizer: estimate, position / heading error, covariance
  diagonal, and a column per declared per-scan diagnostic: those of :data:`SCAN_COLUMNS`
  in every results folder, NULL where a localizer does not report them; any other is added
  when first written (REAL or INTEGER for a scalar, else a BLOB of the value's little-endian
  bytes);
* ``runs``, ``run_summaries``, ``day_summaries``, ``nav_runs`` — per-run and per-day
  summaries (generated from their dataclasses: :data:`.schema.TABLES`);
* ``events`` — driver and experiment events (skipped waypoints, detours, kidnappings);
* ``point_classes`` — per run and localizer, the 4x4 point-class confusion matrix against the
  beam classes (:data:`~dynmap_sim.metrics.BEAM_TO_POINT_CLASS`);
* ``point_class_truth`` — per run and localizer that reported point classes, the 4x4
  confusion against the seen-before truth (H&W §4.4, :mod:`dynmap_sim.metrics.point_classes`),
  the sum over scans of each reported class's share of the scan's valid readings, and the
  number of those scans;
* ``timescale_counts`` — per run and localizer, how often each timescale λ1–λ5 was selected
  (B&D Fig. 12); ``run_diagnostics`` — every other declared per-run diagnostic;
* ``artifacts`` — what a localizer handed over after a day (``Localizer.day_artifacts``):
  bytes, or named arrays stored as ``.npz`` (read without pickle);
* ``geometry`` — the static segments of each run's world (for report figures);
* ``scan_ranges``, ``scan_people`` — per run, every scan's ranges and the people's positions,
  only for an experiment run with ``--keep-scans``;
* ``digests`` — per run, the SHA-256 of its rows of each guarded table (:mod:`.integrity`);
* ``checkpoint`` — the pickled driver and RNG states, the next run to do, and a checksum
  that covers them, the metadata and every run's digests (:mod:`.checkpoints`).

A new store is built under a temporary name and renamed into place, so a folder holds either
a whole store or none. After each run the WAL is checkpointed into ``results.db``, so the
main file alone holds every committed run. A folder with a checkpoint but no ``results.db``
is refused, not restarted.

One writer per results folder: :meth:`ResultsDB.create` and ``open(..., lock=True)`` take an
exclusive OS lock (``flock``) on ``.results.lock`` (:mod:`.folder`); a second writer is
refused at once. A full disk is a :class:`DiskFullError` that says how many runs are kept:
the failed run's transaction is rolled back and its files removed, so ``--resume``
continues after the kept runs once there is space.

Results formats 1 (before localizers declared their diagnostics), 2 (before the seen-before
truth) and 3 (before the checksums) are read (report, export, check; what they lack is left
out) but not continued.
"""

from dynmap_sim.experiments.results.folder import (
    DiskFullError,
    FolderLock,
    is_disk_full,
    orphaned_checkpoint,
)
from dynmap_sim.experiments.results.integrity import DamagedResults
from dynmap_sim.experiments.results.records import (
    Checkpoint,
    LocalizerDiagnostics,
    PeopleTrack,
    RunRecord,
)
from dynmap_sim.experiments.results.schema import (
    CHECKPOINT_DIR,
    DB_NAME,
    ESTIMATE_COLUMNS,
    LOCK_NAME,
    RESULTS_FORMAT,
    RUN_TABLES,
    SCAN_COLUMNS,
    UPDATE_TIME_CPU,
    Artifact,
)
from dynmap_sim.experiments.results.store import ResultsDB

__all__ = [
    "CHECKPOINT_DIR",
    "DB_NAME",
    "ESTIMATE_COLUMNS",
    "LOCK_NAME",
    "RESULTS_FORMAT",
    "RUN_TABLES",
    "SCAN_COLUMNS",
    "UPDATE_TIME_CPU",
    "Artifact",
    "Checkpoint",
    "DamagedResults",
    "DiskFullError",
    "FolderLock",
    "LocalizerDiagnostics",
    "PeopleTrack",
    "ResultsDB",
    "RunRecord",
    "is_disk_full",
    "orphaned_checkpoint",
]
