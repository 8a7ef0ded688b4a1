"""RGB-D SLAM on the ICL-NUIM living room (real-format data): ATE, loop closures, odometry
resets and map merges of `eddie vslam replay` runs.

Data: ``/work/shared/datasets/rgbd/icl_livingroom1_micro`` (or ``$EDDIE_ICL_LIVINGROOM``),
listed as TUM folders by ``tests/vslam/icl_data.py`` (nothing copied). Runs:

- ``gt5``: frames 0-4 against their ground truth;
- ``full``: frames 0-210 against Open3D's estimate (default parameters);
- ``fb``: forward then backward (every return frame an exact revisit), every frame a node;
- ``fb_icp``: ``fb`` with ICP odometry (``Reg/Strategy 1``): words and loop closures must stay;
- ``gap``: frames 101-149 removed (a 0.86 m / 37° jump): odometry lost, re-seeded, a new map;
- ``gap_return`` / ``gap_return_nodes``: the gap, then back to frame 0 through the frames the
  gap skipped (the return revisits the first map: a loop closure should merge the maps), with
  default update thresholds / every frame a node.

    .venv/bin/python benchmarks/bench_vslam_icl.py [--runs gt5 full fb fb_icp gap gap_return ...]
        [--work DIR]  (where the TUM folders and outputs go; default a temporary folder)

Writes ``benchmarks/results/vslam_icl.json`` (the reports, the commands, the machine).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from _common import machine, print_table, write_json

from eddiebot.vslam.replay import replay_tum, tum_camera_setup
from eddiebot.vslam.tum import write_tum_trajectory

ROOT = Path(__file__).resolve().parents[1]
EVERY_FRAME = {"RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0"}
#: ICP odometry (and ICP-refined loop closures): no visual features in the odometry
ICP_ODOMETRY = {"Reg/Strategy": "1", "Icp/PointToPlane": "true", "Icp/DownsamplingStep": "4"}


def _icl() -> Any:
    spec = importlib.util.spec_from_file_location("icl_data",
                                                  ROOT / "tests" / "vslam" / "icl_data.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["icl_data"] = mod
    spec.loader.exec_module(mod)
    return mod


def _runs(icl: Any) -> dict[str, tuple[list[int], dict[str, str], str]]:
    """name → (frame indices, parameters, reference)."""
    fwd = list(range(icl.ICL_FRAMES))
    gap = [*range(101), *range(150, icl.ICL_FRAMES)]
    back = list(range(icl.ICL_FRAMES - 2, -1, -1))
    o3d = "Open3D's estimate (open3d_reconstruction_trajectory.log)"
    return {
        "gt5": (list(range(5)), {}, "ground truth of frames 0-4"),
        "full": (fwd, {}, o3d),
        "fb": (icl.forward_backward(1), EVERY_FRAME, o3d),
        "fb_icp": (icl.forward_backward(1), {**EVERY_FRAME, **ICP_ODOMETRY}, o3d),
        "gap": (gap, {}, o3d),
        "gap_return": (gap + back, {}, o3d),
        "gap_return_nodes": (gap + back, EVERY_FRAME, o3d),
    }


def main() -> int:
    icl = _icl()
    runs = _runs(icl)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", nargs="+", choices=list(runs), default=list(runs))
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--out", default="vslam_icl")
    args = ap.parse_args()
    if not (icl.ICL / "image").is_dir():
        print(f"bench_vslam_icl: the ICL-NUIM sample is not at {icl.ICL}", file=sys.stderr)
        return 2
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_vslam_icl_"))
    rows: list[dict[str, Any]] = []
    for name in args.runs:
        indices, params, reference = runs[name]
        folder = icl.write_icl_tum(work / name, indices)
        if name == "gt5":
            write_tum_trajectory(folder / "groundtruth.txt", [k / icl.RATE_HZ for k in range(5)],
                                 icl.read_redwood_log(
                                     icl.ICL / "gt_livingroom1_frames0-4_from_open3d_TestData.log"))
        setup = tum_camera_setup(folder, depth_scale=icl.ICL_DEPTH_SCALE,
                                 depth_scale_source="--depth-scale")
        t0 = time.perf_counter()
        report = replay_tum(folder, work / f"{name}_out", params, setup=setup)
        sets = " ".join(f"--set {k}={v}" for k, v in params.items())
        rows.append({"name": name, "frames": report.frames, "reference": reference,
                     "parameters": params, "wall_s": round(time.perf_counter() - t0, 1),
                     "command": f"eddie vslam replay DIR --depth-scale 1000 {sets}".strip(),
                     "report": asdict(report)})
        print(f"{name}: done in {rows[-1]['wall_s']} s", flush=True)
    table = [{"run": r["name"], "frames": r["frames"], "nodes": r["report"]["nodes"],
              "lost": r["report"]["lost_frames"], "loops": r["report"]["loop_closures"],
              "prox": r["report"]["proximity_links"],
              "resets": r["report"]["odometry_resets"], "merges": r["report"]["map_merges"],
              "maps": r["report"]["maps"], "ate_cm": 100 * r["report"]["slam_ate_m"],
              "key_ate_cm": 100 * r["report"]["keyframe_ate_m"],
              "odom_ate_cm": 100 * r["report"]["odom_ate_m"],
              "words": r["report"]["words"], "node_kb": r["report"]["node_kb"]} for r in rows]
    print_table(table, list(table[0]))
    path = write_json(args.out, {
        "machine": machine(),
        "data": f"{icl.ICL} (Augmented ICL-NUIM livingroom1, frames 0-210, depth 1000 units/m)",
        "results": rows})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
