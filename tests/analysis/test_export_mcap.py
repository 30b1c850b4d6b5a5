"""`dynmap-sim export --mcap`: a ROS 2 bag of a CI run, read back with rosbags and mcap."""

from __future__ import annotations

import datetime as dt
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from mcap.reader import make_reader  # noqa: E402
from rosbags.interfaces import QosDurability  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from dynmap_sim.analysis.export import export_tum  # noqa: E402
from dynmap_sim.analysis.export_mcap import (  # noqa: E402
    PERSON_HEIGHT_M,
    export_mcap,
    occupancy_from_logodds,
    pose_topics,
    ros_name,
)
from dynmap_sim.analysis.scenarios import load_scenario  # noqa: E402
from dynmap_sim.cli import main  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner, make_env, run_experiment  # noqa: E402
from dynmap_sim.experiments.scenario import parse_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "worlds/scenarios/ci-apartment-mcl.toml"
#: Two apartment days with its two visitors (days 15-21), 10 s a run, with the localizer
#: that hands over its long-term map as a grid
PEOPLE_AND_MAP = {
    "name": "ci-apartment-people-map",
    "world": "apartment",
    "days": [15, 16],
    "sensor": {"preset": "urg-04lx"},
    "driver": {"kind": "tour", "speed_mps": 0.35, "max_run_s": 10.0},
    "prior": {"map": "walls", "initial_pose": "known"},
    "localizers": [
        {"name": "odometry", "label": "odometry"},
        {"name": "adaptive-memory", "label": "adaptive-memory"},
    ],
}
STORE = get_typestore(Stores.ROS2_JAZZY)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ci") / "results"
    return run_experiment(load_scenario(SCENARIO), out_dir=out, progress=False, workers=1)


