"""How long ``~/add_submap`` holds up the SLAM node's executor on real logs (Intel and ACES,
the halves of `bench_slam_merge.py`).

The node copies the map (`eddiebot.slam.merge.map_snapshot`, on the executor) and has a
worker thread run the search in a spawned process (`eddiebot.slam.placement_process`). This
measures the snapshot's wall time and — while the search runs, in the process (``process``,
what the node does) or on the worker thread itself (``thread``, the design it replaced) —
the lateness of a 20 ms timer on the main thread
standing for the executor (map → odom every ``transform_publish_period``, scans as they
come): each tick is due ``TICK_S`` after the previous one ran (a ROS timer does not fire its
missed periods), and its delay past that is recorded (largest, 99th percentile, median),
beside the same loop with nothing else running (the machine's own scheduling noise). Each
tick does ``WORK_S`` of Python work, as a callback does: the scan-matching kernels are
compiled numba functions that hold the GIL while they run, so Python work on the executor
waits for a kernel call to end each time it asks the worker for the GIL. The whole search
(the stall when it ran on the executor) is given beside.

    python benchmarks/bench_slam_merge_stall.py [intel] [aces] [process] [thread]
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results
from bench_slam_merge import LOGS, SECOND_FRAME, _map
from degrade_odometry import degrade_odometry

from eddiebot.geometry import se2_compose, se2_inverse
from eddiebot.slam.io import read_carmen
from eddiebot.slam.merge import MapCopy, map_snapshot, place_copy
from eddiebot.slam.placement_process import PlacementProcess

#: the executor's stand-in: a timer of this period (s), each tick this much Python work (s)
TICK_S = 0.02
WORK_S = 0.002
#: ticks of the baseline loop (nothing else running)
BASELINE_TICKS = 250


def _ticks(running: Callable[[], bool]) -> np.ndarray:
    """Delays (ms) of a ``TICK_S`` timer doing ``WORK_S`` of Python work per tick."""
    late = []
    last = time.perf_counter()
    while running():
        due = last + TICK_S
        time.sleep(max(0.0, due - time.perf_counter()))
        last = time.perf_counter()
        late.append(last - due)
        end = last + WORK_S
        while time.perf_counter() < end:  # bytecode, so the GIL is asked for as a callback does
            pass
    return np.array(late) * 1e3


def _search(mode: str, map_copy: MapCopy, session: MapCopy, out: dict[str, Any]) -> None:
    w0 = time.perf_counter()
    if mode == "process":
        out["placement"] = PlacementProcess().run(map_copy, session)
    else:
        out["placement"] = place_copy(map_copy, session)
    out["place_wall_s"] = time.perf_counter() - w0


def _run(name: str, path: Path, modes: list[str]) -> list[dict[str, Any]]:
    lasers = read_carmen(path).lasers
    robot_ref = np.array([r.laser_pose for r in lasers])
    odom = degrade_odometry(robot_ref, seed=1)
    half = len(lasers) // 2
    first, _ = _map(lasers[:half], odom[:half])
    to_second = np.broadcast_to(se2_inverse(SECOND_FRAME), odom[half:].shape)
    second, _ = _map(lasers[half:], se2_compose(to_second, odom[half:]))
    count = iter(range(BASELINE_TICKS))
    alone = _ticks(lambda: next(count, None) is not None)
    rows = []
    for mode in modes:
        t0 = time.perf_counter()
        map_copy = map_snapshot(first)
        snapshot_ms = (time.perf_counter() - t0) * 1e3
        session = map_snapshot(second)
        out: dict[str, Any] = {}
        worker = threading.Thread(target=_search, args=(mode, map_copy, session, out))
        worker.start()
        during = _ticks(worker.is_alive)
        worker.join()
        rows.append({
            "log": name,
            "search_in": mode,
            "nodes_map": len(first.nodes),
            "nodes_session": len(second.nodes),
            "links": len(out["placement"].links),
            "snapshot_ms": snapshot_ms,
            "place_wall_s": out["place_wall_s"],
            "ticks": int(during.size),
            "tick_late_max_ms": float(during.max()),
            "tick_late_p99_ms": float(np.percentile(during, 99)),
            "tick_late_median_ms": float(np.median(during)),
            "alone_late_max_ms": float(alone.max()),
            "alone_late_p99_ms": float(np.percentile(alone, 99)),
        })
    return rows


def main() -> int:
    args = sys.argv[1:]
    modes = [a for a in args if a in ("process", "thread")] or ["process", "thread"]
    only = [a for a in args if a in LOGS]
    rows = [row for name, path in LOGS.items() if path.exists() and (not only or name in only)
            for row in _run(name, path, modes)]
    if not rows:
        print("no logs found")
        return 0
    print_table(rows, list(rows[0]))
    print(write_results("slam_merge_stall", rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
