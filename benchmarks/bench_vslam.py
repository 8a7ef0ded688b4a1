"""RGB-D SLAM benchmarks: visual odometry time/accuracy and loop-closure update time at 1,000 nodes.

Synthetic data: a textured corridor rendered by the pinhole ray-caster of the tests
(`tests/vslam/vslam_synthetic.py`), so ground truth is exact. Prints a table and writes
`benchmarks/results/vslam.json`. Optional `--tum FOLDER` replays a TUM RGB-D sequence too.

    .venv/bin/python benchmarks/bench_vslam.py [--nodes 1000] [--vo-frames 120] [--tum DIR]
        [--cpu-parts]  (per-part breakdown in CPU time; --vo-frames 0 skips odometry)
        [--vo-params defaults vo_stage] [--vo-only] [--vo-profile FILE]  (odometry settings,
        odometry alone, cProfile of the odometry frames on the CPU clock)
        [--profile FILE]  (cProfile, CPU clock, of the updates from node --nodes − 100 on)
        [--set NAME=VALUE ...]  (further RTAB-Map parameters for the loop-closure run)
        [--records FILE]  (every node's loop decision, CPU time and closure error, as JSON)
        [--compare-records A B]  (two --records files: same decisions? largest pose difference?)
        [--depth-scale UNITS_PER_M] [--fx FX --fy FY --cx CX --cy CY | --camera-info FILE.yaml]
            (the --tum folder's depth units and intrinsics, as `eddie vslam replay` reads them)
        [--tum-speed] [--tum-cycles 3] [--tum-nodes 1000]  (with --tum: time the folder alone,
            no synthetic run: odometry F2M and F2F per frame, then loop closure + graph update
            per node over the sequence played forward-backward --tum-cycles times, every frame
            a node, timed from --tum-nodes nodes in working memory on; memory per node)

        [--icl]  (--tum is the shared ICL-NUIM living-room sample, listed as a TUM folder in a
            temporary directory by `tests/vslam/icl_data.py`; nothing copied)

ICL-NUIM living room (depth 1000 units per metre), one core, written to
`benchmarks/results/vslam_icl_speed.json`:

    .venv/bin/python benchmarks/bench_vslam.py --icl --depth-scale 1000 --tum-speed \
        --out benchmarks/results/vslam_icl_speed.json
"""

from __future__ import annotations

import argparse
import cProfile
import datetime as dt
import hashlib
import importlib.util
import json
import os
import platform
import pstats
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from eddiebot.cli.vslam import _tum_setup
from eddiebot.vslam.camera import check_depth_plausible
from eddiebot.vslam.errors import DepthScaleError
from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.replay import CameraSetup, replay_tum
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import se3_inverse
from eddiebot.vslam.tum import load_tum_frame, read_tum_sequence

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "vslam.json"
REPORT_PARAMS = {
    "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "RGBD/ProximityBySpace": "false",
    "RGBD/AngularUpdate": "0.01", "RGBD/LinearUpdate": "0.01",
}


