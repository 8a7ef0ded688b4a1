"""Frontier exploration of the built-in worlds: `eddie explore` on each world × seeds.

Each run is `eddiebot.explore.mission.run_exploration` (the simulator with its default wheel
slip and sensor noise, Eddie's base, SLAM, Nav2's servers and the explore node on the sim
clock, Kinect 160x120 at 10 Hz, Eddie's explore parameters) until no frontier is left or
``--time-limit`` simulated seconds of exploring, then home. Figures per run: coverage of the
world's reachable free floor that the map marks free, agreement with the scan-height ground
truth on the cells both call known, ATE of the SLAM poses (aligned RMSE), distance driven,
simulated and wall time, share of the time spent turning in place, collisions, whether the
robot came home, frontier goals reached and abandoned; beside the simulated time, the
world's oracle tour (``explore_oracle.py``: a route from the start that sees every reachable
free cell and comes back, from the ground truth) as ``oracle_s`` and the run's simulated time
over it as ``vs_oracle``. Targets: coverage ≥ 95 %, agreement ≥ 95 %, 0 collisions, home at
the end, simulated time within 1.5x of the oracle's. Prints a table and writes
``benchmarks/results/explore.json``; ``--keep DIR`` keeps each run's map and report;
``--oracle-only`` prints the oracle tours of the worlds and runs nothing; ``--jobs N`` runs N
explorations at a time, each in a process of its own (its own graph and sim clock: a run's
figures do not depend on what runs beside it, only its wall time does).

    .venv/bin/python benchmarks/bench_explore.py [--worlds office house ...] [--seeds 0 1 2]
        [--time-limit 1200] [--keep DIR] [--jobs N] [--oracle-only]
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results

COLUMNS = ["world", "seed", "reason", "coverage", "coverage_aligned", "map_agreement", "ate_m", "distance_m",
           "explore_time_s", "sim_time_s", "oracle_s", "vs_oracle", "wall_time_s", "turning_share",
           "waiting_share", "collisions",
           "returned_home", "frontiers_visited", "frontiers_abandoned"]
ORACLE_COLUMNS = ["world", "reachable_m2", "unseeable", "oracle_95_s", "oracle_95_views",
                  "oracle_100_s", "oracle_100_views", "oracle_path_m", "oracle_s", "method"]


def oracle_row(world: str) -> dict[str, Any]:
    """The oracle tours of ``world``: seeing 95 % and all of its seeable floor (s, from the
    start to the last view), and ``oracle_s``, all of it and back to the start."""
    from explore_oracle import oracle_for_world

    result = oracle_for_world(world)
    t95, t100 = result.tour(0.95), result.tour(1.0)
    return {"world": world,
            "reachable_m2": round(result.reachable_cells * result.resolution**2, 1),
            "unseeable": round(result.unseeable, 4),
            "oracle_95_s": round(t95.time_s, 1), "oracle_95_views": len(t95.legs),
            "oracle_100_s": round(t100.time_s, 1), "oracle_100_views": len(t100.legs),
            "oracle_path_m": round(t100.path_m + t100.home_path_m, 1),
            "oracle_s": round(t100.round_trip_s, 1), "method": t100.method}


def builtin_worlds() -> list[str]:
    from eddiebot.sim.worlds import list_worlds

    return list(list_worlds())


def run_one(world: str, seed: int, time_limit: float, keep: Path | None) -> dict[str, Any]:
    from eddiebot.explore.mission import run_exploration
    from eddiebot.explore.report import write_report

    out = (keep / f"{world}_seed{seed}") if keep else Path(tempfile.mkdtemp(prefix="explore_"))
    result = run_exploration(out, world=world, seed=seed, time_limit=time_limit,
                             camera=(160, 120, 10.0))
    write_report(result, out)
    row = result.summary()
    row.pop("goals", None)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", nargs="*", default=None, help="default: every built-in world")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--time-limit", type=float, default=1200.0,
                        help="simulated seconds of exploring per run (default 1200)")
    parser.add_argument("--keep", type=Path, default=None, help="keep maps and reports here")
    parser.add_argument("--name", default="explore", help="results file name")
    parser.add_argument("--jobs", type=int, default=1,
                        help="explorations run at a time, one process each (default 1)")
    parser.add_argument("--oracle-only", action="store_true",
                        help="print the worlds' oracle tours and run no exploration")
    args = parser.parse_args(argv)
    worlds = args.worlds or builtin_worlds()
    oracles: dict[str, dict[str, Any]] = {}
    if args.oracle_only:
        for world in worlds:
            oracles[world] = oracle_row(world)
            print_table([oracles[world]], ORACLE_COLUMNS)
            sys.stdout.flush()
        print()
        print_table(list(oracles.values()), ORACLE_COLUMNS)
        return 0
    if args.jobs < 1:
        parser.error(f"--jobs must be at least 1, not {args.jobs}")
    runs = [(world, seed) for world in worlds for seed in args.seeds]
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=min(args.jobs, len(runs)),
                             mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run_one, world, seed, args.time_limit, args.keep)
                   for world, seed in runs]
        for (world, _seed), future in zip(runs, futures, strict=True):
            row = future.result()
            if world not in oracles:
                oracles[world] = oracle_row(world)
            row["oracle_s"] = oracles[world]["oracle_s"]
            row["vs_oracle"] = round(float(row["sim_time_s"]) / row["oracle_s"], 2)
            rows.append(row)
            print_table([row], COLUMNS)
            sys.stdout.flush()
            write_results(args.name, rows)  # keep what is done if a later run is stopped
    print()
    print_table(rows, COLUMNS)
    path = write_results(args.name, rows)
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
