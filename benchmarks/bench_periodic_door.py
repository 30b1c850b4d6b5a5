"""The temporal models on a real door: ``python benchmarks/bench_periodic_door.py``.

Trains :class:`~dynmap_sim.agent.maps.fremen.Fremen` (Krajník et al. T-RO 2017) and
:class:`~dynmap_sim.agent.maps.markov_grid.MarkovGrid` (Saarinen et al. IROS 2012) on the
67 training days of the periodic-door data set (``--data``: ``training.txt.gz``,
``test_week1..4.txt.gz``, ``unix_time state`` a line) and prints, per test week, the mean
squared error of the predicted probability and of the thresholded prediction (p > 0.5)
against the state, beside the two references of the data set: the static mean of the
training part and the last state seen in it. Neither model sees the test weeks: FreMEn
predicts each minute from its spectrum, the Markov chain from the last training state after
the gap. FreMEn learns the training part a week at a time, each week scored before it is
learned, so its order is chosen by prediction error on data it had not seen.

Then the speed on synthetic data: learning and predicting ``--cells`` cells observed at
``--times`` scan times (cell·observations per second of CPU, ``time.process_time``), with a
reference measured in the same run on the same array (numpy's mean over time: the static
model's learning) and the ratio.

Last (``--localizer-days``, 0 to skip), the localizers ``fremen`` and ``markov-grid`` on a
synthetic periodic room (URG-04LX scans of 683 beams from the tests' exact ray caster, a box
there in the 08:00 run and gone in the 20:00 run of each day): scans per second of CPU of
their updates and the CPU of their end-of-run learning, beside ``static-mcl`` walls-only on
the prior walls on the same streams (the reference and the ratio), their mean position
errors per day, and whether each one's map predicted for the next morning and evening holds
the box.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from dynmap_sim.agent.grid import OCCUPIED
from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.agent.maps.fremen import WEEK_S, Fremen, default_periods
from dynmap_sim.agent.maps.markov_grid import MarkovGrid
from dynmap_sim.sensors.lidar import make_lidar
from dynmap_sim.types import Prior

# the synthetic geometry the agent tests use (one exact ray caster, one drifting stream)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from synthetic_scans import box, drifting_stream, polyline_path  # noqa: E402

#: The simulator's URG-04LX (683 beams).
URG = make_lidar("urg-04lx").spec

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "periodic-door"


def _load(path: Path) -> tuple[np.ndarray, np.ndarray]:
    d = np.loadtxt(path, dtype=np.float64)
    return d[:, 0], d[:, 1]


def _errors(p: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """(MSE of the probability, MSE of the thresholded prediction) against the states."""
    return float(np.mean((p - s) ** 2)), float(np.mean(((p > 0.5) - s) ** 2))


def door(data: Path, n_periods: int, max_order: int) -> None:
    """Per test week, the errors of FreMEn, the Markov chain and the two references."""
    t, s = _load(data / "training.txt.gz")
    zero = np.zeros(t.size, np.int64)
    fremen = Fremen(1, periods_s=default_periods(WEEK_S, n_periods), max_order=max_order)
    for w0 in np.arange(t[0], t[-1] + 1, WEEK_S):
        m = (t >= w0) & (t < w0 + WEEK_S)
        fremen.update(t[m], zero[m], s[m])
    markov = MarkovGrid(1)
    markov.update(t, zero, s)
    order = int(fremen.order[0])
    _, amp, _, omega = fremen.components(order=order)
    comps = ", ".join(
        f"{2 * np.pi / w / 3600:.1f} h: {a:.3f}" for a, w in zip(amp[0], omega[0], strict=True)
    )
    print(f"training: {t.size} samples, open {s.mean():.3f} of the time")
    print(f"FreMEn: {n_periods} periods (a week / 1..{n_periods}), order {order} chosen of")
    print(f"  0..{max_order} by prediction error (sse per order {np.round(fremen.sse[0], 1)})")
    print(f"  components (period: amplitude): {comps}")
    lam_in, lam_out = (float(r[0]) for r in markov.rates())
    print(
        f"Markov chain: entry {lam_in * 3600:.3f}/h, exit {lam_out * 3600:.3f}/h, "
        f"p_inf {markov.stationary()[0]:.3f}"
    )
    names = ("FreMEn", "Markov chain", "static mean", "last state")
    print("\nmean squared error per test week: probability / thresholded (p > 0.5)")
    print(f"{'week':>4} " + " ".join(f"{n:>19}" for n in names) + "  FreMEn/static")
    for week in range(1, 5):
        tw, sw = _load(data / f"test_week{week}.txt.gz")
        preds = (
            fremen.predict(tw)[:, 0],
            markov.predict(tw)[:, 0],
            np.full(tw.size, s.mean()),
            np.full(tw.size, s[-1]),
        )
        errs = [_errors(p, sw) for p in preds]
        cols = " ".join(f"{a:>9.4f} / {b:<7.4f}" for a, b in errs)
        print(f"{week:>4} {cols}  {errs[0][0] / errs[2][0]:.2f}")


def speed(n_cells: int, n_times: int, seed: int = 0) -> None:
    """Cell·observations per second of CPU of learning and predicting, with the reference."""
    rng = np.random.default_rng(seed)
    times = np.arange(n_times) * 1800.0
    states = (rng.random((n_times, n_cells)) < 0.3).astype(np.float64)
    t_all = np.repeat(times, n_cells)
    c_all = np.tile(np.arange(n_cells, dtype=np.int64), n_times)
    s_all = states.ravel()
    n = n_cells * n_times
    Fremen(1).update([0.0], [0], [1.0])  # compile (cached) outside the timing
    MarkovGrid(1).update([0.0], [0], [1.0])

    def cpu(fn) -> float:
        t0 = time.process_time()
        fn()
        return time.process_time() - t0

    ref = min(cpu(lambda: [states.mean(axis=0) for _ in range(20)]) for _ in range(3)) / 20
    f = Fremen(n_cells)
    rows = [
        ("numpy mean over time (reference)", ref),
        ("FreMEn update, scored", cpu(lambda: f.update(t_all, c_all, s_all))),
        (
            "FreMEn update, not scored",
            cpu(lambda: Fremen(n_cells).update(t_all, c_all, s_all, score=False)),
        ),
        ("Markov grid update", cpu(lambda: MarkovGrid(n_cells).update(t_all, c_all, s_all))),
    ]
    print(
        f"\nspeed: {n_cells} cells x {n_times} scan times = {n} cell observations, "
        f"{len(f.periods_s)} periods, max order {f.max_order}"
    )
    print(f"{'':36} {'CPU s':>8} {'cell-obs/s':>12} {'x reference':>12}")
    for name, sec in rows:
        print(f"{name:36} {sec:8.3f} {n / sec:12.3g} {sec / ref:12.1f}")
    g = MarkovGrid(n_cells)
    g.update(t_all, c_all, s_all)
    for name, fn in (
        ("FreMEn predict, one map", lambda: f.predict(times[-1] + 900.0)),
        ("Markov grid predict, one map", lambda: g.predict(times[-1] + 900.0)),
    ):
        sec = min(cpu(fn) for _ in range(3))
        print(f"{name:36} {sec:8.4f} {n_cells / sec:12.3g} cells/s")
    print(
        f"memory: FreMEn {f.acc.nbytes + f.sse.nbytes + 24 * n_cells} B, "
        f"Markov grid {g.counts.nbytes + 16 * n_cells} B for {n_cells} cells"
    )


def _room() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The walls (the prior), the box that comes and goes, the route (poses ``(T, 3)``)."""
    pts = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    corners = np.array([[1.0, 1.0], [4.2, 1.0], [4.0, 3.8], [1.0, 3.6]])
    return walls, box(2.6, 2.2, 3.2, 2.8), polyline_path(corners, 0.035, 0.1)


