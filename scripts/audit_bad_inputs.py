"""Audit: feed the CLI hundreds of bad invocations and mutated files; count tracebacks and hangs.

Issue 14 asks for a scripted run of at least 500 bad invocations and mutated files with no
traceback and no hang. This script builds them systematically rather than by hand:

* **bad arguments** — for every command, every option and positional that takes a value is
  replaced, one at a time, by each of :data:`HOSTILE_ARGS` (out-of-range days, runs and seeds,
  bad paths, devices, FIFOs, folders of the wrong kind, unknown formats, absurd lengths), the
  other arguments being a valid, cheap invocation;
* **mutated files** — ``validate`` of shipped world and scenario files with one assignment's
  value replaced by one of :data:`HOSTILE_VALUES` (seeded sample of all line x value pairs).

Each call runs in-process through :func:`dynmap_sim.cli.main` under a per-call alarm; it
counts as a *traceback* when an exception other than ``SystemExit`` escapes or ``Traceback``
appears in its output, as a *hang* when the alarm fires. Accepted values (exit 0) are fine:
a hostile-looking value may be legal (``--seed 0``). Prints a table and writes JSON.

    python scripts/audit_bad_inputs.py [--files 600] [--timeout-s 120] [--json audit.json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import random
import re
import signal
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from tqdm import tqdm

from dynmap_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml"
#: Argument values a careless user or a broken script passes; ``{tmp}`` and ``{fifo}`` are
#: filled in (an existing folder, a named pipe).
HOSTILE_ARGS = (
    "", "-1", "0", "99", "2-1", "1-999", "x", "1e308", "nan", "-inf", "18446744073709551616",
    "/dev/zero", "/dev/null/x", "{tmp}/missing/folder/f.png", "{tmp}", "{fifo}", "../../..",
    "f.xyz", "a" * 5000, "tcp://256.0.0.1:0", "x.y=1,2",
)  # fmt: skip
#: Values put in place of one assignment of a TOML file.
HOSTILE_VALUES = (
    "-1", "0", "1e308", "-1e308", "nan", "inf", '"x"', '""', "[]", "[1, 2]", "[[1]]", "{}",
    "true", "9999-12-31", "0001-01-01", "18446744073709551616", '"../../x"', "[nan, 0, 0]",
    "[1e308, 1e308, 0]", '".relative:X"', '"os:path"', "{ noise = 5 }", "[" * 3000 + "]" * 3000,
    '"\\u0000"', "2024-02-30",
)  # fmt: skip
FILES = (
    "worlds/apartment.toml", "worlds/lab.toml", "worlds/office.toml",
    "worlds/scenarios/ci-apartment.toml", "worlds/scenarios/ci-apartment-kidnap.toml",
    "worlds/scenarios/ci-apartment-autonomous.toml", "worlds/scenarios/lab-5w.toml",
    "worlds/sweeps/apartment-week.toml",
)  # fmt: skip
ASSIGNMENT = re.compile(r"^\s*[A-Za-z_]+\s*=")


class _Alarm(Exception):
    pass


def _on_alarm(signum, frame):  # noqa: ARG001 - signal handler signature
    raise _Alarm


def _call(argv: list[str], timeout_s: int) -> tuple[str, int | None, str]:
    """Run the CLI in-process: ('ok'|'traceback'|'hang', exit code, last output line)."""
    out, err = io.StringIO(), io.StringIO()
    signal.alarm(timeout_s)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse's exit 2, --help
                code = exc.code if isinstance(exc.code, int) else 1
        kind = "traceback" if "Traceback" in out.getvalue() + err.getvalue() else "ok"
    except _Alarm:
        return "hang", None, ""
    except BaseException as exc:  # noqa: BLE001 - the very thing counted
        return "traceback", None, f"{type(exc).__name__}: {exc}"[:200]
    finally:
        signal.alarm(0)
    lines = (err.getvalue() or out.getvalue()).strip().splitlines()
    return kind, code, lines[-1][:200] if lines else ""


def _tiny_log(path: Path, n_scans: int = 30) -> None:
    """A CARMEN log of a robot driving straight in a 6 m corridor (FLASER + ODOM)."""
    lines = []
    for k in range(n_scans):
        x, t = 0.05 * k, 0.2 * k
        ranges = " ".join(
            f"{min(1.5 / max(abs(math.sin(math.radians(i))), 0.2), 8.0):.3f}" for i in range(181)
        )
        lines.append(f"ODOM {x:.3f} 0 0 0 0 0 {t:.6f} h {t:.6f}")
        lines.append(f"FLASER 181 {ranges} {x:.3f} 0 0 {x:.3f} 0 0 {t:.6f} h {t:.6f}")
    path.write_text("\n".join(lines) + "\n")


def bad_invocations(tmp: Path, results: Path, log: Path) -> list[list[str]]:
    """Every command's valid cheap invocation with one value at a time made hostile."""
    fifo = tmp / "fifo"
    os.mkfifo(fifo)
    (tmp / "folder").mkdir()
    out = iter(range(10**6))

    def fresh(suffix: str = "") -> str:
        return str(tmp / f"out{next(out)}{suffix}")

    # command -> (valid argv with {slots}, slot names that take hostile values)
    bases = {
        "validate": (["{file}"], ["file"]),
        "schema": (["{kind}", "-o", "{o}"], ["kind", "o"]),
        "render-world": (
            ["{world}", "--day", "{day}", "--run", "{run}", "--seed", "{seed}", "-o", "{o}"],
            ["world", "day", "run", "seed", "o"],
        ),
        "run": (
            [
                "{scenario}",
                "--days",
                "{days}",
                "--seed",
                "{seed}",
                "--out",
                "{out}",
                "-q",
                "--workers",
                "{workers}",
            ],
            ["scenario", "days", "seed", "out", "workers"],
        ),  # fmt: skip
        "report": (["{dir}"], ["dir"]),
        "export": (
            [
                "{dir}",
                "--tum",
                "{tum}",
                "--localizer",
                "{localizer}",
                "--day",
                "{day}",
                "--run",
                "{run}",
            ],
            ["dir", "tum", "localizer", "day", "run"],
        ),  # fmt: skip
        "export-parquet": (["{dir}", "--parquet", "{parquet}"], ["parquet"]),
        "export-mcap": (["{dir}", "--mcap", "{mcap}"], ["mcap"]),
        "video": (
            [
                "{dir}",
                "--day",
                "{day}",
                "--run",
                "{run}",
                "-o",
                "{o}",
                "--fps",
                "{fps}",
                "--size",
                "{size}",
                "-q",
            ],
            ["dir", "day", "run", "o", "fps", "size"],
        ),  # fmt: skip
        "check": (["{scenario}", "--out", "{out}", "-q"], ["scenario"]),
        "replay": (
            ["{log}", "--localizer", "{localizer}", "--out", "{out}"],
            ["log", "localizer", "out"],
        ),
        "sweep": (
            [
                "{scenario}",
                "--seeds",
                "{seeds}",
                "--days",
                "{days}",
                "--only",
                "{only}",
                "--set",
                "{set}",
                "--out",
                "{out}",
                "--workers",
                "{workers}",
                "-q",
            ],
            ["scenario", "seeds", "days", "only", "set", "out", "workers"],
        ),  # fmt: skip
        "toy": (["--out", "{out}", "--seed", "{seed}"], ["out", "seed"]),
    }
    valid = {
        "file": str(SCENARIO), "kind": "world", "world": "apartment", "day": "1", "run": "1",
        "seed": "0", "scenario": str(SCENARIO), "days": "1-1", "workers": "1",
        "dir": str(results), "localizer": "odometry", "fps": "5", "size": "200",
        "log": str(log), "seeds": "0-0", "only": "odometry", "set": "odometry.x=1",
    }  # fmt: skip
    suffix = {"o": ".png", "tum": "", "parquet": "", "mcap": "", "out": ""}
    calls = []
    for command, (argv, slots) in bases.items():
        for slot in slots:
            for value in HOSTILE_ARGS:
                value = value.format(tmp=tmp / "folder", fifo=fifo)

                def fill(name: str, _slot=slot, _value=value) -> str:
                    if name == _slot:
                        return _value
                    return valid.get(name) or fresh(suffix.get(name, ""))

                args = [re.sub(r"\{(\w+)\}", lambda m: fill(m.group(1)), a) for a in argv]
                calls.append([command.split("-")[0] if command.startswith("export") else command,
                              *args])  # fmt: skip
    return calls


