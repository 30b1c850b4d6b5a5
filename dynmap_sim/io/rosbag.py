"""Read a robot's ROS bag (ROS 1 ``.bag``, ROS 2 ``.db3`` / ``.mcap``) into the scan and
odometry stream that :func:`~dynmap_sim.io.carmen.read_carmen` gives (a
:class:`~dynmap_sim.io.carmen.CarmenLog`), through ``rosbags`` (extra ``ros``).

* Scans: a ``sensor_msgs/LaserScan`` topic, found by type when the bag has one (else named
  with ``scan_topic``), stamped by their headers. Readings at or beyond ``range_max`` are
  no return (``+inf``), other non-positive ones no reading (``NaN``), as in a CARMEN log;
  scans whose start angle or beam count vary (an interlaced scanner) are placed on one
  beam grid (:mod:`.beam_grid`).
* Odometry: a ``nav_msgs/Odometry`` topic (found by type when there is one), else the
  ``odom`` -> ``base_link`` transforms on ``/tf``; ``odom_topic`` names either. Its poses
  are interpolated (heading unwrapped) to the scan stamps, as a CARMEN log's ``ODOM`` lines.
* The laser's mounting: ``laser_mount`` ``(x, y, theta)`` when given, else the transforms
  from ``base_link`` to the scans' frame on ``/tf_static`` (or ``/tf``), chained.

A ROS 2 bag is a folder holding ``metadata.yaml``; its ``.db3`` or ``.mcap`` file may be
named instead. Anything that cannot be read -- no laser topic, two candidates, stamps that go
back, a truncated bag, a type without a definition -- is one :class:`BagError` naming the
file and the topic.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.errors import FileError
from dynmap_sim.io.beam_grid import beam_grid
from dynmap_sim.io.carmen import CarmenLog, interpolate_poses
from dynmap_sim.types import LaserSpec

FloatArray = NDArray[np.float64]

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: File endings of a bag (a ROS 2 bag's folder holds ``metadata.yaml``).
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
#: The value of ``odom_topic`` (and the source named) for odometry from ``/tf``.
TF_ODOMETRY = "/tf"


class BagError(FileError):
    """A bag that cannot be read as a robot's scans and odometry; names file and topic."""


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a ROS bag by its name (or a folder with ``metadata.yaml``)."""
    p = Path(path)
    return p.suffix in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def _reader_path(p: Path) -> Path:
    """What ``rosbags`` opens: the ``.bag`` file, or a ROS 2 bag's folder."""
    if not p.exists():
        raise BagError(p, [("", "file not found")])
    if p.suffix == ".bag" or p.is_dir():
        return p
    if (p.parent / "metadata.yaml").is_file():
        return p.parent
    raise BagError(
        p, [("", "a ROS 2 bag is a folder with metadata.yaml; none is next to this file")]
    )


def _frame(name: str) -> str:
    return name.lstrip("/")


