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
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from dynmap_sim.agent.maps.fremen import WEEK_S, Fremen, default_periods
from dynmap_sim.agent.maps.markov_grid import MarkovGrid

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

    ref = min(cpu(lambda: states.mean(axis=0)) for _ in range(3))
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the periodic-door folder")
    ap.add_argument("--n-periods", type=int, default=56, help="periods a week / 1..N")
    ap.add_argument("--max-order", type=int, default=5, help="most spectral components")
    ap.add_argument("--cells", type=int, default=20000, help="cells of the speed test")
    ap.add_argument("--times", type=int, default=50, help="scan times of the speed test")
    args = ap.parse_args()
    door(args.data, args.n_periods, args.max_order)
    speed(args.cells, args.times)


if __name__ == "__main__":
    main()
