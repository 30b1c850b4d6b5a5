"""ROS bags in: the tests write small ROS 1 and ROS 2 bags themselves (rosbags)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.cli import main
from dynmap_sim.io.beam_grid import beam_grid
from dynmap_sim.io.carmen import read_carmen
from dynmap_sim.io.logs import BagOptions, read_log
from dynmap_sim.io.rosbag import BagError, read_bag
from tests.io.test_carmen import write_log

pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

N_BEAMS = 91
INC = math.radians(2.0)


class _Bag:
    """A small bag of scans, odometry and transforms, written as ROS 1 or ROS 2."""

    def __init__(self, path: Path, ros2: bool, storage: str = "mcap") -> None:
        self.ros2 = ros2
        self.store = get_typestore(Stores.ROS2_JAZZY if ros2 else Stores.ROS1_NOETIC)
        if not ros2:  # ROS 1's tf2 message, as a ROS 1 robot records /tf
            tf = "geometry_msgs/TransformStamped[] transforms"
            self.store.register(get_types_from_msg(tf, "tf2_msgs/msg/TFMessage"))
        self.t = self.store.types
        if ros2:
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            self.w = Writer2(path, version=8, storage_plugin=plugin)
        else:
            self.w = Writer1(path)
        self.conns: dict[str, object] = {}

    def __enter__(self) -> _Bag:
        self.w.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.w.close()

    def _header(self, t: float, frame: str):
        sec = int(math.floor(t))
        stamp = self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t - sec) * 1e9)))
        if self.ros2:
            return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
        return self.t["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)

    def put(self, topic: str, msgtype: str, t: float, msg: object) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.store)
        ser = self.store.serialize_cdr if self.ros2 else self.store.serialize_ros1
        self.w.write(self.conns[topic], int(round(t * 1e9)), ser(msg, msgtype))

    def _quat(self, yaw: float):
        q = self.t["geometry_msgs/msg/Quaternion"]
        return q(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def scan(self, t, ranges, angle_min=-math.pi / 2, topic="/scan", at=None) -> None:
        """A LaserScan stamped ``t``, recorded at ``at`` (default ``t``)."""
        msg = self.t["sensor_msgs/msg/LaserScan"](
            header=self._header(t, "laser"), angle_min=angle_min,
            angle_max=angle_min + INC * (len(ranges) - 1), angle_increment=INC,
            time_increment=0.0, scan_time=0.1, range_min=0.0, range_max=30.0,
            ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, np.float32),
        )  # fmt: skip
        self.put(topic, "sensor_msgs/msg/LaserScan", t if at is None else at, msg)

    def odom(self, t: float, pose: np.ndarray, topic: str = "/odom") -> None:
        t_ = self.t
        point = t_["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
        p = t_["geometry_msgs/msg/Pose"](position=point, orientation=self._quat(pose[2]))
        pwc = t_["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36))
        vec = t_["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        tw = t_["geometry_msgs/msg/Twist"](linear=vec, angular=vec)
        twc = t_["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36))
        msg = t_["nav_msgs/msg/Odometry"](
            header=self._header(t, "odom"), child_frame_id="base_link", pose=pwc, twist=twc
        )
        self.put(topic, "nav_msgs/msg/Odometry", t, msg)

    def tf(self, t: float, parent: str, child: str, pose, topic: str = "/tf") -> None:
        t_ = self.t
        tr = t_["geometry_msgs/msg/Transform"](
            translation=t_["geometry_msgs/msg/Vector3"](x=float(pose[0]), y=float(pose[1]), z=0.0),
            rotation=self._quat(float(pose[2])),
        )
        ts = t_["geometry_msgs/msg/TransformStamped"](
            header=self._header(t, parent), child_frame_id=child, transform=tr
        )
        self.put(topic, "tf2_msgs/msg/TFMessage", t, t_["tf2_msgs/msg/TFMessage"](transforms=[ts]))


def _stream(n: int = 20, seed: int = 0):
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000.0 + 0.1 * np.arange(n)
    poses = np.cumsum(
        np.column_stack([np.full(n, 0.05), rng.normal(0, 0.01, n), rng.normal(0, 0.02, n)]), axis=0
    )
    ranges = rng.uniform(0.5, 10.0, (n, N_BEAMS)).astype(np.float32)
    ranges[:, ::7] = np.inf
    return stamps, poses, ranges


def _write(path: Path, ros2: bool, tf_odom: bool = False, mount_chain: bool = True, **kw):
    stamps, poses, ranges = _stream()
    with _Bag(path, ros2, **kw) as b:
        b.tf(stamps[0], "base_link", "mast", (0.1, 0.0, 0.0), "/tf_static")
        b.tf(stamps[0], "mast", "laser", (0.05, 0.02, math.pi / 2), "/tf_static")
        for k, t in enumerate(stamps):
            if tf_odom:
                b.tf(t, "odom", "base_link", poses[k])
            else:
                b.odom(t, poses[k])
            b.scan(t, ranges[k])
    return stamps, poses, ranges


@pytest.mark.parametrize(
    ("name", "ros2", "kw"),
    [
        ("a.bag", False, {}),
        ("b", True, {"storage": "mcap"}),
        ("c", True, {"storage": "sqlite3"}),
        ("d.bag", False, {"tf_odom": True}),
    ],
)
def test_a_bag_reads_to_its_scans_odometry_and_mount(tmp_path, name, ros2, kw):
    stamps, poses, ranges = _write(tmp_path / name, ros2, **kw)
    target = tmp_path / name
    if ros2 and kw["storage"] == "mcap":  # the bag's file may be named instead of its folder
        target = next(target.glob("*.mcap"))
    log = read_bag(target)
    assert len(log) == len(stamps)
    np.testing.assert_allclose(log.stamps_s, stamps, rtol=0, atol=1e-6)
    assert log.ranges_m.dtype == np.float32 and np.array_equal(log.ranges_m, ranges)
    np.testing.assert_allclose(log.odometry, poses, rtol=0, atol=1e-9)
    np.testing.assert_allclose(log.laser.mount_pose, (0.15, 0.02, math.pi / 2), atol=1e-12)
    assert log.laser.n_beams == N_BEAMS and log.odometry_source == (
        "/tf" if kw.get("tf_odom") else "/odom"
    )
    assert log.laser.angle_min_rad == pytest.approx(-math.pi / 2, abs=1e-6)


def test_interlaced_scans_sit_on_one_beam_grid(tmp_path):
    """Scans offset by a quarter of the resolution, with one beam fewer, go on the grid of
    the quarter step, each reading at its own angle; the rest is NaN."""
    stamps, poses, _ = _stream(8)
    r = np.linspace(1.0, 20.0, N_BEAMS).astype(np.float32)
    with _Bag(tmp_path / "i.bag", False) as b:
        b.tf(stamps[0], "base_link", "laser", (0.0, 0.0, 0.0), "/tf_static")
        for k, t in enumerate(stamps):
            b.odom(t, poses[k])
            q = k % 4
            b.scan(t, r if q == 0 else r[:-1], -math.pi / 2 + q * INC / 4)
    log = read_bag(tmp_path / "i.bag")
    assert log.laser.n_beams == 4 * (N_BEAMS - 1) + 1
    assert log.laser.angle_increment_rad == pytest.approx(INC / 4, rel=1e-6)
    for k in range(8):
        q = k % 4
        got = log.ranges_m[k]
        have = np.flatnonzero(np.isfinite(got))
        assert np.array_equal(have, q + 4 * np.arange(N_BEAMS if q == 0 else N_BEAMS - 1))
        assert np.array_equal(got[have], r[: len(have)])


def test_beam_grid_refuses_unrelated_layouts():
    assert isinstance(beam_grid(np.array([0.0, 0.0]), np.array([0.01, 0.02]), [3, 3]), str)
    assert isinstance(beam_grid(np.array([0.0, 0.0037]), np.array([0.01, 0.01]), [3, 3]), str)
    g = beam_grid(np.array([0.0, 0.005]), np.array([0.01, 0.01]), np.array([3, 3]))
    assert g.stride == 2 and g.n_beams == 6 and list(g.offsets) == [0, 1]


def _no_laser(p: Path) -> str:
    with _Bag(p, False) as b:
        b.odom(1.0, np.zeros(3))
    return "no sensor_msgs/LaserScan topic"


def _two_lasers(p: Path) -> str:
    stamps, poses, ranges = _stream(3)
    with _Bag(p, False) as b:
        for k, t in enumerate(stamps):
            b.odom(t, poses[k])
            b.scan(t, ranges[k], topic="/front")
            b.scan(t, ranges[k], topic="/rear")
    return "2 sensor_msgs/LaserScan topics (/front, /rear): choose one with --scan-topic"


def _back(p: Path) -> str:
    stamps, poses, ranges = _stream(4)
    with _Bag(p, False) as b:
        b.tf(stamps[0], "base_link", "laser", (0, 0, 0), "/tf_static")
        for k, t in enumerate(stamps[[0, 2, 1, 3]]):  # recorded in order, stamped out of it
            b.odom(stamps[k], poses[k])
            b.scan(t, ranges[k], at=stamps[k])
    return "/scan: time stamps go back at message 2"


def _truncated(p: Path) -> str:
    _write(p, False)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    return "not a readable ROS bag (truncated?)"


def _no_mount(p: Path) -> str:
    stamps, poses, ranges = _stream(3)
    with _Bag(p, False) as b:
        for k, t in enumerate(stamps):
            b.odom(t, poses[k])
            b.scan(t, ranges[k])
    return "/tf_static: no transform from base_link to the scans' frame 'laser'"


def _nan_odometry(p: Path) -> str:
    stamps, poses, ranges = _stream(3)
    poses[1, 0] = np.nan
    with _Bag(p, False) as b:
        b.tf(stamps[0], "base_link", "laser", (0, 0, 0), "/tf_static")
        for k, t in enumerate(stamps):
            b.odom(t, poses[k])
            b.scan(t, ranges[k])
    return "/odom: message 1: its pose is not finite"


@pytest.mark.parametrize(
    "make", [_no_laser, _two_lasers, _back, _truncated, _no_mount, _nan_odometry]
)
def test_bad_bags_are_one_line_naming_file_and_topic(tmp_path, capsys, make):
    p = tmp_path / "bad.bag"
    want = make(p)
    with pytest.raises(BagError) as info:
        read_bag(p)
    msg = str(info.value)
    assert msg.count("\n") == 0 and msg.startswith(f"{p}: ") and want in msg, msg
    rc = main(["replay", str(p), "--localizer", "odometry", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and err.count("\n") == 0 and want in err and "Traceback" not in err


def test_unknown_message_type_named_as_the_scan_topic_is_refused(tmp_path):
    stamps, poses, ranges = _write(tmp_path / "u", True)
    with pytest.raises(BagError, match="/odom: is nav_msgs/msg/Odometry, not sensor_msgs/Lase"):
        read_log(tmp_path / "u", bag=BagOptions(scan_topic="/odom"))
    with pytest.raises(BagError, match="/nope: no such topic"):
        read_bag(tmp_path / "u", odom_topic="/nope")


def test_export_mcap_reads_back_to_the_same_scans_and_odometry(tmp_path):
    """A replay of a CARMEN log kept with its scans, exported by ``export --mcap``, reads
    back to the log's scans, stamps, laser and odometry (up to the odometry frame's origin)."""
    p = tmp_path / "loop.log"
    write_log(p, kind="ROBOTLASER1")
    carmen = read_carmen(p)
    out = tmp_path / "r"
    args = ["replay", str(p), "--localizer", "odometry", "--keep-scans", "--out", str(out)]
    assert main(args) == 0
    assert main(["export", str(out), "--mcap", str(tmp_path / "bag")]) == 0
    log = read_log(tmp_path / "bag")
    assert np.array_equal(log.ranges_m, carmen.ranges_m, equal_nan=True)
    np.testing.assert_allclose(log.stamps_s, carmen.stamps_s, rtol=0, atol=1e-6)
    rel_bag = se2.between(log.odometry[0], log.odometry)
    rel_log = se2.between(carmen.odometry[0], carmen.odometry)
    np.testing.assert_allclose(rel_bag, rel_log, rtol=0, atol=1e-9)
    np.testing.assert_allclose(log.laser.mount_pose, carmen.laser.mount_pose, atol=1e-12)
    for f in ("angle_min_rad", "angle_increment_rad", "range_max_m"):  # float32 fields
        assert getattr(log.laser, f) == pytest.approx(getattr(carmen.laser, f), rel=1e-6)
    # the bag replays like the log (the same odometry estimates, float32 rounding apart)
    out2 = tmp_path / "r2"
    assert (
        main(["replay", str(tmp_path / "bag"), "--localizer", "odometry", "--out", str(out2)]) == 0
    )