def _icl_tum_folder(work: Path) -> Path:
    """The shared ICL-NUIM sample (frames 0-210) listed as a TUM folder under `work`."""
    spec = importlib.util.spec_from_file_location("icl_data",
                                                  ROOT / "tests" / "vslam" / "icl_data.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["icl_data"] = mod
    spec.loader.exec_module(mod)
    if not (mod.ICL / "image").is_dir():
        raise OSError(f"ICL-NUIM sample not found at {mod.ICL} (set EDDIE_ICL_LIVINGROOM)")
    return Path(mod.write_icl_tum(work / "icl_livingroom1", range(mod.ICL_FRAMES)))


def _synthetic():
    spec = importlib.util.spec_from_file_location(
        "vslam_synthetic", ROOT / "tests" / "vslam" / "vslam_synthetic.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["vslam_synthetic"] = mod
    spec.loader.exec_module(mod)
    return mod


def corridor_loop(step: float = 0.06, turn_step: float = 0.1) -> list[tuple[float, float, float]]:
    """Planar poses (x, y, yaw) around a 26 m × 2 m rectangle in a 30 m × 5 m corridor."""
    corners = [(2.0, 1.5), (28.0, 1.5), (28.0, 3.5), (2.0, 3.5)]
    poses = []
    yaw = 0.0
    for k in range(4):
        (x0, y0), (x1, y1) = corners[k], corners[(k + 1) % 4]
        n = round(float(np.hypot(x1 - x0, y1 - y0)) / step)
        poses += [(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
        for _ in range(round((np.pi / 2) / turn_step)):
            yaw += turn_step
            poses.append((x1, y1, yaw))
    return poses


def _stats(ms: list[float]) -> dict[str, float]:
    a = np.asarray(ms)
    return {"median_ms": float(np.median(a)), "p95_ms": float(np.percentile(a, 95)),
            "max_ms": float(a.max()), "n": int(a.size)}


def _vo_parameters(name: str) -> dict[str, str]:
    """`--vo-params` sets: the library defaults (the published rows) or the simulated robot's
    odometry settings (`eddiebot.demo.vslam_stage.VO_PARAMETERS`, ICP fallback on)."""
    if name == "defaults":
        return {}
    from eddiebot.demo.vslam_stage import VO_PARAMETERS
    return dict(VO_PARAMETERS)


def bench_vo(syn, world, n_frames: int, params: dict[str, str] | None = None,
             profile: Path | None = None) -> dict[str, dict[str, Any]]:
    cam = syn.kinect_camera(640, 480)
    traj = corridor_loop(step=0.03, turn_step=0.05)[:n_frames]
    frames = [syn.render(world, syn.planar_pose(*p), cam) for p in traj]
    out = {}
    for name, strategy in (("F2M", "0"), ("F2F", "1")):
        vo = VisualOdometry(RtabmapParameters.from_dict({**(params or {}),
                                                          "Odom/Strategy": strategy}))
        rgb0, depth0 = frames[0]
        vo.process(rgb0, depth0, cam, 0)  # warm-up (numba, first map)
        vo.reset()
        times = []
        cpu = []
        errors = []
        lost = 0
        first = syn.planar_pose(*traj[0])
        prof = cProfile.Profile(time.process_time) if profile is not None else None
        poses = []
        for k, (rgb, depth) in enumerate(frames):
            if prof is not None and k > 0:
                prof.enable()
            t0, c0 = time.perf_counter(), time.process_time()
            r = vo.process(rgb, depth, cam, k * 33_333_333)
            times.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            if prof is not None:
                prof.disable()
            poses.append(None if r.pose is None else r.pose.round(9).tobytes())
            if r.pose is None:
                lost += 1
                continue
            truth = se3_inverse(first) @ syn.planar_pose(*traj[k])
            errors.append(float(np.linalg.norm(r.pose[:3, 3] - truth[:3, 3])))
        path = float(sum(np.hypot(traj[k + 1][0] - traj[k][0], traj[k + 1][1] - traj[k][1])
                         for k in range(len(traj) - 1)))
        if prof is not None and profile is not None:
            prof.dump_stats(profile.with_name(f"{profile.stem}_{name}{profile.suffix}"))
            print(f"-- VO {name}: cProfile (CPU clock), top 25 by own time")
            pstats.Stats(prof).sort_stats("tottime").print_stats(25)
        md5 = hashlib.md5(b"".join(b"-" if q is None else q for q in poses)).hexdigest()
        out[name] = {**_stats(times[1:]), "cpu": _stats(cpu[1:]), "lost": lost, "final_error_m": errors[-1],
                     "rmse_m": float(np.sqrt(np.mean(np.square(errors)))), "path_m": path,
                     "poses_md5": md5}
    return out


def bench_loop_closure(syn, world, n_nodes: int, extra: int,
                       memory_thr: int = 0, cpu_parts: bool = False,
                       frame_cache: Path | None = None,
                       compare_relinearize: float | None = None,
                       profile: Path | None = None,
                       overrides: dict[str, str] | None = None,
                       records: Path | None = None) -> dict[str, Any]:
    cam = syn.kinect_camera(640, 480)
    # ~Eddie at 1 Hz: 0.25 m or 0.25 rad between nodes; laps repeat, so revisits start at lap 2
    traj = corridor_loop(step=0.25, turn_step=0.25)
    laps = (traj * (1 + (n_nodes + extra) // len(traj)))[: n_nodes + extra]
    params = RtabmapParameters.from_dict({**REPORT_PARAMS, "Rtabmap/MemoryThr": str(memory_thr),
                                          **(overrides or {})})
    extractor = FeatureExtractor(params, max_features=params.vis_max_features,
                                 strategy=params.kp_detector_strategy)
    # with cpu_parts the core's own Timing/* statistics are CPU time (the machine is shared)
    slam = Rtabmap(params, timer=time.process_time if cpu_parts else time.perf_counter)
    # optional same-process A/B: a second core with another iSAM2 relinearisation threshold,
    # fed the same frames in alternating order, so that both see the same machine load
    other = None
    if compare_relinearize is not None:
        other = Rtabmap(params, timer=time.process_time)
        inner = getattr(other.optimizer, "incremental", None)
        assert inner is not None
        inner.relinearize_threshold = compare_relinearize
    other_cpu: list[float] = []
    other_loops = 0
    # optional cProfile (CPU-time clock) of the core over the nodes from --nodes − 100 on
    profiler = cProfile.Profile(time.process_time) if profile is not None else None
    rng = np.random.default_rng(0)
    odom = np.eye(4)
    prev_truth = syn.planar_pose(*laps[0])
    times: list[float] = []
    cpu: list[float] = []
    wm: list[int] = []
    parts: list[dict[str, float]] = []
    loops = 0
    # every node's decision (hypothesis id and value, loop, rejected loop), hashed: two code
    # versions that give the same digest took the same decisions
    decisions = hashlib.md5()
    rows: list[dict[str, Any]] = []
    render_s = 0.0
    for k, pose in enumerate(laps):
        truth = syn.planar_pose(*pose)
        step = se3_inverse(prev_truth) @ truth
        # wheel-odometry-like drift: 2 % scale, small heading noise
        step[:2, 3] *= 1.02
        c, s = np.cos(rng.normal(0, 0.002)), np.sin(rng.normal(0, 0.002))
        step[:2, :2] = step[:2, :2] @ np.array([[c, -s], [s, c]])
        odom = odom @ step
        prev_truth = truth
        t0 = time.perf_counter()
        cached = frame_cache / f"{k:05d}.npz" if frame_cache else None
        if cached is not None and cached.exists():
            with np.load(cached) as z:
                rgb, depth = z["rgb"], z["depth"]
        else:
            rgb, depth = syn.render(world, truth, cam)
            if cached is not None:
                np.savez(cached, rgb=rgb, depth=depth)
        feats = extractor.extract(rgb, depth, cam)
        render_s += time.perf_counter() - t0
        if other is not None and k % 2 == 0:
            c1 = time.process_time()
            other_loops += bool(other.process(rgb, depth, cam, odom, k * 1_000_000_000,
                                              features=feats).loop_closure_id)
            other_cpu.append((time.process_time() - c1) * 1e3)
        if profiler is not None and k == max(0, n_nodes - 100):
            profiler.enable()
        t0, c0 = time.perf_counter(), time.process_time()
        r = slam.process(rgb, depth, cam, odom, k * 1_000_000_000, features=feats)
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
        if other is not None and k % 2 == 1:
            c1 = time.process_time()
            other_loops += bool(other.process(rgb, depth, cam, odom, k * 1_000_000_000,
                                              features=feats).loop_closure_id)
            other_cpu.append((time.process_time() - c1) * 1e3)
        wm.append(int(r.statistics["Memory/Working_memory_size/"]))
        parts.append({k: v for k, v in r.statistics.items() if k.startswith("Timing/")})
        loops += bool(r.loop_closure_id)
        decisions.update(repr((r.hypothesis_id, round(r.hypothesis_value, 9), r.loop_closure_id,
                               r.rejected_loop_id)).encode())
        if records is not None:
            rows.append({"node": r.node_id, "hyp": r.hypothesis_id,
                         "value": round(r.hypothesis_value, 6), "loop": r.loop_closure_id,
                         "rejected": r.rejected_loop_id, "reason": r.rejection_reason,
                         "verified": r.statistics.get("Loop/Hypotheses_verified/", 0.0),
                         "cpu_ms": round(cpu[-1], 2), "wm": wm[-1],
                         # the node's map pose as returned (x, y, yaw; full precision)
                         "pose": (None if r.pose is None else
                                  [float(r.pose[0, 3]), float(r.pose[1, 3]),
                                   float(np.arctan2(r.pose[1, 0], r.pose[0, 0]))])})
            link = slam.memory.links.get(r.node_id, {}).get(r.loop_closure_id)
            if link is not None:  # the closure's error against the rendered poses (m)
                true = se3_inverse(syn.planar_pose(*laps[r.node_id - 1])) @ syn.planar_pose(
                    *laps[r.loop_closure_id - 1])
                rows[-1]["closure_error_m"] = round(float(np.linalg.norm(
                    (se3_inverse(true) @ link.transform)[:2, 3])), 4)
    if records is not None:
        # the last row also carries the final optimised graph (id → x, y, yaw)
        if rows:
            rows[-1]["final_poses"] = {
                str(i): [float(t[0, 3]), float(t[1, 3]), float(np.arctan2(t[1, 0], t[0, 0]))]
                for i, t in sorted(slam.optimized_poses.items())}
        records.write_text(json.dumps(rows))
    if profiler is not None and profile is not None:
        profiler.disable()
        profiler.dump_stats(str(profile))
        stats = pstats.Stats(profiler)
        stats.sort_stats("tottime").print_stats(20)
    target = min(n_nodes, len(times)) if memory_thr <= 0 else memory_thr
    near = [k for k, w in enumerate(wm) if w >= target - 110]
    if memory_thr > 0:
        near = list(range(max(0, len(times) - 200), len(times)))
    at_1000 = [times[k] for k in near]
    at_1000_cpu = [cpu[k] for k in near]
    keys = sorted({k for p in parts for k in p})
    breakdown = {k: float(np.median([parts[i].get(k, 0.0) for i in (near or range(len(parts)))]))
                 for k in keys}
    compare = {}
    if other is not None:
        compare = {"relinearize_threshold": compare_relinearize, "loop_closures": other_loops,
                   "at_1000_wm_cpu": _stats([other_cpu[k] for k in near] or other_cpu[-50:]),
                   "this_at_1000_wm_cpu": _stats(at_1000_cpu or cpu[-50:])}
    return {
        "compare": compare,
        "at_1000_wm_breakdown_median_ms": breakdown,
        "at_1000_wm_cpu": _stats(at_1000_cpu or cpu[-50:]),
        "nodes": len(times), "wm_final": wm[-1], "loop_closures": loops,
        "decisions_md5": decisions.hexdigest(),
        "dictionary_words": slam.vocabulary.active_words,
        "all": _stats(times), "at_1000_wm": _stats(at_1000 or times[-50:]),
        "render_and_extract_s": render_s,
    }


def bench_tum_speed(folder: Path, setup: CameraSetup, cycles: int, wm_target: int,
                    overrides: dict[str, str], profile: Path | None = None) -> dict[str, Any]:
    """Odometry per frame (F2M, F2F) on a TUM folder, then loop closure + graph update per
    node over the sequence played forward-backward `cycles` times, every frame a node.
    `profile`: cProfile (CPU clock) of the updates with WM >= `wm_target`."""
    listed = read_tum_sequence(folder).frames
    check_depth_plausible(load_tum_frame(listed[0], setup.depth_scale)[1], setup.depth_scale,
                          "give the depth images' units per metre with --depth-scale")
    frames = [load_tum_frame(f, setup.depth_scale) for f in listed]
    cam = setup.camera
    out: dict[str, Any] = {
        "folder": str(folder), "frames": len(frames),
        "intrinsics": [cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height],
        "intrinsics_source": setup.intrinsics_source, "depth_scale": setup.depth_scale,
        "depth_scale_source": setup.depth_scale_source, "load_avg_start": list(os.getloadavg()),
    }
    forward: list[Any] = []
    for name, strategy in (("F2M", "0"), ("F2F", "1")):
        vo = VisualOdometry(RtabmapParameters.from_dict({"Odom/Strategy": strategy}))
        vo.process(*frames[0], cam, 0)  # warm-up (numba, first map)
        vo.reset()
        wall, cpu, results = [], [], []
        for k, (rgb, depth) in enumerate(frames):
            t0, c0 = time.perf_counter(), time.process_time()
            r = vo.process(rgb, depth, cam, k * 33_333_333)
            wall.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            results.append(r)
        out[f"vo_{name}"] = {"cpu": _stats(cpu[1:]), "wall": _stats(wall[1:]),
                             "lost": sum(r.pose is None for r in results)}
        if name == "F2M":
            forward = results
    out["load_avg_after_vo"] = list(os.getloadavg())
    # forward-backward: frame k is revisited at the same pose, so the odometry of the forward
    # pass (pose, covariance, features) stands for the backward pass too
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
    order = order * cycles
    params = RtabmapParameters.from_dict({"RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0",
                                          **overrides})
    slam = Rtabmap(params)
    cpu, wall, wm = [], [], []
    loops = 0
    decisions = hashlib.md5()
    profiler = cProfile.Profile(time.process_time) if profile is not None else None
    for n, k in enumerate(order):
        r = forward[k]
        if r.pose is None:
            continue
        rgb, depth = frames[k]
        if profiler is not None and wm and wm[-1] >= wm_target:
            profiler.enable()
        t0, c0 = time.perf_counter(), time.process_time()
        res = slam.process(rgb, depth, cam, r.pose, n * 33_333_333,
                           odom_covariance=r.covariance, features=r.frame_features)
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
        if profiler is not None:
            profiler.disable()
        wm.append(int(res.statistics["Memory/Working_memory_size/"]))
        loops += bool(res.loop_closure_id)
        decisions.update(f"{res.loop_closure_id};".encode())
    if profiler is not None and profile is not None:
        profiler.dump_stats(str(profile))
        pstats.Stats(profiler).sort_stats("cumulative").print_stats(40)
    final = np.array([p[:3, 3] for p in slam.optimized_poses.values()]).reshape(-1, 3)
    near = [i for i, w in enumerate(wm) if w >= wm_target]
    in_ram = [nd.data.nbytes for nd in slam.memory.nodes.values() if nd.data is not None]
    out["loop_closure"] = {
        "order": f"frames 0..{len(frames) - 1}..1, {cycles} times (forward-backward)",
        "parameters": {"RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0", **overrides},
        "nodes": len(cpu), "wm_final": wm[-1] if wm else 0, "loop_closures": loops,
        "decisions_md5": decisions.hexdigest(),
        "optimized_xyz_mean_m": [round(float(v), 6) for v in final.mean(axis=0)],
        "timed_from_wm": wm_target, "timed_nodes": len(near),
        "cpu": _stats([cpu[i] for i in near] or cpu[-50:]),
        "wall": _stats([wall[i] for i in near] or wall[-50:]),
        "cpu_all": _stats(cpu),
        "node_kb_mean": float(np.mean(in_ram)) / 1e3 if in_ram else 0.0,
        "node_kb_max": float(np.max(in_ram)) / 1e3 if in_ram else 0.0,
        "nodes_with_data": len(in_ram),
    }
    out["load_avg_end"] = list(os.getloadavg())
    return out


def _print_vo(vo: dict[str, dict[str, Any]]) -> None:
    print(f"{'measure':44s} {'median':>9s} {'p95':>9s} {'goal':>8s}")
    for name in vo:
        v = vo[name]
        print(f"VO {name} per 640x480 frame, wall (ms)         {v['median_ms']:9.1f} "
              f"{v['p95_ms']:9.1f} {'<= 30':>8s}")
        print(f"VO {name} per 640x480 frame, CPU (ms)          {v['cpu']['median_ms']:9.1f} "
              f"{v['cpu']['p95_ms']:9.1f}")
        print(f"VO {name} error after {v['path_m']:.1f} m (m)"
              f"{'':18s}{v['final_error_m']:9.3f} {'':9s} lost={v['lost']} "
              f"poses md5 {v['poses_md5'][:12]}")


def compare_records(a_path: Path, b_path: Path) -> dict[str, Any]:
    """Two `--records` files: whether every node took the same decision, and the largest
    difference of the returned poses and of the final graphs (x, y in m, yaw in rad)."""
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    keys = ("node", "hyp", "value", "loop", "rejected", "reason")
    same = len(a) == len(b) and all(tuple(x[k] for k in keys) == tuple(y[k] for k in keys)
                                    for x, y in zip(a, b))
    pose_diff = max((abs(u - v) for x, y in zip(a, b) if x.get("pose") and y.get("pose")
                     for u, v in zip(x["pose"], y["pose"])), default=0.0)
    fa, fb = a[-1].get("final_poses", {}), b[-1].get("final_poses", {})
    graph_diff = max((abs(u - v) for i in fa.keys() & fb.keys() for u, v in zip(fa[i], fb[i])),
                     default=0.0)
    return {"nodes": len(a), "same_decisions": same, "max_pose_diff": pose_diff,
            "same_graph_nodes": fa.keys() == fb.keys(), "max_graph_diff": graph_diff}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--extra", type=int, default=100, help="frames after reaching --nodes")
    ap.add_argument("--vo-frames", type=int, default=120)
    ap.add_argument("--tum", type=Path, help="TUM RGB-D folder to replay (optional)")
    ap.add_argument("--memory-thr", type=int, default=0, help="Rtabmap/MemoryThr for the SLAM run")
    ap.add_argument("--cpu-parts", action="store_true",
                    help="per-part breakdown in CPU time instead of wall time")
    ap.add_argument("--compare-relinearize", type=float, metavar="THRESHOLD",
                    help="also run a core with this iSAM2 relinearisation threshold, interleaved")
    ap.add_argument("--frame-cache", type=Path,
                    help="folder keeping the rendered loop-closure frames between runs")
    ap.add_argument("--profile", type=Path, metavar="FILE",
                    help="cProfile (CPU time) of the updates from node --nodes - 100 on: "
                         "top 20 printed, stats in FILE (profiling slows the timed nodes)")
    ap.add_argument("--vo-params", nargs="+", choices=["defaults", "vo_stage"],
                    default=["defaults"],
                    help="odometry settings: library defaults and/or vslam_stage.VO_PARAMETERS")
    ap.add_argument("--vo-only", action="store_true", help="skip the loop-closure benchmark")
    ap.add_argument("--vo-profile", type=Path, metavar="FILE",
                    help="cProfile (CPU clock) of the timed odometry frames: top 25 printed, "
                         "stats in FILE_<F2M|F2F> (profiling slows the timed frames)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="RTAB-Map parameter for the loop-closure run (repeatable), e.g. "
                         "--set Rtabmap/LoopThr=0.05")
    ap.add_argument("--records", type=Path, metavar="FILE",
                    help="every node's loop-closure decision and CPU time, as JSON, in FILE")
    ap.add_argument("--compare-records", type=Path, nargs=2, metavar=("A", "B"),
                    help="compare two --records files (decisions, poses) and exit")
    ap.add_argument("--depth-scale", type=float, default=None, metavar="UNITS_PER_M",
                    help="--tum depth PNG units per metre (default 5000, ICL-NUIM 1000)")
    for name in ("fx", "fy", "cx", "cy"):
        ap.add_argument(f"--{name}", type=float, default=None,
                        help=f"--tum intrinsic {name} in pixels (give all four)")
    ap.add_argument("--camera-info", type=Path, default=None, metavar="FILE.yaml",
                    help="--tum intrinsics from a ROS camera_info YAML")
    ap.add_argument("--icl", action="store_true",
                    help="--tum is the shared ICL-NUIM living-room sample (give --depth-scale 1000)")
    ap.add_argument("--tum-speed", action="store_true",
                    help="time the --tum folder alone (odometry, loop closure, memory per node)")
    ap.add_argument("--tum-cycles", type=int, default=3,
                    help="forward-backward plays of the --tum folder for --tum-speed")
    ap.add_argument("--tum-nodes", type=int, default=1000,
                    help="--tum-speed times loop closure from this working-memory size on")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    if args.compare_records:
        print(json.dumps(compare_records(*args.compare_records)))
        return 0
    overrides = dict(kv.split("=", 1) for kv in args.set)
    cv2.setNumThreads(1)  # one core, as the published figures
    setup = None
    if args.icl:
        try:
            args.tum = _icl_tum_folder(Path(tempfile.mkdtemp(prefix="bench_vslam_icl_")))
        except OSError as exc:
            print(f"bench_vslam: {exc}", file=sys.stderr)
            return 2
    if args.tum:
        try:
            setup = _tum_setup(args.tum, args)
        except (ValueError, OSError) as exc:
            print(f"bench_vslam: {exc}", file=sys.stderr)
            return 2
    if args.tum_speed:
        if setup is None:
            print("bench_vslam: --tum-speed needs --tum FOLDER", file=sys.stderr)
            return 2
        try:
            speed = bench_tum_speed(args.tum, setup, args.tum_cycles, args.tum_nodes, overrides,
                                    args.profile)
        except DepthScaleError as exc:
            print(f"bench_vslam: {args.tum}: {exc}", file=sys.stderr)
            return 2
        speed = {"machine": platform.processor() or platform.machine(),
                 "python": platform.python_version(), "cpus": os.cpu_count(),
                 "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                 "clock": "cpu = time.process_time (one thread: cv2.setNumThreads(1))",
                 **speed}
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(speed, indent=2))
        for name in ("F2M", "F2F"):
            v = speed[f"vo_{name}"]
            print(f"VO {name} per frame: CPU median {v['cpu']['median_ms']:.1f} / p95 "
                  f"{v['cpu']['p95_ms']:.1f} ms, wall median {v['wall']['median_ms']:.1f} ms, "
                  f"lost {v['lost']}  (<= 20)")
        lc = speed["loop_closure"]
        print(f"loop closure + update per node at WM >= {lc['timed_from_wm']} ({lc['timed_nodes']} "
              f"nodes, WM final {lc['wm_final']}): CPU median {lc['cpu']['median_ms']:.1f} / p95 "
              f"{lc['cpu']['p95_ms']:.1f} ms, wall median {lc['wall']['median_ms']:.1f} ms "
              f"(<= 50); loop closures {lc['loop_closures']}")
        print(f"memory per node {lc['node_kb_mean']:.1f} kB (<= 100); load average "
              f"{speed['load_avg_end']}; wrote {args.out}")
        return 0
    syn = _synthetic()
    world = syn.BoxRoom(size_x=30.0, size_y=5.0, height=2.5, seed=7)
    results: dict[str, object] = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
    }
    vo: dict[str, dict[str, Any]] = {}
    if args.vo_frames > 1:
        for pset in args.vo_params:
            prof = (None if args.vo_profile is None else
                    args.vo_profile.with_name(f"{args.vo_profile.stem}_{pset}{args.vo_profile.suffix}"))
            part = bench_vo(syn, world, args.vo_frames, _vo_parameters(pset), prof)
            suffix = "" if pset == "defaults" else f" {pset}"
            vo.update({f"{k}{suffix}": {**v, "params": pset} for k, v in part.items()})
    results["vo"] = vo
    results["vo_load_avg"] = list(os.getloadavg())
    if args.vo_only:
        if args.out == RESULTS:  # keep the full run's file
            args.out = RESULTS.with_name("vslam_vo_speed_run.json")
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2))
        _print_vo(vo)
        print(f"load average {results['vo_load_avg']}; wrote {args.out}")
        return 0
    if args.frame_cache:
        args.frame_cache.mkdir(parents=True, exist_ok=True)
    lc = bench_loop_closure(syn, world, args.nodes, args.extra, args.memory_thr, args.cpu_parts,
                            args.frame_cache, args.compare_relinearize, args.profile, overrides,
                            args.records)
    lc["memory_thr"] = args.memory_thr
    lc["parameters"] = {**REPORT_PARAMS, **overrides}
    lc["load_avg_end"] = list(os.getloadavg())
    lc["breakdown_clock"] = "cpu" if args.cpu_parts else "wall"
    results["loop_closure"] = lc
    if args.tum:
        rep = replay_tum(args.tum, ROOT / "benchmarks" / "results" / "vslam_tum", setup=setup)
        results["tum"] = {"folder": str(args.tum), **rep.__dict__}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    _print_vo(vo)
    a = lc["at_1000_wm"]
    c = lc["at_1000_wm_cpu"]
    print(f"loop closure + update per node, WM~{lc['wm_final']}, wall (ms) {a['median_ms']:9.1f} "
          f"{a['p95_ms']:9.1f} {'<= 50':>8s}")
    print(f"loop closure + update per node, WM~{lc['wm_final']}, CPU (ms)  {c['median_ms']:9.1f} "
          f"{c['p95_ms']:9.1f}")
    print(f"  nodes {lc['nodes']}, loop closures {lc['loop_closures']}, "
          f"active words {lc['dictionary_words']}, decisions md5 {lc['decisions_md5']}")
    for k, v in lc["at_1000_wm_breakdown_median_ms"].items():
        print(f"  {k:42s} {v:9.1f}")
    comp = lc["compare"]
    if comp:
        o = comp["at_1000_wm_cpu"]
        print(f"  interleaved core, relinearisation {comp['relinearize_threshold']}: CPU "
              f"{o['median_ms']:.1f} / {o['p95_ms']:.1f} ms, loop closures {comp['loop_closures']}")
    if args.tum:
        print(json.dumps(results["tum"], indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
