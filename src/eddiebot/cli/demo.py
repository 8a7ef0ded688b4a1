"""``eddie demo``: the main job, in the simulator, with a report under ``out/demo/``.

Stages (``--stages``, default all):

- ``base``: the firmware emulator serves a pty; the bring-up stack drives a 1 m square over
  it exactly as on the robot and prints wheel odometry against the emulator's true pose.
- ``mapping``: in the ``office`` world, a scripted drive maps the building with the
  Kinect-made scan (2D SLAM); the map is saved and judged against the ground truth.
- ``nav``: Eddie tours a list of goals in the saved map with the navigation stack.
- ``vslam``: the same route with RGB-D SLAM beside the 2D SLAM.

Every stage runs the real nodes; all but ``base`` run on a simulated clock as fast as the
CPU allows. The report (Markdown + PNG) is ``out/demo/report.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

from eddiebot.demo.report import Report, world_to_map

STAGES = ("base", "mapping", "nav", "vslam")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", type=Path, default=Path("out/demo"), help="output folder")
    parser.add_argument("--stages", default=",".join(STAGES),
                        help=f"comma-separated stages to run (default: {','.join(STAGES)})")
    parser.add_argument("--side", type=float, default=1.0, help="square side of the base stage, m")
    parser.add_argument("--seed", type=int, default=0)


def _stage_base(out: Path, report: Report, side: float) -> bool:
    from eddiebot.demo.square import run_square

    print("== stage base: bring-up over a pty against the firmware emulator, 1 m square ==", flush=True)
    result = run_square(out, side=side)
    print(f"emulated board on {result.device}")
    header = (f"{'corner':>6}  {'odom x':>8} {'odom y':>8} {'odom θ°':>8}  {'true x':>8} {'true y':>8} "
              f"{'true θ°':>8}  {'Δpos m':>7} {'Δθ°':>5}")
    print(header)
    rows = []
    for c in result.corners:
        line = (f"{c.index:>6}  {c.odom[0]:8.3f} {c.odom[1]:8.3f} {math.degrees(c.odom[2]):8.1f}  "
                f"{c.truth[0]:8.3f} {c.truth[1]:8.3f} {math.degrees(c.truth[2]):8.1f}  "
                f"{c.position_error:7.3f} {math.degrees(c.heading_error):5.1f}")
        print(line)
        rows.append(line)
    ok = len(result.corners) == 4
    report.add("## Stage 1 — bring-up over a serial line (pty) against the firmware emulator\n\n"
               "The bring-up launch (board driver, twist mux, velocity controller, odometry, range, "
               "safety, robot description) drove a 1 m square over `/cmd_vel`; the board was the "
               "firmware emulator on a pseudo-terminal, so every byte went through the real driver.\n\n"
               "```\n" + header + "\n" + "\n".join(rows) + "\n```\n"
               + (f"\nRecorded to `{result.bag.name}/` (rosbag2 MCAP).\n" if result.bag else ""))
    if result.bag is not None:
        print(f"recorded the run to {result.bag} (rosbag2 MCAP)")
    if not ok:
        print(f"the square did not finish: {len(result.corners)} corners", file=sys.stderr)
    return ok


def _stage_mapping(out: Path, report: Report, seed: int) -> bool:
    from eddiebot.demo.mapping import run_mapping
    from eddiebot.sim.ground_truth import cached_ground_truth
    from eddiebot.sim.worlds import load_world
    from eddiebot.viz.snapshot import render_map

    print("== stage mapping: 2D SLAM of the office world on the Kinect-made scan ==", flush=True)
    r = run_mapping(out, seed=seed, dashboard=True)
    print(f"drove {r.distance_m:.1f} m in {r.sim_seconds:.0f} s simulated ({r.wall_seconds:.0f} s wall, "
          f"{r.sim_seconds / max(r.wall_seconds, 1e-9):.1f}× real time); {r.nodes} graph nodes, "
          f"{r.loop_closures} loop closures, {r.collisions} collisions")
    print(f"wheel odometry drift against ground truth: {r.odom_end_error_m:.3f} m after {r.distance_m:.1f} m "
          f"({100 * r.odom_end_error_m / max(r.distance_m, 1e-9):.2f} % of distance)")
    print(f"SLAM trajectory error: RMSE {r.ate_rmse_m:.3f} m, max {r.ate_max_m:.3f} m from the start "
          f"pose; {r.ate_aligned_rmse_m:.3f} m, max {r.ate_aligned_max_m:.3f} m after the rigid "
          f"alignment (the map turned {r.aligned_turn_deg:+.2f}°); "
          f"end point: SLAM {r.slam_end_error_m:.3f} m, wheel odometry {r.odom_end_error_m:.3f} m")
    print(f"map agreement with the ground truth (cells both call known): {100 * r.agreement:.1f} % "
          f"({100 * r.agreement_tolerant:.1f} % within one cell); saved {r.map_yaml}")
    pictures = []
    if r.grid is not None:
        # drawn in this order: SLAM last, on top of the odometry and the truth it follows
        trajectories = {"ground truth": world_to_map(r.truth, r.start)}
        if len(r.odom_world):
            trajectories["wheel odometry"] = world_to_map(r.odom_world, r.start)
        trajectories["SLAM"] = world_to_map(r.slam_world, r.start)
        render_map(r.grid, trajectories=trajectories, out_path=out / "mapping.png",
                   title="office: SLAM map and trajectories (map frame)")
        pictures.append("![SLAM map](mapping.png)")
        truth_map = cached_ground_truth(load_world("office")).scan
        render_map(truth_map, trajectories={"ground truth": r.truth}, out_path=out / "ground_truth.png",
                   title="office: ground truth at scan height (world frame)")
        pictures.append("![ground truth](ground_truth.png)")
    report.add("## Stage 2 — mapping the office with the Kinect-made scan (2D SLAM)\n\n"
               "The simulator (firmware emulator's plant in the `office` world), the base stack, "
               "depthimage_to_laserscan and the SLAM node ran in one process on a simulated clock; a "
               "scripted operator drove through the corridor and two rooms and back.\n\n"
               + report.table([
                   ("distance driven (m)", r.distance_m),
                   ("simulated time (s)", r.sim_seconds),
                   ("wall time (s)", r.wall_seconds),
                   ("graph nodes", r.nodes),
                   ("loop closures", r.loop_closures),
                   ("collisions", r.collisions),
                   ("SLAM trajectory RMSE from the start pose (m)", r.ate_rmse_m),
                   ("SLAM trajectory max error (m)", r.ate_max_m),
                   ("SLAM trajectory RMSE after a rigid alignment (m; TUM/evo ATE)", r.ate_aligned_rmse_m),
                   ("turn of the whole SLAM map against the world (°)", r.aligned_turn_deg),
                   ("end-point error, SLAM (m)", r.slam_end_error_m),
                   ("end-point error, wheel odometry alone (m)", r.odom_end_error_m),
                   ("map agreement, cells both call known", r.agreement),
                   ("map agreement, occupied within one cell", r.agreement_tolerant),
               ])
               + f"\nMap: `{r.map_yaml.name if r.map_yaml else '-'}`; session: "
               f"`{r.session.name if r.session else '-'}`; bag: `{r.bag.name if r.bag else '-'}/`.\n\n"
               + "\n".join(pictures) + "\n")
    return r.finished


def _stage_nav(out: Path, report: Report, seed: int) -> bool:
    if importlib.util.find_spec("eddiebot.demo.nav_stage") is None:
        print("== stage nav: not available in this build ==")
        return True
    from eddiebot.demo.nav_stage import run_nav_stage  # type: ignore[import-not-found]

    print("== stage nav: a tour of goals in the saved map ==", flush=True)
    ok: bool = run_nav_stage(out, report, seed=seed)
    return ok


def _stage_vslam(out: Path, report: Report, seed: int) -> bool:
    if importlib.util.find_spec("eddiebot.demo.vslam_stage") is None:
        print("== stage vslam: not available in this build ==")
        return True
    from eddiebot.demo.vslam_stage import SLAM_PARAMETERS, run_vslam  # type: ignore[import-not-found]

    print("== stage vslam: RGB-D SLAM on the same route ==", flush=True)
    from eddiebot.vslam.features import retain_freed_memory

    retain_freed_memory()  # the stage runs visual odometry: no page faults per frame
    # Eddie's wheel odometry variance per node link as measured in the simulator (instead of
    # rtabmap_ros's 0.001 default) and loop closures registered 3D->3D from both frames' depth
    r = run_vslam(out, seed=seed, parameters=dict(SLAM_PARAMETERS))
    labels = {
        "ate_rmse_m": "trajectory RMSE against the ground truth (m; ATE)",
        "ate_max_m": "trajectory max error (m)",
        "odom_end_error_m": "end-point error, wheel odometry alone (m)",
        "slam_end_error_m": "end-point error, RGB-D SLAM (m)",
        "loop_closures": "loop closures",
        "nodes": "graph nodes",
        "sim_seconds": "simulated time (s)",
        "wall_seconds": "wall time (s)",
    }
    rows = [(label, getattr(r, k)) for k, label in labels.items() if hasattr(r, k)]
    for label, v in rows:
        print(f"{label}: {v}")
    picture = ""
    if len(getattr(r, "slam_world", ())) and len(getattr(r, "truth", ())):
        from eddiebot.viz.snapshot import render_trajectories

        render_trajectories({"ground truth": world_to_map(r.truth, r.start),
                             "RGB-D SLAM": world_to_map(r.slam_world, r.start)},
                            out_path=out / "vslam.png",
                            title="RGB-D SLAM trajectory against the ground truth (map frame)")
        picture = "\n![RGB-D SLAM](vslam.png)\n"
    report.add("## Stage 4 — RGB-D SLAM (RTAB-Map's manner) on the same route\n\n"
               + report.table(rows) + picture)
    return bool(getattr(r, "finished", True))


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    out.mkdir(parents=True, exist_ok=True)
    stages = [s.strip() for s in args.stages.split(",") if s.strip()]
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        print(f"eddie demo: unknown stages {unknown}; choose from {list(STAGES)}", file=sys.stderr)
        return 2
    report = Report(out)
    t0 = time.perf_counter()
    results = {}
    if "base" in stages:
        results["base"] = _stage_base(out, report, args.side)
    if "mapping" in stages:
        results["mapping"] = _stage_mapping(out, report, args.seed)
    if "nav" in stages:
        results["nav"] = _stage_nav(out, report, args.seed)
    if "vslam" in stages:
        results["vslam"] = _stage_vslam(out, report, args.seed)
    report.verdicts.update(results)
    path = report.write()
    print(f"\nreport: {path} ({time.perf_counter() - t0:.0f} s in all)")
    missed = [k for k, ok in results.items() if not ok]
    if missed:
        print(f"eddie demo: stages that fell short (see the report): {', '.join(missed)}",
              file=sys.stderr)
    return 1 if missed else 0