def _stamp(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _pick(p: Path, conns: list, wanted: str | None, types: set[str], what: str, opt: str) -> Any:
    """The connection of topic ``wanted`` (checked to be of ``types``), or the one topic of
    those types; ``None`` when there is none and none was asked for."""
    if wanted is not None:
        named = [c for c in conns if c.topic == wanted]
        if not named:
            have = ", ".join(sorted({c.topic for c in conns})) or "none"
            raise BagError(p, [(wanted, f"no such topic (topics: {have})")])
        if named[0].msgtype not in types:
            raise BagError(p, [(wanted, f"is {named[0].msgtype}, not {what}")])
        return named[0]
    found = [c for c in conns if c.msgtype in types]
    topics = sorted({c.topic for c in found})
    if len(topics) > 1:
        raise BagError(
            p, [("", f"{len(topics)} {what} topics ({', '.join(topics)}): choose one with {opt}")]
        )
    return found[0] if found else None


def _messages(p: Path, reader: Any, conns: list) -> Any:
    """``(topic, message)`` of ``conns`` in the bag's order; a message that cannot be read or
    decoded is a :class:`BagError` naming its topic."""
    topic = ""
    try:
        for conn, _, raw in reader.messages(connections=conns):
            topic = conn.topic
            yield conn.topic, reader.deserialize(raw, conn.msgtype)
    except BagError:
        raise
    except Exception as exc:  # rosbags' readers raise many types for damaged data
        raise BagError(p, [(topic or "", f"cannot read the bag (truncated?): {exc}")]) from None


class _Streams:
    """What :func:`read_bag` collects from the messages."""

    def __init__(self) -> None:
        self.scan_t: list[float] = []
        self.scans: list[NDArray[np.float32]] = []
        self.layout: list[tuple[float, float]] = []
        self.range_lim: tuple[float, float] | None = None
        self.frame = ""
        self.odom_t: list[float] = []
        self.odom: list[tuple[float, float, float]] = []
        self.static: dict[str, tuple[str, FloatArray]] = {}  # child -> (parent, pose)

    def scan(self, m: Any) -> None:
        self.scan_t.append(_stamp(m.header))
        self.scans.append(np.asarray(m.ranges, dtype=np.float32).copy())
        self.layout.append((float(m.angle_min), float(m.angle_increment)))
        if self.range_lim is None:
            self.range_lim = (float(m.range_min), float(m.range_max))
            self.frame = _frame(m.header.frame_id)

    def transforms(self, m: Any, odom: tuple[str, str], collect: bool) -> None:
        """The ``odom`` (parent, child) transforms as odometry when ``collect``; the first of
        every other (parent, child) as a static transform."""
        for tf in m.transforms:
            parent, child = _frame(tf.header.frame_id), _frame(tf.child_frame_id)
            tr, q = tf.transform.translation, tf.transform.rotation
            pose = (float(tr.x), float(tr.y), _yaw(q))
            if (parent, child) == odom:
                if collect:
                    self.odom_t.append(_stamp(tf.header))
                    self.odom.append(pose)
            elif child not in self.static:
                self.static[child] = (parent, np.array(pose))


def _mount(p: Path, s: _Streams, base: str) -> tuple[float, float, float]:
    """The scans' frame in ``base`` from the collected static transforms, chained."""
    pose, frame, hops = np.zeros(3), s.frame, 0
    while frame != base:
        if frame not in s.static or hops > 32:
            raise BagError(
                p,
                [
                    (
                        "/tf_static",
                        f"no transform from {base} to the scans' frame {s.frame!r}: give the "
                        "laser's mounting with --laser-mount X,Y,THETA (0,0,0 at the centre)",
                    )
                ],
            )
        parent, rel = s.static[frame]
        pose, frame, hops = se2.compose(rel, pose), parent, hops + 1
    return float(pose[0]), float(pose[1]), float(pose[2])


def _check_stamps(p: Path, topic: str, t: FloatArray, what: str) -> None:
    if len(t) == 0:
        raise BagError(p, [(topic, f"no {what} messages")])
    if not np.isfinite(t).all():
        k = int(np.argmin(np.isfinite(t)))
        raise BagError(p, [(topic, f"message {k}: its time stamp is not finite")])
    back = np.flatnonzero(np.diff(t) < 0)
    if len(back):
        k = int(back[0]) + 1
        raise BagError(
            p, [(topic, f"time stamps go back at message {k} ({t[k - 1]:.6f} -> {t[k]:.6f})")]
        )


def read_bag(
    path: str | Path,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    laser_mount: tuple[float, float, float] | None = None,
    base_frame: str = "base_link",
    odom_frame: str = "odom",
) -> CarmenLog:
    """The scans and odometry of the bag at ``path`` (module docstring)."""
    p = Path(path)
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError(
            p, [("", 'reading bags needs rosbags: pip install "dynmap-sim[ros]"')]
        ) from None
    src = _reader_path(p)
    try:
        reader = AnyReader([src], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as exc:  # damaged or not a bag at all
        raise BagError(p, [("", f"not a readable ROS bag (truncated?): {exc}")]) from None
    try:
        conns = list(reader.connections)
        s, scan_conn, odom_src = _collect(p, reader, conns, scan_topic, odom_topic, odom_frame,
                                          base_frame)  # fmt: skip
    finally:
        reader.close()
    return _log_of(p, s, scan_conn.topic, odom_src, laser_mount, base_frame)


def _collect(
    p: Path, reader: Any, conns: list, scan_topic: str | None, odom_topic: str | None,
    odom_frame: str, base_frame: str,
) -> tuple[_Streams, Any, str]:  # fmt: skip
    """Read the scan, odometry and transform topics: the streams, the scan connection and
    the odometry's source (a topic, or :data:`TF_ODOMETRY`)."""
    scan_conn = _pick(p, conns, scan_topic, {SCAN_TYPE}, "sensor_msgs/LaserScan", "--scan-topic")
    if scan_conn is None:
        have = ", ".join(f"{c.topic} ({c.msgtype})" for c in conns) or "none"
        raise BagError(p, [("", f"no sensor_msgs/LaserScan topic (topics: {have})")])
    tf_conns = [c for c in conns if c.msgtype == TF_TYPE and c.topic in ("/tf", "/tf_static")]
    odom_conn = None
    if odom_topic != TF_ODOMETRY:
        odom_conn = _pick(p, conns, odom_topic, {ODOM_TYPE}, "nav_msgs/Odometry", "--odom-topic")
    if odom_conn is None and not any(c.topic == "/tf" for c in tf_conns):
        raise BagError(
            p, [("", "no odometry: no nav_msgs/Odometry topic and no /tf (odom -> base_link)")]
        )
    odom_src = odom_conn.topic if odom_conn is not None else TF_ODOMETRY
    odom_pair = (_frame(odom_frame), _frame(base_frame))
    s = _Streams()
    wanted = [scan_conn] + ([odom_conn] if odom_conn is not None else []) + tf_conns
    for topic, m in _messages(p, reader, wanted):
        if topic == scan_conn.topic:
            s.scan(m)
        elif odom_conn is not None and topic == odom_conn.topic:
            s.odom_t.append(_stamp(m.header))
            pose = m.pose.pose
            s.odom.append((float(pose.position.x), float(pose.position.y), _yaw(pose.orientation)))
        else:
            s.transforms(m, odom_pair, odom_conn is None and topic == "/tf")
    return s, scan_conn, odom_src


def _log_of(
    p: Path,
    s: _Streams,
    scan_topic: str,
    odom_src: str,
    laser_mount: tuple[float, float, float] | None,
    base_frame: str,
) -> CarmenLog:
    """The :class:`CarmenLog` of the collected streams."""
    stamps = np.array(s.scan_t)
    _check_stamps(p, scan_topic, stamps, "sensor_msgs/LaserScan")
    odom_t = np.array(s.odom_t)
    _check_stamps(p, odom_src, odom_t, "odometry")
    odom = np.array(s.odom, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(odom).all():
        k = int(np.argmin(np.isfinite(odom).all(axis=1)))
        raise BagError(p, [(odom_src, f"message {k}: its pose is not finite")])
    layout = np.array(s.layout)
    if not np.isfinite(layout).all():
        k = int(np.argmin(np.isfinite(layout).all(axis=1)))
        raise BagError(p, [(scan_topic, f"message {k}: its angles are not finite")])
    counts = np.array([len(r) for r in s.scans])
    grid = beam_grid(layout[:, 0], layout[:, 1], counts)
    if isinstance(grid, str):
        raise BagError(p, [(scan_topic, f"the scans share no beam layout: {grid}")])
    ranges = grid.place(s.scans)
    range_min, range_max = s.range_lim
    ranges[ranges >= range_max] = np.inf
    ranges[np.isfinite(ranges) & (ranges <= 0.0)] = np.nan
    mount = tuple(laser_mount) if laser_mount is not None else (
        (0.0, 0.0, 0.0) if s.frame == _frame(base_frame) else _mount(p, s, _frame(base_frame))
    )  # fmt: skip
    laser = LaserSpec(
        name=f"rosbag{scan_topic.replace('/', '-')}",
        n_beams=grid.n_beams,
        angle_min_rad=grid.angle_min_rad,
        angle_increment_rad=grid.increment_rad,
        range_min_m=max(range_min, 0.0),
        range_max_m=range_max,
        scan_period_s=0.0,
        time_increment_s=0.0,
        mount_pose=tuple(float(v) for v in mount),
    )
    odo = interpolate_poses(odom_t, odom, stamps)
    return CarmenLog(p, laser, stamps, ranges, odo, None, f"{scan_topic} LaserScan", odom_src)
