"""Real-time factor of the whole simulated robot: simulator + firmware emulator + the base
stack (board driver over the in-process link, mux, controller, odometry, range, safety,
state publisher) + depthimage_to_laserscan, driving in circles in the office world.

Configurations: Kinect 640×480 at 30 Hz (target ≥ 2.5×), 320×240 at 10 Hz (≥ 10×), and
physics + scan only (no camera rendering; ≥ 100×, for which the scan comes from a 1-row
depth image at 10 Hz). Prints where the time goes (cProfile, top functions by own time).
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.registry import NODES

CONFIGS = [
    ("Kinect 640x480 @ 30 Hz", {"camera_width": "640", "camera_height": "480", "camera_rate": "30"}, 2.5),
    ("Kinect 320x240 @ 10 Hz", {"camera_width": "320", "camera_height": "240", "camera_rate": "10"}, 10.0),
    ("physics + scan (160x20 depth only @ 10 Hz)", {"camera_width": "160", "camera_height": "20",
                                              "camera_rate": "10"}, 100.0),
]


def run(args: dict[str, str], sim_seconds: float, profile: bool = False) -> tuple[float, str]:
    ctx = Context(use_sim_time=True)
    nodes = build_nodes(parse_launch_file(find_launch_file("sim"), {"world": "office", **args}), ctx, NODES)
    if args["camera_height"] == "20":
        sim = ctx.resources["simulator"]
        sim.publish_rgb = False
    drv = Node("driver", context=ctx)
    pub = drv.create_publisher(Twist, "/cmd_vel_teleop", 10)

    def tick() -> None:
        t = Twist()
        t.linear.x, t.angular.z = 0.3, 0.4
        pub.publish(t)

    drv.create_timer(0.1, tick)
    ex = SingleThreadedExecutor(context=ctx)
    for n in [*nodes, drv]:
        ex.add_node(n)
    ex.spin_for(1.0)  # warm up (numba, first frames)
    prof = cProfile.Profile() if profile else None
    t0 = time.perf_counter()
    if prof:
        prof.enable()
    ex.spin_for(sim_seconds)
    if prof:
        prof.disable()
    wall = time.perf_counter() - t0
    where = ""
    if prof:
        import io

        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(8)
        where = buf.getvalue()
    ctx.shutdown()
    return sim_seconds / wall, where


def main() -> int:
    rows = []
    for name, args, target in CONFIGS:
        rtf, _ = run(args, 20.0)
        rows.append({"configuration": name, "real-time factor": rtf, "target": f">= {target:g}"})
    print_table(rows, ["configuration", "real-time factor", "target"])
    write_results("sim_rtf", rows)
    print("\nwhere the time goes, Kinect 320x240 @ 10 Hz (top own-time functions):")
    _, where = run(CONFIGS[1][1], 10.0, profile=True)
    print("\n".join(where.splitlines()[:30]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