def _box_held(loc, t_s: float, box_segs: np.ndarray) -> float:
    """Share of the box's side midpoints with an occupied cell within a cell at ``t_s``."""
    grid = loc.predicted_grid(t_s)
    mid = 0.5 * (box_segs[:, :2] + box_segs[:, 2:])
    ix, iy = grid.cell_of(mid)
    occ = grid.occupancy == OCCUPIED
    near = [occ[y - 1 : y + 2, x - 1 : x + 2].any() for x, y in zip(ix, iy, strict=True)]
    return float(np.mean(near))


def localizers(n_days: int, seed: int = 0) -> None:
    """The localizers on the periodic room: speed against static-mcl, errors, the box."""
    walls, box_segs, truth = _room()
    rng = np.random.default_rng(seed)
    labels = ("fremen", "markov-grid", "static-mcl")
    locs = {
        "fremen": make_localizer("fremen", laser=URG, rng=np.random.default_rng(1),
                                 run_clock_s=8 * 3600.0, run_spacing_s=12 * 3600.0),
        "markov-grid": make_localizer("markov-grid", laser=URG, rng=np.random.default_rng(1),
                                      run_clock_s=8 * 3600.0, run_spacing_s=12 * 3600.0),
        "static-mcl": make_localizer("static-mcl", laser=URG, rng=np.random.default_rng(1),
                                     config="walls-only", map_source="prior-walls"),
    }  # fmt: skip
    cpu = dict.fromkeys(labels, 0.0)
    learn = dict.fromkeys(("fremen", "markov-grid"), 0.0)
    n_scans = 0
    print(f"\nlocalizers on a periodic room ({URG.n_beams} beams, {len(truth)} scans a run, "
          "a box at 08:00, none at 20:00); mean error [cm] per day, run 1 / run 2")  # fmt: skip
    for day in range(1, n_days + 1):
        errs = {k: [] for k in labels}
        for run in (1, 2):
            segs = walls if run == 2 else np.concatenate([walls, box_segs])
            stream = drifting_stream(truth, segs, URG, rng)
            n_scans += len(stream)
            for k, loc in locs.items():
                loc.begin_run(Prior(initial_pose=truth[0].copy(), walls=walls, day=day, run=run))
                c0 = time.process_time()
                ests = [loc.update(o, sc) for o, sc in stream]
                cpu[k] += time.process_time() - c0
                c0 = time.process_time()
                loc.end_run()
                if k in learn:
                    learn[k] += time.process_time() - c0
                err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
                errs[k].append(f"{100 * err.mean():.1f}")
        for loc in locs.values():
            loc.end_day()
        morning, evening = day * 86400.0 + 8 * 3600.0, day * 86400.0 + 20 * 3600.0
        held = "; ".join(f"{k} {_box_held(locs[k], morning, box_segs):.2f} / "
                         f"{_box_held(locs[k], evening, box_segs):.2f}" for k in learn)  # fmt: skip
        print(f"  day {day}: " + ", ".join(f"{k} {' / '.join(v)}" for k, v in errs.items())
              + f"; box in the next day's 08:00 / 20:00 map: {held}")  # fmt: skip
    ref = n_scans / cpu["static-mcl"]
    for k in labels:
        line = f"  {k:12} {n_scans / cpu[k]:7.0f} scans/s of CPU ({ref / (n_scans / cpu[k]):.2f}"
        line += " x static-mcl's time)"
        if k in learn:
            line += f", learning {1e3 * learn[k] / (2 * n_days):.0f} ms of CPU a run"
        print(line)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the periodic-door folder")
    ap.add_argument("--n-periods", type=int, default=56, help="periods a week / 1..N")
    ap.add_argument("--max-order", type=int, default=5, help="most spectral components")
    ap.add_argument("--cells", type=int, default=20000, help="cells of the speed test")
    ap.add_argument("--times", type=int, default=50, help="scan times of the speed test")
    ap.add_argument("--localizer-days", type=int, default=4, help="days of the localizers")
    args = ap.parse_args()
    door(args.data, args.n_periods, args.max_order)
    speed(args.cells, args.times)
    if args.localizer_days > 0:
        localizers(args.localizer_days)


if __name__ == "__main__":
    main()
