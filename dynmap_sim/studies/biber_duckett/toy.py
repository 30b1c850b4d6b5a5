"""The toy example of Biber & Duckett §3.5 (Fig. 2): sample sets vs recency-weighted averaging.

A sensor measures the distance to a wall 2 m away; a cupboard stands 1 m away from ``t = 10``
to ``t = 20``. At every time step 20 measurements with σ = 10 cm noise are made. A dynamic
sample set of 20 samples (initialized with the first step's measurements) is updated once per
step with update ratio ``u``; recency-weighted averaging (eq. 1, initialized with the mean of
the first step) is updated after every measurement with the step size ``α`` that forgets as
fast per time step: ``(1 − α)^20 = 1 − u`` (eq. 2 vs eq. 3).

``run_toy(out_dir, seed)`` writes ``toy.csv`` (columns ``t, u, method, estimate``; method
``samples`` or ``rwa``) and ``toy.png`` (two panels like Fig. 2).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynmap_sim.agent.maps.sample_set import SampleSets, to_mm

WALL_M = 2.0
CUPBOARD_M = 1.0
CUPBOARD_FROM = 10
CUPBOARD_UNTIL = 20
UPDATE_RATIOS = (0.75, 0.25, 0.05)


@dataclass(frozen=True)
class ToyConfig:
    """Parameters of the §3.5 simulation."""

    n_steps: int = 40
    n_measurements: int = 20
    n_samples: int = 20
    noise_sigma_m: float = 0.10
    update_ratios: tuple[float, ...] = UPDATE_RATIOS


def true_distance_m(t: int) -> float:
    """The distance the sensor sees at step ``t``: cupboard for 10 <= t < 20, else the wall."""
    return CUPBOARD_M if CUPBOARD_FROM <= t < CUPBOARD_UNTIL else WALL_M


def rwa_step_size(u: float, n_measurements: int) -> float:
    """``α`` with ``(1 − α)^n_measurements = 1 − u``: same forgetting per time step as ``u``."""
    return 1.0 - (1.0 - u) ** (1.0 / n_measurements)


def simulate_toy(cfg: ToyConfig, seed: int) -> list[tuple[int, float, str, float]]:
    """Rows ``(t, u, method, estimate_m)`` for every step, update ratio and method.

    All update ratios and both methods see the *same* measurements.
    """
    rng = np.random.default_rng(seed)
    meas = np.array(
        [
            true_distance_m(t) + cfg.noise_sigma_m * rng.standard_normal(cfg.n_measurements)
            for t in range(cfg.n_steps)
        ]
    )
    rows: list[tuple[int, float, str, float]] = []
    rays = np.zeros(cfg.n_measurements, dtype=np.int64)
    for u in cfg.update_ratios:
        sub = np.random.default_rng([seed, round(u * 1e6)])
        ss = SampleSets(1, cfg.n_samples, u)
        ss.update(rays, to_mm(meas[0]), sub, fill=True)
        alpha = rwa_step_size(u, cfg.n_measurements)
        d = float(np.mean(meas[0]))
        for t in range(cfg.n_steps):
            if t > 0:
                ss.update(rays, to_mm(meas[t]), sub)
                for z in meas[t]:
                    d = (1.0 - alpha) * d + alpha * float(z)  # eq. 1
            rows.append((t, u, "samples", float(ss.estimates().rho_m[0])))
            rows.append((t, u, "rwa", d))
    return rows


def _write_figure(rows: list[tuple[int, float, str, float]], cfg: ToyConfig, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    titles = {"rwa": "recency weighted averaging", "samples": "sample-based dynamic map"}
    for ax, method in zip(axes, ("rwa", "samples"), strict=True):
        t_true = np.arange(cfg.n_steps)
        ax.step(
            t_true,
            [true_distance_m(t) for t in t_true],
            where="post",
            color="0.7",
            lw=3,
            label="truth",
        )
        for u in cfg.update_ratios:
            sel = [(t, e) for t, uu, m, e in rows if uu == u and m == method]
            ax.plot([t for t, _ in sel], [e for _, e in sel], marker=".", label=f"u = {u}")
        ax.set_title(titles[method])
        ax.set_ylabel("distance estimate [m]")
        ax.set_ylim(0.7, 2.3)
        ax.legend(loc="lower right", fontsize=8)
    axes[-1].set_xlabel("time step")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_toy(out_dir: Path, seed: int) -> list[Path]:
    """Run the §3.5 toy example; write ``toy.csv`` and ``toy.png`` into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = ToyConfig()
    rows = simulate_toy(cfg, seed)
    csv_path = out_dir / "toy.csv"
    with csv_path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "u", "method", "estimate"])
        for t, u, m, e in rows:
            w.writerow([t, u, m, f"{e:.4f}"])
    png_path = out_dir / "toy.png"
    _write_figure(rows, cfg, png_path)
    return [csv_path, png_path]
