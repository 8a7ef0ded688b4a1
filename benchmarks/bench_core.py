"""Runtime benchmarks: sim-clock executor throughput and in-process publish → callback."""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.sensor_msgs import Image


def timer_rate(seconds_sim: float = 300.0) -> float:
    ctx = Context(use_sim_time=True)
    node = Node("bench", context=ctx)
    count = [0]

    def tick() -> None:
        count[0] += 1

    node.create_timer(0.001, tick)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    t0 = time.perf_counter()
    ex.spin_for(seconds_sim)
    dt = time.perf_counter() - t0
    ctx.shutdown()
    return count[0] / dt


def pubsub_latency(msg: object, n: int = 20000) -> float:
    """Median µs from publish() to the callback, one process, single-threaded executor."""
    ctx = Context()
    a, b = Node("a", context=ctx), Node("b", context=ctx)
    stamps: list[float] = []
    b.create_subscription(type(msg), "/x", lambda m: stamps.append(time.perf_counter()), 10)
    pub = a.create_publisher(type(msg), "/x", 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(a)
    ex.add_node(b)
    lat = []
    for _ in range(n):
        t0 = time.perf_counter()
        pub.publish(msg)
        ex.spin_once(timeout_sec=0)
        lat.append(stamps[-1] - t0)
    ctx.shutdown()
    return statistics.median(lat) * 1e6


def main() -> int:
    img = Image(height=480, width=640, encoding="16UC1", step=1280,
                data=np.zeros(640 * 480 * 2, dtype=np.uint8))
    rows = [
        {"benchmark": "sim-clock timer callbacks", "value": timer_rate(), "unit": "1/s",
         "target": ">= 100000"},
        {"benchmark": "in-process Twist publish->callback (median)", "value": pubsub_latency(Twist()),
         "unit": "us", "target": "<= 10"},
        {"benchmark": "in-process 640x480 16UC1 Image publish->callback (median)",
         "value": pubsub_latency(img), "unit": "us", "target": "<= 20"},
    ]
    print_table(rows, ["benchmark", "value", "unit", "target"])
    write_results("core", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