@pytest.fixture(scope="module")
def people_results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``run --keep-scans`` of :data:`PEOPLE_AND_MAP`: ranges, people and the grids."""
    out = tmp_path_factory.mktemp("people") / "results"
    scn = parse_scenario(PEOPLE_AND_MAP, ROOT / "worlds/scenarios/people-map.toml")
    return run_experiment(scn, out_dir=out, progress=False, workers=1, keep_scans=True)


@pytest.fixture(scope="module")
def bag(results: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bag") / "run"
    export_mcap(results, out, localizer="mcl-tuned")
    return out


def _read_all(bag: Path) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {}
    with Reader(bag) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, STORE.deserialize_cdr(raw, conn.msgtype)))
    return out


def _yaw(q: object) -> float:
    return 2.0 * np.arctan2(q.z, q.w)  # type: ignore[attr-defined]


def _xyyaw(pose: object) -> np.ndarray:
    p = pose.position  # type: ignore[attr-defined]
    return np.array([p.x, p.y, _yaw(pose.orientation)])  # type: ignore[attr-defined]


def test_counts_per_topic_match_the_store(results: Path, bag: Path) -> None:
    with ResultsDB.open(results) as db:
        n_scans = db.query("SELECT count(*) FROM scans")[0][0]
        n_runs = db.query("SELECT count(*) FROM runs")[0][0]
        labels = db.labels()
    expected = {
        "/tf": n_scans,
        "/odom": n_scans,
        "/truth/pose": n_scans,
        "/tf_static": n_runs,
        "/world/obstacles": n_runs,
        "/plan": n_runs,  # the tour driver's planned path of each run
    } | {topic: n_scans for topic in pose_topics(labels)}
    assert set(pose_topics(labels)) == {"/odometry/pose", "/mcl_tuned/pose", "/mcl_nav2/pose"}
    with Reader(bag) as reader:
        got = {topic: info.msgcount for topic, info in reader.topics.items()}
        assert reader.duration > 0
    assert got == expected  # no /scan (ranges not kept)
    with (bag / f"{bag.name}.mcap").open("rb") as f:
        counted = Counter(ch.topic for _, ch, _ in make_reader(f).iter_messages())
    assert dict(counted) == expected


def test_mcap_file_is_what_foxglove_reads(bag: Path) -> None:
    with (bag / f"{bag.name}.mcap").open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        tf = next(s for s in summary.schemas.values() if s.name == "tf2_msgs/msg/TFMessage")
        assert b"MSG: geometry_msgs/TransformStamped" in tf.data  # dependencies embedded
        statics = [c for c in summary.channels.values() if c.topic == "/tf_static"]
        assert "offered_qos_profiles" in statics[0].metadata
    meta = (bag / "metadata.yaml").read_text()
    assert "storage_identifier: mcap" in meta
    assert "compression_mode: ''" in meta  # no FILE/MESSAGE compression
    with Reader(bag) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos["/tf_static"][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos["/tf"][0].durability == QosDurability.VOLATILE


def test_frames_values_and_stamps(results: Path, bag: Path, tmp_path: Path) -> None:
    msgs = _read_all(bag)
    with ResultsDB.open(results) as db:
        labels = db.labels()
        truth = db.per_scan(0)["truth"]
        est = db.per_scan(labels.index("mcl-tuned"))["estimate"]
        odo = db.per_scan(labels.index("odometry"))["estimate"]
        first_date = db.meta()["first_date"]
        n_seg = len(db.geometry(1, 1)[0])
    # a pose equals the store's truth, and stamps are the TUM export's + the first date
    i = 57
    stamp, pose = msgs["/truth/pose"][i]
    assert pose.header.frame_id == "map"
    np.testing.assert_allclose(_xyyaw(pose.pose), truth[i], atol=1e-9)
    tum = np.loadtxt(export_tum(results, tmp_path)[0])
    epoch_s = (dt.date.fromisoformat(first_date) - dt.date(1970, 1, 1)).days * 86400
    stamps = np.array([s for s, _ in msgs["/truth/pose"]])
    np.testing.assert_array_equal(stamps - epoch_s * 10**9, np.rint(tum[:, 0] * 1e9))
    assert pose.header.stamp.sec * 10**9 + pose.header.stamp.nanosec == stamp
    # /tf: map->odom from the chosen localizer, odom->base_link from the odometry
    _, tf = msgs["/tf"][i]
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [
        ("map", "odom"),
        ("odom", "base_link"),
    ]
    t_odom = tf.transforms[1].transform
    np.testing.assert_allclose(
        [t_odom.translation.x, t_odom.translation.y, _yaw(t_odom.rotation)], odo[i], atol=1e-9
    )
    from dynmap_sim.se2 import compose

    t_map = tf.transforms[0].transform
    map_odom = [t_map.translation.x, t_map.translation.y, _yaw(t_map.rotation)]
    np.testing.assert_allclose(compose(map_odom, odo[i]), est[i], atol=1e-9)
    _, odom = msgs["/odom"][i]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    np.testing.assert_allclose(_xyyaw(odom.pose.pose), odo[i], atol=1e-9)
    _, static = msgs["/tf_static"][0]
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ("base_link", "laser")
    ]
    _, pose = msgs["/mcl_tuned/pose"][i]
    np.testing.assert_allclose(_xyyaw(pose.pose), est[i], atol=1e-9)
    # the obstacles: DELETEALL, then a LINE_LIST per class with both ends of every segment
    _, arr = msgs["/world/obstacles"][0]
    assert arr.markers[0].action == 3
    lines = arr.markers[1:]
    assert {m.type for m in lines} == {5} and {m.header.frame_id for m in lines} == {"map"}
    assert sum(len(m.points) for m in lines) == 2 * n_seg


def test_day_and_run_choose_runs(results: Path, tmp_path: Path) -> None:
    res = export_mcap(results, tmp_path / "day2", days=(2, 2), run=1)
    assert res.counts["/tf_static"] == 1 and res.counts["/tf"] == 201
    assert any("/scan" in note for note in res.notes)
    # a folder without the people's table (no --keep-scans, or written before it) says so
    assert any("/world/people" in n and "--keep-scans" in n for n in res.notes)
    assert any("no OccupancyGrid" in note for note in res.notes)  # MCL keeps no grid


def test_scans_kept_by_the_run_are_exported_as_laser_scans(tmp_path: Path) -> None:
    """``run --keep-scans`` stores every scan's ranges; the bag then has one LaserScan per
    scan in ``laser``, with the laser's geometry and the stored REP-117 ranges bit for bit,
    and a resumed experiment keeps them too."""
    out = tmp_path / "kept"
    scn = load_scenario(SCENARIO)
    first = ExperimentRunner(scn, out, (1, 2), 0, resume=False, keep_scans=True)
    first.run(progress=False, stop_after=1)  # interrupted after day 1
    assert main(["run", str(SCENARIO), "--days", "1-2", "--out", str(out), "-q",
                 "--resume"]) == 0  # fmt: skip
    res = export_mcap(out, tmp_path / "bag")
    assert not any("/scan" in note for note in res.notes)
    # the people were kept too (also after the resume), but days 1-2 have nobody on the floor
    assert any("no people on the floor" in note for note in res.notes)
    assert "/world/people" not in res.counts
    with ResultsDB.open(out) as db:
        laser = db.meta()["laser"]
        runs = db.query("SELECT day, run, n_steps FROM runs ORDER BY day, run")
        assert [r[:2] for r in runs] == [(1, 1), (2, 1)]  # day 2 from the resumed run
        stored = np.concatenate([db.scan_ranges(d, r) for d, r, _ in runs])
    assert stored.shape == (sum(r[2] for r in runs), laser["n_beams"])
    assert np.isposinf(stored).any() and np.isfinite(stored).mean() > 0.5
    msgs = [m for _, m in _read_all(tmp_path / "bag")["/scan"]]
    assert res.counts["/scan"] == len(msgs) == len(stored)
    m = msgs[0]
    assert m.header.frame_id == "laser"
    assert m.angle_min == pytest.approx(laser["angle_min_rad"], abs=1e-6)
    assert m.angle_increment == pytest.approx(laser["angle_increment_rad"], abs=1e-9)
    assert m.range_max == pytest.approx(laser["range_max_m"])
    assert m.scan_time == pytest.approx(laser["scan_period_s"])
    np.testing.assert_array_equal(np.stack([m.ranges for m in msgs]), stored)


def test_ros_names() -> None:
    assert ros_name("mcl-tuned") == "mcl_tuned"
    assert ros_name("2nd try") == "loc_2nd_try"
    assert pose_topics(["a-b", "a_b", "truth"]) == ["/a_b/pose", "/a_b_1/pose", "/truth_2/pose"]


def test_cli_refuses_to_overwrite_and_names_the_extra(
    results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    out = tmp_path / "bag"
    assert main(["export", str(results), "--mcap", str(out), "--day", "1"]) == 0
    assert "/truth/pose 201" in capsys.readouterr().out
    assert main(["export", str(results), "--mcap", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["export", str(results), "--mcap", str(out), "--force"]) == 0
    assert "/truth/pose 402" in capsys.readouterr().out
    assert main(["export", str(results), "--day", "1"]) == 2
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)  # the extra is not installed
    assert main(["export", str(results), "--mcap", str(tmp_path / "other")]) == 2
    assert 'pip install "dynmap-sim[ros]"' in capsys.readouterr().err
    assert not (tmp_path / "other").exists()


def test_missing_folders_above_the_bag_are_made_as_for_parquet(
    results: Path, tmp_path: Path
) -> None:
    out = tmp_path / "bags" / "deeper" / "x"
    assert main(["export", str(results), "--mcap", str(out), "--day", "1"]) == 0
    assert (out / "x.mcap").is_file() and (out / "metadata.yaml").is_file()


def test_people_are_exported_as_cylinders_at_every_scan(
    people_results: Path, tmp_path: Path
) -> None:
    """``run --keep-scans`` keeps the people's positions per scan; the bag has one
    MarkerArray per scan on ``/world/people``: a CYLINDER per person (ns ``people``, id its
    index, stable over the run) at the stored position, its body's diameter, living one
    scan period."""
    res = export_mcap(people_results, tmp_path / "bag")
    assert not any("people" in note or "OccupancyGrid" in note for note in res.notes)
    with ResultsDB.open(people_results) as db:
        runs = [(d, r) for d, r in db.query("SELECT day, run FROM runs ORDER BY day, run")]
        tracks = [db.scan_people(d, r) for d, r in runs]
        period = db.meta()["laser"]["scan_period_s"]
        n_scans = db.query("SELECT count(*) FROM scans")[0][0]
    assert all(t is not None and len(t.ids) == 2 for t in tracks)  # the two visitors
    stored = np.concatenate([t.xy for t in tracks])
    assert stored.shape == (n_scans, 2, 2) and np.isfinite(stored).all()
    msgs = _read_all(tmp_path / "bag")["/world/people"]
    assert res.counts["/world/people"] == len(msgs) == n_scans
    with (tmp_path / "bag" / "bag.mcap").open("rb") as f:
        n_mcap = sum(ch.topic == "/world/people" for _, ch, _ in make_reader(f).iter_messages())
    assert n_mcap == n_scans
    truth_stamps = [s for s, _ in _read_all(tmp_path / "bag")["/truth/pose"]]
    assert [s for s, _ in msgs] == truth_stamps  # one per scan, at the scan's stamp
    for i in (0, 57, n_scans - 1):
        markers = msgs[i][1].markers
        assert [(m.ns, m.id, m.type, m.action) for m in markers] == [
            ("people", 0, 3, 0),
            ("people", 1, 3, 0),
        ]
        for j, m in enumerate(markers):
            assert m.header.frame_id == "map"
            np.testing.assert_allclose([m.pose.position.x, m.pose.position.y], stored[i, j])
            assert m.pose.position.z == pytest.approx(PERSON_HEIGHT_M / 2)
            assert m.scale.x == m.scale.y == pytest.approx(2 * tracks[0].radius_m[j])
            assert m.lifetime.sec * 1e9 + m.lifetime.nanosec == pytest.approx(period * 1e9)
    # they walk: at most 1.1 m/s (the visitors' top speed) between scans, and move
    step = np.hypot(*np.diff(tracks[0].xy, axis=0).transpose(2, 0, 1))
    assert step.max() <= 1.1 * period + 1e-3 and step.sum(axis=0).min() > 1.0


def test_the_stored_people_are_the_engines_truth(people_results: Path) -> None:
    """The first scan's people are where the env puts them on reset of that day and run."""
    scn = parse_scenario(PEOPLE_AND_MAP, ROOT / "worlds/scenarios/people-map.toml")
    env = make_env(scn)
    try:
        with ResultsDB.open(people_results) as db:
            for day, run in db.query("SELECT day, run FROM runs ORDER BY day, run"):
                track = db.scan_people(day, run)
                _, info = env.reset(seed=0, options={"day": day, "run": run})
                now = env.unwrapped.people()
                assert track.ids == now.ids == ("person:visitor_loop:0", "person:visitor:0")
                np.testing.assert_allclose(track.xy[0], now.xy, atol=1e-5)  # float32
                np.testing.assert_allclose(track.xy[0], info["truth"]["people"][:2, :2], atol=1e-5)
                np.testing.assert_array_equal(track.radius_m, now.radius)
    finally:
        env.close()


