"""Watching a run (extra ``video``): ``dynmap-sim video`` of a stored run, read back with
imageio; bad arguments; Gymnasium's ``RecordVideo`` on the env."""

from pathlib import Path

import numpy as np
import pytest

iio = pytest.importorskip("imageio.v2")
pytest.importorskip("imageio_ffmpeg")

from dynmap_sim.analysis import video  # noqa: E402
from dynmap_sim.cli import main  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402
from dynmap_sim.experiments.runner import run_experiment  # noqa: E402
from dynmap_sim.experiments.scenario import load_scenario, parse_scenario  # noqa: E402
from dynmap_sim.raster import CLASS_RGB  # noqa: E402
from dynmap_sim.types import BeamClass  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("video") / "res"
    run_experiment(load_scenario(CI), out_dir=out, days=(1, 1), progress=False, workers=1)
    return out


def _scans(results: Path) -> np.ndarray:
    with ResultsDB.open(results) as db:
        rows = db.query("SELECT x, y FROM scans WHERE day=1 AND run=1 ORDER BY step")
    return np.array(rows, dtype=np.float64)


def _cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_video_writes_a_playable_mp4_with_a_frame_per_scan(results, tmp_path, capsys):
    out = tmp_path / "run.mp4"
    code, stdout, err = _cli(capsys, "video", results, "--day", 1, "--run", 1, "-o", out, "-q")
    assert code == 0, err
    n = len(_scans(results))
    reader = iio.get_reader(out, format="ffmpeg")
    meta = reader.get_meta_data()
    frames = [frame for frame in reader]  # noqa: C416 - list() asks the reader's len: inf
    reader.close()
    assert meta["codec"] == "h264" and meta["fps"] == 10.0  # the urg-04lx's 10 Hz: real time
    assert len(frames) == n > 100
    w, h = meta["size"]
    assert frames[0].shape == (h, w, 3) and w % 16 == 0 and h % 16 == 0
    assert f"{n} frames, {w}x{h} px" in stdout
    assert not np.array_equal(frames[0], frames[-1])  # the robot moved
    assert "no people" in err and "--keep-scans" in err  # what cannot be drawn is said
    assert [p.name for p in tmp_path.iterdir()] == ["run.mp4"]  # no temporary file left


def test_frames_draw_the_true_pose_where_it_was(results):
    with ResultsDB.open(results) as db:
        run = video.load_run(db, 1, 1, [])  # the truth alone
    frames = video._Frames(run, 320)
    assert len(frames) == len(run.t_s)
    for i, frame in enumerate(frames):
        if i in (0, len(frames) - 1):
            x, y, theta = run.truth[i]  # behind the centre: the disc, not the heading line
            r, c = frames.canvas.px(np.array([x - 0.1 * np.cos(theta), y - 0.1 * np.sin(theta)]))
            pixel = frame[frames.header_px + r, frames.map_left + c]
            assert tuple(pixel) == tuple(video._TRUTH), i


def test_kept_scans_are_drawn_where_their_returns_were(tmp_path):
    """With ``run --keep-scans`` each frame draws its scan's returns from the true pose: a
    return's pixel has the scan colour, and the returns lie on the stored obstacles."""
    out = tmp_path / "kept"
    run_experiment(
        load_scenario(CI), out_dir=out, days=(1, 1), progress=False, workers=1, keep_scans=True
    )
    with ResultsDB.open(out) as db:
        run = video.load_run(db, 1, 1, [])
        ranges = db.scan_ranges(1, 1)
    assert run.scan_xy is not None and run.scan_xy.shape == (*ranges.shape, 2)
    hits = run.scan_xy[0][np.isfinite(run.scan_xy[0, :, 0])]
    assert len(hits) == np.isfinite(ranges[0]).sum() > 100
    # every return lies on (within the URG's range noise of) a stored segment
    seg = run.segments
    a, b = seg[:, :2], seg[:, 2:]
    u = np.clip(np.einsum("nsk,sk->ns", hits[:, None] - a, b - a) / ((b - a) ** 2).sum(1), 0, 1)
    d = np.linalg.norm(hits[:, None] - (a + u[..., None] * (b - a)), axis=2).min(axis=1)
    assert np.median(d) < 0.02 and np.mean(d < 0.1) > 0.9  # people are not segments
    frames = video._Frames(run, 320)
    frame = next(iter(frames))
    r, c = frames.canvas.px(hits[len(hits) // 2])
    assert tuple(frame[frames.header_px + r, frames.map_left + c]) == tuple(video._SCAN)


def test_gif_with_fps_size_and_localizer(results, tmp_path, capsys):
    out = tmp_path / "run.gif"
    args = ("video", results, "--day", 1, "--run", 1, "-o", out, "-q", "--fps", 20)
    code, stdout, err = _cli(capsys, *args, "--size", 96, "--localizer", "odometry")
    assert code == 0, err
    frames = iio.mimread(out, memtest=False)
    assert len(frames) == len(_scans(results))
    assert "at 20 fps" in stdout


def test_an_existing_file_is_replaced_only_with_force(results, tmp_path, capsys):
    out = tmp_path / "run.gif"
    out.write_bytes(b"keep me")
    code, _, err = _cli(capsys, "video", results, "--day", 1, "--run", 1, "-o", out, "-q")
    assert code == 2 and "exists; pass --force" in err and out.read_bytes() == b"keep me"
    args = ("video", results, "--day", 1, "--run", 1, "-o", out, "-q", "--size", 64, "--force")
    code, stdout, err = _cli(capsys, *args)
    assert code == 0, err
    assert "replaced the earlier file" in stdout and out.read_bytes()[:6] == b"GIF89a"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--day", 2, "--run", 1, "-o", "{tmp}/a.mp4"], "--day 2: {res} holds day 1"),
        (["--day", 1, "--run", 3, "-o", "{tmp}/a.mp4"], "--run 3: day 1 of {res} holds run 1"),
        (["--day", 1, "--run", 1, "-o", "{tmp}/a.avi"], "a video is .mp4 or .gif, not '.avi'"),
        (["--day", 1, "--run", 1, "-o", "{tmp}/a"], "a video is .mp4 or .gif, not 'no suffix'"),
        (["--day", 1, "--run", 1, "-o", "{tmp}/no/a.mp4"], "folder {tmp}/no does not exist"),
        (["--day", 1, "--run", 1, "-o", "{tmp}"], "is a folder"),
        (["--day", 1, "--run", 1, "--localizer", "amcl", "-o", "{tmp}/a.mp4"], "its localizers"),
        (["--day", 1, "--run", 1, "--size", 9, "-o", "{tmp}/a.mp4"], "--size must be"),
    ],
)
def test_bad_arguments_are_one_line_errors(results, tmp_path, capsys, args, message):
    filled = [str(a).format(tmp=tmp_path) for a in args]
    code, stdout, err = _cli(capsys, "video", results, *filled, "-q")
    assert code == 2 and stdout == ""
    assert err.count("\n") == 1 and err.startswith("error: "), err
    assert message.format(tmp=tmp_path, res=results) in err
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_folder_without_results_is_refused(tmp_path, capsys):
    code, _, err = _cli(capsys, "video", tmp_path, "--day", 1, "--run", 1, "-o", tmp_path / "a.mp4")
    assert code == 2 and err.count("\n") == 1 and "no results database here" in err


