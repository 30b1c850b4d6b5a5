"""One bad world file per kind of mistake: each gives the expected field and message.

Each case edits the valid ``data/room.toml`` (replacing one line) and loads the file through
:func:`load_world`, the same path the CLI takes.
"""

from pathlib import Path

import pytest

from dynmap_sim.world import WorldFileError, load_world

ROOM = Path(__file__).parent / "data" / "room.toml"

# (case, text to replace, replacement, field path, message fragment)
CASES = [
    (
        "negative size",
        "size = [1.0, 0.6]",
        "size = [1.0, -0.6]",
        "objects.0.size",
        "sizes must be > 0",
    ),
    (
        "unknown field",
        'kind = "exhibit"',
        'kind = "exhibit"\ncolour = "red"',
        "objects.3.colour",
        "Extra inputs are not permitted",
    ),
    ("unknown kind", 'kind = "exhibit"', 'kind = "statue"', "objects.3.kind", "Input should be"),
    ("wrong type", "n_days = 10", 'n_days = "ten"', "calendar.n_days", "valid integer"),
    (
        "bad clock time",
        'runs = ["09:00", "14:00"]',
        'runs = ["9 am", "14:00"]',
        "calendar.runs",
        "HH:MM",
    ),
    (
        "runs out of order",
        'runs = ["09:00", "14:00"]',
        'runs = ["14:00", "09:00"]',
        "calendar.runs",
        "strictly increasing",
    ),
    (
        "bad region",
        "region = [0.4, 2.4, 2.8, 3.8]",
        "region = [2.8, 2.4, 0.4, 3.8]",
        "schedule.1.region",
        "xmax > xmin",
    ),
    ("duplicate id", 'id = "chair_2"', 'id = "chair_1"', "objects.2.id", "duplicate id 'chair_1'"),
    (
        "unknown group",
        'group = "expo"\nstart',
        'group = "expos"\nstart',
        "schedule.0.group",
        "unknown group 'expos'",
    ),
    (
        "unknown target",
        'target = "door"',
        'target = "gate"',
        "schedule.2.target",
        "unknown object id 'gate'",
    ),
    ("day outside the calendar", "end = 5", "end = 12", "schedule.0.end", "outside the calendar"),
    (
        "date outside the calendar",
        "start = 2024-01-03",
        "start = 2023-12-20",
        "schedule.0.start",
        "outside the calendar",
    ),
    ("run beyond the day's runs", "run = 2", "run = 3", "schedule.2.run", "2 per day"),
    (
        "object inside a wall",
        "pose = [3.0, 3.0, 0.0]",
        "pose = [3.0, 3.9, 0.0]",
        "objects.0",
        "inside wall 'outer.2'",
    ),
    (
        "route through a wall",
        "[5.0, 3.0]]",
        "[5.0, 3.0], [7.0, 3.0]]",
        "robot.route.2",
        "goes through wall",
    ),
    (
        "start inside a wall",
        "start = [1.0, 1.0, 0.0]",
        "start = [0.05, 1.0, 0.0]",
        "robot.start",
        "inside wall",
    ),
    (
        "door event on a non-door",
        'target = "door"',
        'target = "table"',
        "schedule.2.target",
        "is not a door",
    ),
    ("end before start", "end = 5", "end = 2", "schedule.0.end", "before start"),
    (
        "people area outside",
        "areas = [[0.5, 0.5, 5.5, 2.2]]",
        "areas = [[0.5, 0.5, 9.5, 2.2]]",
        "people.0.areas.0",
        "outside the world bounds",
    ),
    (
        "shuffled object does not fit",
        "region = [0.4, 2.4, 2.8, 3.8]",
        "region = [0.4, 2.4, 2.8, 2.8]",
        "schedule.1.region",
        "'chair_1' does not fit in the region",
    ),
    ("bad calendar moment", "at = 4", 'at = "soon"', "schedule.2.at", "working-day number"),
    (
        "unknown action",
        'action = "open"',
        'action = "teleport"',
        "schedule.2",
        "does not match any of the expected tags",
    ),
]


