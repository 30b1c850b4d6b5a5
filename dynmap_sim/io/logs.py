"""One entry to a recorded log: a CARMEN text log or a ROS bag, by its name.

``replay`` and ``slam-eval`` read either through :func:`read_log`; both give a
:class:`~dynmap_sim.io.carmen.CarmenLog` (scans, odometry at the scan times, the laser).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from dynmap_sim.errors import InputError
from dynmap_sim.io.carmen import CarmenLog, read_carmen
from dynmap_sim.io.rosbag import is_bag, read_bag

#: Bytes read at a time to fingerprint a log.
_CHUNK = 1 << 20


@dataclass(frozen=True)
class BagOptions:
    """How to read a bag: the scan and odometry topics (``None``: found by type) and the
    laser's mount pose ``(x [m], y [m], theta [rad])`` (``None``: from ``/tf_static``)."""

    scan_topic: str | None = None
    odom_topic: str | None = None
    laser_mount: tuple[float, float, float] | None = None

    def given(self) -> list[str]:
        """The options set, by their command-line names."""
        names = ("--scan-topic", "--odom-topic", "--laser-mount")
        vals = (self.scan_topic, self.odom_topic, self.laser_mount)
        return [n for n, v in zip(names, vals, strict=True) if v is not None]


def read_log(
    path: str | Path,
    odometry: str = "auto",
    reversals: str = "repair",
    bag: BagOptions | None = None,
) -> CarmenLog:
    """The scans and odometry of ``path``: a ROS bag (:func:`~.rosbag.read_bag`, read as
    ``bag`` says) or else a CARMEN log (:func:`~.carmen.read_carmen` with ``odometry`` and
    ``reversals``, which a bag does not have)."""
    bag = bag or BagOptions()
    if is_bag(path):
        if odometry != "auto" or reversals != "repair":
            raise InputError(
                f"{path}: --odometry and --odometry-reversals are for CARMEN logs; a bag's "
                "odometry is its topic (--odom-topic)"
            )
        return read_bag(path, bag.scan_topic, bag.odom_topic, bag.laser_mount)
    if bag.given():
        raise InputError(f"{path}: {', '.join(bag.given())} are for ROS bags, not CARMEN logs")
    return read_carmen(path, odometry=odometry, reversals=reversals)


def log_digest(path: str | Path) -> hashlib._Hash:
    """SHA-256 of a log's bytes (a ROS 2 bag folder: of its files in name order), read in
    chunks."""
    p = Path(path)
    files = sorted(f for f in p.iterdir() if f.is_file()) if p.is_dir() else [p]
    h = hashlib.sha256()
    for f in files:
        with open(f, "rb") as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
    return h