@pytest.mark.parametrize(
    "args", [["--day", 0, "--run", 1], ["--run", 1], ["--day", 1, "--run", "x"]]
)
def test_day_and_run_are_positive_integers(results, tmp_path, capsys, args):
    with pytest.raises(SystemExit) as ei:
        main(["video", str(results), *map(str, args), "-o", str(tmp_path / "a.mp4")])
    assert ei.value.code == 2
    assert "error:" in capsys.readouterr().err


def test_record_video_records_an_episode_of_the_env(tmp_path):
    """Gymnasium's RecordVideo (moviepy >= 2) on an env made with render_mode="rgb_array"."""
    pytest.importorskip("moviepy")
    import gymnasium
    from gymnasium.wrappers import RecordVideo

    import dynmap_sim  # noqa: F401  (registers the envs)

    env = gymnasium.make("dynmap_sim/Apartment-v0", render_mode="rgb_array", max_episode_steps=15)
    env = RecordVideo(env, str(tmp_path / "videos"), episode_trigger=lambda _: True)
    env.reset(seed=0)
    done, steps = False, 0
    while not done:
        _, _, terminated, truncated, _ = env.step(np.array([0.3, 0.2], np.float32))
        done, steps = terminated or truncated, steps + 1
    env.close()
    (mp4,) = (tmp_path / "videos").glob("*.mp4")
    reader = iio.get_reader(mp4, format="ffmpeg")
    assert reader.count_frames() == steps + 1  # the reset's frame and one per step
    reader.close()


def test_kept_people_are_drawn_as_red_discs_where_they_were(tmp_path):
    """With ``run --keep-scans`` the people are kept too: each frame draws them, a disc of
    their body radius in the person colour at their stored position (apartment day 15: two
    visitors)."""
    scn = parse_scenario(
        {
            "name": "video-people",
            "world": "apartment",
            "days": [15, 15],
            "driver": {"kind": "tour", "speed_mps": 0.35, "max_run_s": 5.0},
            "prior": {"map": "walls", "initial_pose": "known"},
            "localizers": [{"name": "odometry", "label": "odometry"}],
        },
        ROOT / "worlds" / "scenarios" / "video-people.toml",
    )
    out = tmp_path / "people"
    run_experiment(scn, out_dir=out, progress=False, workers=1, keep_scans=True)
    with ResultsDB.open(out) as db:
        run = video.load_run(db, 15, 1, [])
    assert run.people is not None and run.people.shape[0] == len(run.t_s)
    on_floor = run.people[0][np.isfinite(run.people[0, :, 0])]
    assert len(on_floor) >= 1
    frames = video._Frames(run, 480)
    frame = next(iter(frames))
    for x, y, radius in on_floor:
        assert radius > 0.1
        r, c = frames.canvas.px(np.array([x, y]))
        pixel = frame[frames.header_px + r, frames.map_left + c]
        assert tuple(pixel) in {tuple(CLASS_RGB[BeamClass.PERSON]), tuple(video._SCAN)}
    assert "people" in [text for text, _ in frames.legend]