def _cell(grid: object, x: float, y: float) -> int:
    """The occupancy of the OccupancyGrid's cell holding ``(x, y)`` by ROS conventions."""
    info = grid.info  # type: ignore[attr-defined]
    ix = int((x - info.origin.position.x) // info.resolution)
    iy = int((y - info.origin.position.y) // info.resolution)
    return int(grid.data[iy * info.width + ix])  # type: ignore[attr-defined]


def test_a_localizers_grid_is_exported_as_an_occupancy_grid(
    people_results: Path, tmp_path: Path
) -> None:
    """adaptive-memory hands over its long-term map after each day; the bag has it on
    ``/adaptive_memory/map`` once per run (the day's grid), latched, in ``map``, with the
    stored shape, resolution and origin, cells row-major from the origin."""
    res = export_mcap(people_results, tmp_path / "bag")
    with ResultsDB.open(people_results) as db:
        labels = db.labels()
        arts = db.artifacts(labels.index("adaptive-memory"), "ltm")
        assert db.scan_people(1, 1) is None  # no such run: None, as for an old folder
    assert [d for d, _ in arts] == [15, 16]
    env = make_env(parse_scenario(PEOPLE_AND_MAP, ROOT / "worlds/scenarios/people-map.toml"))
    walls = np.asarray(env.unwrapped.world_facts().wall_segments, dtype=float)  # the prior
    env.close()
    assert "/odometry/map" not in res.counts and res.counts["/adaptive_memory/map"] == 2
    with Reader(tmp_path / "bag") as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos["/adaptive_memory/map"][0].durability == QosDurability.TRANSIENT_LOCAL
    with (tmp_path / "bag" / "bag.mcap").open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channel = next(c for c in summary.channels.values() if c.topic == "/adaptive_memory/map")
        assert summary.schemas[channel.schema_id].name == "nav_msgs/msg/OccupancyGrid"
        assert summary.statistics.channel_message_counts[channel.id] == 2
    msgs = _read_all(tmp_path / "bag")
    first_stamps = [msgs["/tf_static"][k][0] for k in range(2)]
    for (stamp, grid), (_, art), t0 in zip(
        msgs["/adaptive_memory/map"], arts, first_stamps, strict=True
    ):
        assert stamp == t0 and grid.header.frame_id == "map"
        lo = art["logodds"]
        h, w = lo.shape
        assert (grid.info.height, grid.info.width) == (h, w) and len(grid.data) == h * w
        assert grid.info.resolution == pytest.approx(0.05)
        origin = grid.info.origin
        np.testing.assert_allclose([origin.position.x, origin.position.y], art["origin_m"])
        assert (origin.orientation.w, origin.orientation.z) == (1.0, 0.0)
        np.testing.assert_array_equal(grid.data, occupancy_from_logodds(lo).ravel())
        data = grid.data.reshape(h, w)
        assert set(np.unique(data)) <= {-1, *range(101)} and (data == -1).any()
        # known cells, at the ROS index ((y - oy) // res) * width + (x - ox) // res: the
        # prior's outer wall (its outline's edge y = -0.1 m from x = -0.1 to 8.1 m) is pinned
        # at l_max = 3.5 -> 97 in the cell just above the edge; outside it, never observed
        (x0, y0, x1, y1) = walls[0]
        assert y0 == y1 == -0.1 and x1 - x0 > 8
        assert _cell(grid, 4.0, -0.1 + 0.025) == 97 and _cell(grid, 4.0, -0.1 - 0.025) == -1
    # a bag of day 15 alone has the map after day 15
    res = export_mcap(people_results, tmp_path / "day15", days=(15, 15))
    ((_, only),) = _read_all(tmp_path / "day15")["/adaptive_memory/map"]
    np.testing.assert_array_equal(only.data, occupancy_from_logodds(arts[0][1]["logodds"]).ravel())


def test_occupancy_from_logodds_follows_ros() -> None:
    lo = np.array([[0.0, 3.5, -2.0], [np.nan, 50.0, -60.0]], dtype=np.float32)
    np.testing.assert_array_equal(
        occupancy_from_logodds(lo), np.array([[-1, 97, 12], [-1, 100, 0]], dtype=np.int8)
    )
