"""``static-mcl`` variants side by side on the untuned worlds, over several filter seeds.

Issue 16: "no jump over 0.5 m" on the worlds nobody tuned the localizers for.

A jump of ``static-mcl`` is a rare event: whether it happens in a 10-day calendar depends on
the filter's own random draws as much as on its settings, so one run per setting says little
(on the corridor the shipped ``tuned`` jumps 20.2 m with one filter seed and 12.7 m with
another). This script runs each world's tour once (``worlds/scenarios/<world>-tour.toml``:
the same sensor stream for all) with ``static-mcl`` ``tuned`` in every variant given by
``--variant`` and ``--filter-seeds`` copies of each, every copy on a filter generator of its
own (the engine gives each localizer of a scenario its own child of the seed tree, by its
position), and prints per world, variant and filter seed the mean and largest position
error and the lost share (> 0.5 m), then per variant the worst of its seeds.

A variant is ``NAME`` (``tuned`` as it is) or ``NAME=field=value,field=value`` with
:class:`~dynmap_sim.agent.localization.particle_filter.MCLConfig` fields and JSON values.
The first copy of the first variant gets the filter generator that ``static-mcl tuned`` has
in the tour scenario, so its row is that scenario's.

    python benchmarks/mcl_untuned_variants.py --worlds corridor --filter-seeds 3 \\
        --variant tuned --variant a01=alpha1=0.01,alpha2=0.01,alpha3=0.01,alpha4=0.01

It measures: nothing here changes the shipped settings.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_untuned_worlds import WORLDS, add_tour_arguments, check_out

from dynmap_sim.agent.localization.particle_filter import CONFIGS, MCLConfig
from dynmap_sim.experiments.replay import json_or_text
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import LocalizerConfig, load_scenario

#: a position error above this [m] counts as lost (the project's ``lost`` threshold) ...
LOST_M = 0.5


def variant(text: str) -> tuple[str, dict[str, Any]]:
    """``NAME`` or ``NAME=field=value,...`` -> ``(NAME, overrides)``."""
    name, _, rest = text.partition("=")
    if not name or any(c in name for c in "/\\ ,"):
        raise argparse.ArgumentTypeError(f"a variant is NAME[=field=value,...], not {text!r}")
    overrides: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, val = item.partition("=")
        if not sep or not key:
            raise argparse.ArgumentTypeError(f"variant {name}: expected field=value, got {item!r}")
        overrides[key] = json_or_text(val)
    unknown = set(overrides) - {f.name for f in dataclasses.fields(MCLConfig)}
    if unknown:
        raise argparse.ArgumentTypeError(f"variant {name}: not MCLConfig fields: {sorted(unknown)}")
    try:
        dataclasses.replace(CONFIGS["tuned"], **overrides)
    except (TypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"variant {name}: {exc}") from None
    return name, overrides


def positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"a count >= 1, not {text!r}")
    return n


def localizers(variants: list[tuple[str, dict[str, Any]]], n_seeds: int) -> list[LocalizerConfig]:
    """odometry first (the tour scenario's first localizer), then the first copy of every
    variant, then the second, ...: the first copy of the first variant sits where the tour
    scenario's ``static-mcl tuned`` does."""
    out = [LocalizerConfig(name="odometry", label="odometry")]
    for s in range(n_seeds):
        for name, overrides in variants:
            params: dict[str, Any] = {"config": "tuned"}
            if overrides:
                params["overrides"] = overrides
            out.append(LocalizerConfig(name="static-mcl", label=f"{name} s{s}", params=params))
    return out


def errors(db: ResultsDB, loc: int) -> np.ndarray:
    d = db.per_scan(loc)
    return np.hypot(*(d["estimate"][:, :2] - d["truth"][:, :2]).T)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--variant",
        type=variant,
        action="append",
        help="NAME or NAME=field=value,... (MCLConfig fields over 'tuned'); repeat "
        "(default: tuned)",
    )
    ap.add_argument(
        "--filter-seeds", type=positive, default=2, help="copies of each variant (default: 2)"
    )
    add_tour_arguments(ap)
    args = ap.parse_args()
    check_out(ap, args)
    variants = args.variant or [("tuned", {})]
    names = [n for n, _ in variants]
    if len(set(names)) != len(names):
        ap.error(f"variant names must differ: {names}")
    locs = localizers(variants, args.filter_seeds)
    print(f"static-mcl variants, seed {args.seed}, {args.filter_seeds} filter seeds each; "
          f"lost: error > {LOST_M} m")  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="mcl-variants-") as tmp:
        base = args.out if args.out is not None else Path(tmp)
        for world in args.worlds:
            scn = load_scenario(WORLDS[world]).model_copy(update={"localizers": locs})
            t0 = time.perf_counter()
            run_experiment(scn, base / world, days=args.days, seed=args.seed, progress=True,
                           overwrite=True, workers=args.workers)  # fmt: skip
            print(f"\n{world} ({time.perf_counter() - t0:.0f} s wall)")
            print(f"  {'variant':>12} {'seed':>4} {'mean [m]':>9} {'max [m]':>8} {'lost':>7}")
            worst: dict[str, list[float]] = {n: [0.0, 0.0, 0.0] for n in names}
            with ResultsDB.open(base / world) as db:
                for k, label in enumerate(db.labels()[1:], start=1):
                    name, seed = label.rsplit(" s", 1)
                    e = errors(db, k)
                    row = (float(e.mean()), float(e.max()), float(np.mean(e > LOST_M)))
                    worst[name] = [max(a, b) for a, b in zip(worst[name], row, strict=True)]
                    print(f"  {name:>12} {seed:>4} {row[0]:9.3f} {row[1]:8.2f} "
                          f"{100 * row[2]:6.2f} %")  # fmt: skip
            for name, (m, x, lost) in worst.items():
                print(f"  {name:>12} worst of its seeds: mean {m:.3f} m, max {x:.2f} m, "
                      f"lost {100 * lost:.2f} %")  # fmt: skip


if __name__ == "__main__":
    main()