def test_the_room_is_valid():
    spec = load_world(ROOM)
    assert spec.name == "room"


@pytest.mark.parametrize("case,old,new,loc,msg", CASES, ids=[c[0] for c in CASES])
def test_bad_file(tmp_path, case, old, new, loc, msg):
    text = ROOM.read_text()
    assert old in text, case
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(old, new, 1))
    with pytest.raises(WorldFileError) as info:
        load_world(bad)
    err = info.value
    assert err.path == str(bad)
    assert any(lo == loc and msg in m for lo, m in err.errors), err.errors
    assert f"{loc}: " in str(err)


# -- reading the file itself: only regular files of sane size, a BOM is not content ------------


def _only(exc: WorldFileError) -> str:
    assert len(exc.errors) == 1, exc.errors
    return exc.errors[0][1]


def test_a_utf8_byte_order_mark_is_not_a_syntax_error(tmp_path):
    bom = tmp_path / "bom.toml"
    bom.write_text(ROOM.read_text(), encoding="utf-8-sig")
    assert bom.read_bytes()[:3] == b"\xef\xbb\xbf"
    assert load_world(bom).name == "room"


@pytest.mark.parametrize("what", ["device", "directory"])
def test_a_device_or_folder_is_refused_at_once(tmp_path, what):
    path = Path("/dev/zero") if what == "device" else tmp_path
    with pytest.raises(WorldFileError) as ei:
        load_world(path)
    assert _only(ei.value) == f"not a regular file but a {what}"
    assert str(ei.value) == f"{path}: not a regular file but a {what}"  # one line


def test_a_fifo_is_refused_without_blocking(tmp_path):
    import os

    fifo = tmp_path / "world.toml"
    os.mkfifo(fifo)  # opening it for reading would wait for a writer forever
    with pytest.raises(WorldFileError) as ei:
        load_world(fifo)
    assert _only(ei.value) == "not a regular file but a FIFO"


def test_a_huge_file_is_refused_before_it_is_read(tmp_path, monkeypatch):
    from dynmap_sim import errors

    monkeypatch.setattr(errors, "MAX_FILE_BYTES", 1000)
    big = tmp_path / "big.toml"
    big.write_text(ROOM.read_text() + "#" * 2000)
    with pytest.raises(WorldFileError) as ei:
        load_world(big)
    assert "file too large" in _only(ei.value) and "limit" in _only(ei.value)


def test_absurd_nesting_is_a_clean_error(tmp_path):
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(WorldFileError) as ei:
        load_world(deep)
    assert _only(ei.value) == "TOML nested too deeply to read"


def test_not_utf8_is_a_clean_error(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(ROOM.read_text().replace('"room"', '"r\xf6om"').encode("latin-1"))
    with pytest.raises(WorldFileError) as ei:
        load_world(bad)
    assert "not UTF-8 text" in _only(ei.value)


@pytest.mark.parametrize("start", ["9999-12-31", "9999-12-01"])
def test_a_calendar_running_past_year_9999_is_a_field_error(tmp_path, start):
    bad = tmp_path / "late.toml"
    bad.write_text(ROOM.read_text().replace("start = 2024-01-01", f"start = {start}"))
    with pytest.raises(WorldFileError) as ei:
        load_world(bad)
    loc, msg = ei.value.errors[0]
    assert loc == "calendar" and f"from {start} may run past 9999-12-31" in msg


def test_a_file_swapped_for_a_fifo_after_the_check_is_still_refused(tmp_path, monkeypatch):
    import os

    from dynmap_sim import errors

    fifo = tmp_path / "world.toml"
    os.mkfifo(fifo)
    monkeypatch.setattr(errors, "regular_file_size", lambda path, error_cls: 0)  # "was regular"
    with pytest.raises(WorldFileError) as ei:
        load_world(fifo)
    assert _only(ei.value) == "not a regular file but a FIFO"