def mutated_files(tmp: Path, n: int, seed: int = 14) -> list[list[str]]:
    """``validate`` of ``n`` files, each a shipped file with one value made hostile."""
    pairs = []
    for rel in FILES:
        lines = (ROOT / rel).read_text().splitlines()
        for k, line in enumerate(lines):
            if ASSIGNMENT.match(line):
                pairs.extend((rel, k, v) for v in HOSTILE_VALUES)
    rng = random.Random(seed)
    calls = []
    for i, (rel, k, value) in enumerate(rng.sample(pairs, min(n, len(pairs)))):
        lines = (ROOT / rel).read_text().splitlines()
        lines[k] = f"{lines[k].split('=')[0]}= {value}"
        text = "\n".join(lines)
        # keep world references resolvable from the temporary folder
        text = re.sub(r'world = "(\w[\w-]*)"', lambda m: f'world = "{ROOT / "worlds"}/{m[1]}.toml"',
                      text)  # fmt: skip
        folder = tmp / Path(rel).parent.name
        folder.mkdir(exist_ok=True)
        path = folder / f"m{i}-{Path(rel).name}"
        path.write_text(text)
        calls.append(["validate", str(path)])
    return calls


def main_(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=600, help="mutated files to validate")
    ap.add_argument("--timeout-s", type=int, default=120, help="a call longer than this hangs")
    ap.add_argument("--json", type=Path, help="write the counts and every failure here")
    args = ap.parse_args(argv)
    json_path = args.json.resolve() if args.json else None
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        work = tmp / "a" / "b" / "c"  # relative outputs land in tmp, even ../../..
        work.mkdir(parents=True)
        os.chdir(work)
        results = tmp / "results"
        print("making a small results folder to export, report and film ...", flush=True)
        if main(["run", str(SCENARIO), "--days", "1-1", "--out", str(results), "-q"]) != 0:
            sys.exit("could not make the results folder the audit needs")
        log = tmp / "corridor.log"
        _tiny_log(log)
        calls = bad_invocations(tmp, results, log) + mutated_files(tmp, args.files)
        signal.signal(signal.SIGALRM, _on_alarm)
        counts: Counter[str] = Counter()
        codes: Counter[str] = Counter()
        failures = []
        t0 = time.perf_counter()
        for call in tqdm(calls, desc="bad inputs", unit="call"):
            kind, code, last = _call(call, args.timeout_s)
            counts[kind] += 1
            codes[str(code)] += 1
            if kind != "ok":
                failures.append({"argv": [a[:120] for a in call], "kind": kind, "last": last})
        wall_s = time.perf_counter() - t0
    n_args = len(calls) - min(args.files, len(calls))
    print(f"\n{len(calls)} calls ({n_args} bad invocations, {len(calls) - n_args} mutated files) "
          f"in {wall_s:.0f} s")  # fmt: skip
    print(f"tracebacks: {counts['traceback']}   hangs: {counts['hang']}   clean: {counts['ok']}")
    print("exit codes: " + ", ".join(f"{c}: {n}" for c, n in sorted(codes.items())))
    for f in failures[:20]:
        print(f"  {f['kind']}: {' '.join(f['argv'])[:150]} -> {f['last']}")
    if json_path:
        json_path.write_text(json.dumps(
            {"calls": len(calls), "counts": counts, "exit_codes": codes, "failures": failures},
            indent=1))  # fmt: skip
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main_())
