"""Loop-closure detection on simulated routes with revisits: recall at 100 % precision
(RTAB-Map's metric), precision–recall over `Rtabmap/LoopThr`, time per image; for the whole
detector (what RTAB-Map's figure counts) and for appearance alone.

Images: the simulator's Kinect RGB camera (640×480, `eddiebot.sim.render`) along the demo
routes of several worlds, one image every 0.35 m or 0.5 rad (Eddie at ~1 Hz), with a small
pose jitter (σ 3 cm, 1°) and pixel noise (σ 2 grey levels) so that revisits never see the
very same image.

Detectors, fed the same images:

* ``full``: the `Rtabmap` core as `launch/vslam.yaml` runs it (the report's parameters plus
  `RGBD/LoopClosureMaxMahalanobis` 4), with the registered depth of the simulated Kinect
  (`kinect_depth`: disparity noise and quantisation, drop-outs) and wheel odometry that drifts
  (2 % scale error, σ 0.002 rad heading noise per image) given with link variances 1e-4 m² /
  1e-5 rad². A closure counts when the Bayes hypothesis ≥ `Rtabmap/LoopThr` passed PnP
  (`Vis/MinInliers`), the Mahalanobis gate and `RGBD/OptimizeMaxError`.
* ``appearance``: `AppearanceLoopDetector` (`eddie vslam loops`): GFTT/ORB, incremental
  vocabulary, TF-IDF, Bayes filter, RTAB-Map defaults; every best hypothesis counts.

Ground truth from the true poses and the rendered depth: two images show the *same place* when
the cameras are within 1 m and 30° and at least half of the first view (a 40×30 grid of its
depth points) re-projects into the second with consistent depth. A query image is *positive*
when a same place is among its loop candidates (older than `Mem/STMSize` images). Its best
hypothesis (appearance) is *right* if it is a same place; *near* (counted neither right nor
wrong) if the headings are within 45° and 30 % of one of the two views re-projects into the
other (e.g. a view 3 m further down a corridor: geometric verification could still register
it); else *wrong*. An accepted closure (full) is *right* if it is a same place and its
transform is within 0.3 m and 10° of the true relative pose; a transform off by more is
*wrong* wherever it points; a right transform between views that overlap less is not counted.

    .venv/bin/python benchmarks/bench_vslam_recall.py [--worlds office corridor warehouse]
        [--modes appearance full] [--set-full Rtabmap/LoopThr=0.05] [--records]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import platform
import time
from pathlib import Path

import cv2
import numpy as np

from eddiebot.demo.route import OFFICE_LONG_ROUTE, WAREHOUSE_ROUTE, Waypoint
from eddiebot.demo.vslam_stage import CORRIDOR_LONG_ROUTE, SLAM_PARAMETERS
from eddiebot.sim.camera import KinectConfig
from eddiebot.sim.render import camera_pose, kinect_depth, render_view
from eddiebot.sim.worlds import load_world
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.loops import (
    AppearanceLoopDetector,
    precision_recall_curve,
    recall_at_full_precision,
)
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import OPTICAL_ROTATION, from_xyz_yaw, se3_inverse, yaw_of

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "vslam_recall.json"
ROUTES: dict[str, tuple[Waypoint, ...]] = {
    "office": OFFICE_LONG_ROUTE, "corridor": CORRIDOR_LONG_ROUTE, "warehouse": WAREHOUSE_ROUTE,
}
GRID = (40, 30)  # depth points per view for the overlap test


def route_poses(start: tuple[float, float, float], route: tuple[Waypoint, ...],
                step: float, turn_step: float) -> list[tuple[float, float, float]]:
    """Poses (x, y, θ) every `step` m or `turn_step` rad: turn towards each waypoint, drive to
    it, spin there."""
    x, y, th = start
    out = [(x, y, th)]

    def turn(target: float) -> None:
        nonlocal th
        delta = math.atan2(math.sin(target - th), math.cos(target - th))
        n = max(1, math.ceil(abs(delta) / turn_step)) if abs(delta) > 1e-6 else 0
        for k in range(n):
            out.append((x, y, th + delta * (k + 1) / n))
        th = th + delta

    for wp in route:
        dist = math.hypot(wp.x - x, wp.y - y)
        if dist > 1e-6:
            turn(math.atan2(wp.y - y, wp.x - x))
            n = max(1, math.ceil(dist / step))
            x0, y0 = x, y
            for k in range(n):
                out.append((x0 + (wp.x - x0) * (k + 1) / n, y0 + (wp.y - y0) * (k + 1) / n, th))
            x, y = wp.x, wp.y
        if wp.spin:
            n = max(1, math.ceil(abs(wp.spin) / turn_step))
            th0 = th
            for k in range(n):
                out.append((x, y, th0 + wp.spin * (k + 1) / n))
            th = th0 + wp.spin
    return out


def _rays(intr, stride_u: int, stride_v: int):
    us = (np.arange(GRID[0]) + 0.5) * stride_u
    vs = (np.arange(GRID[1]) + 0.5) * stride_v
    u, v = np.meshgrid(us, vs)
    return u.ravel(), v.ravel()


class Views:
    """Camera poses and sub-sampled depth of every image, for the overlap test."""

    def __init__(self, intr) -> None:
        self.intr = intr
        self.su, self.sv = intr.width // GRID[0], intr.height // GRID[1]
        self.u, self.v = _rays(intr, self.su, self.sv)
        self.cams: list[tuple[float, float, float, float]] = []
        self.depth: list[np.ndarray] = []

    def add(self, cam: tuple[float, float, float, float], depth: np.ndarray) -> None:
        self.cams.append(cam)
        iu = self.u.astype(int)
        iv = self.v.astype(int)
        self.depth.append(depth[iv, iu].reshape(GRID[1], GRID[0]).astype(np.float64))

    def _axes(self, k: int):
        x, y, z, yaw = self.cams[k]
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x, y, z]), np.array([c, s, 0.0]), np.array([s, -c, 0.0]), \
            np.array([0.0, 0.0, -1.0])

    def overlap(self, i: int, j: int) -> float:
        """Share of view i's depth points seen by view j at a consistent depth."""
        intr = self.intr
        z = self.depth[i].ravel()
        ok = np.isfinite(z) & (z > 0.3) & (z < 8.0)
        if not ok.any():
            return 0.0
        o, f, r, d = self._axes(i)
        xr = (self.u[ok] - intr.cx) / intr.fx
        yd = (self.v[ok] - intr.cy) / intr.fy
        pts = o + z[ok, None] * (f + xr[:, None] * r + yd[:, None] * d)
        o2, f2, r2, d2 = self._axes(j)
        rel = pts - o2
        zf = rel @ f2
        front = zf > 0.3
        u = intr.cx + intr.fx * (rel @ r2) / np.where(front, zf, 1.0)
        v = intr.cy + intr.fy * (rel @ d2) / np.where(front, zf, 1.0)
        inside = front & (u >= 0) & (u < intr.width - 1) & (v >= 0) & (v < intr.height - 1)
        gu = np.clip(np.round(u / self.su - 0.5).astype(int), 0, GRID[0] - 1)
        gv = np.clip(np.round(v / self.sv - 0.5).astype(int), 0, GRID[1] - 1)
        seen = self.depth[j][gv, gu]
        consistent = inside & np.isfinite(seen) & (np.abs(seen - zf) < 0.15 * zf + 0.05)
        return float(consistent.sum() / ok.sum())


def _place(poses, views, i: int, j: int, dist: float, angle: float, share: float,
           either: bool = False) -> bool:
    """Within `dist` m and `angle` degrees, and `share` of both views (of either view if
    `either`) re-project into the other."""
    (xi, yi, ti), (xj, yj, tj) = poses[i], poses[j]
    if math.hypot(xi - xj, yi - yj) > dist:
        return False
    if abs(math.atan2(math.sin(ti - tj), math.cos(ti - tj))) > math.radians(angle):
        return False
    a, b = views.overlap(i, j), views.overlap(j, i)
    return (max(a, b) if either else min(a, b)) >= share


#: The whole detector as `launch/vslam.yaml` runs it: the report's RTAB-Map parameters
#: (eddie_hardware.md §6) plus the Mahalanobis gate on closures (not upstream).
REPORT_PARAMS = {
    "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "RGBD/ProximityBySpace": "false",
    "RGBD/AngularUpdate": "0.01", "RGBD/LinearUpdate": "0.01",
    "RGBD/LoopClosureMaxMahalanobis": "4",
}
#: Odometry link variances (m², rad²) given with each frame, as the `gated` profile of
#: bench_vslam_sim.py: σ 1 cm and 0.18° per node, the size of the simulated drift below.
ODOM_VARIANCE = (1e-4, 1e-5)
#: A verified closure is right only if its transform also agrees with the ground truth.
TRANSFORM_TOLERANCE = (0.3, math.radians(10.0))
#: Profiles of the whole detector: `gated` (the set-up of the first runs: link variances
#: 1e-4 / 1e-5, PnP loop registration) and `product` (the SLAM node's profile for the simulated
#: Eddie, `eddiebot.demo.vslam_stage.SLAM_PARAMETERS`: link variances 1e-5 / 1e-5, per-node
#: odometry frames `RGBD/OdomHeadingSigma`, 3D→3D loop registration `Vis/EstimationType` 0).
PROFILES: dict[str, tuple[tuple[float, float], dict[str, str]]] = {
    "gated": (ODOM_VARIANCE, {}),
    "product": ((float(SLAM_PARAMETERS["odom_tf_linear_variance"]),
                 float(SLAM_PARAMETERS["odom_tf_angular_variance"])),
                {k: str(v) for k, v in SLAM_PARAMETERS.items() if "/" in k}),
}
#: Stages that can stop a positive image (see `stage_breakdown`).
STAGES = ("right", "below_thr", "gate", "registration", "optimize_max_error", "near", "wrong",
          "other")


def _summary(values: list[float], verdicts: list[int], positive: int, loop_thr: float,
             cpu: list[float], wall: list[float]) -> dict[str, object]:
    recall, thr = recall_at_full_precision(values, verdicts, positive)
    curve = precision_recall_curve(values, verdicts, positive)
    at_default = [(p, r) for t, p, r in curve if t >= loop_thr]
    p_def, r_def = at_default[-1] if at_default else (1.0, 0.0)
    return {
        "recall_at_100_precision": recall, "threshold_at_100_precision": thr,
        "at_default_loop_thr": {"Rtabmap/LoopThr": loop_thr, "precision": p_def,
                                "recall": r_def},
        "right": int(sum(v == 1 for v in verdicts)), "near": int(sum(
            v == 0 and val > 0 for v, val in zip(verdicts, values))),
        "wrong": int(sum(v == -1 for v in verdicts)),
        "curve": [{"thr": t, "precision": p, "recall": r}
                  for t, p, r in curve[:: max(1, len(curve) // 60)]],
        "per_image_wall_ms": {"median": float(np.median(wall)),
                              "p95": float(np.percentile(wall, 95))},
        "per_image_cpu_ms": {"median": float(np.median(cpu)), "p95": float(np.percentile(cpu, 95))},
    }


def _verdict(poses, views, k: int, h: int) -> int:
    """1 same place, 0 near (not counted), −1 wrong place."""
    if _place(poses, views, k, h, 1.0, 30.0, 0.5):
        return 1
    if _place(poses, views, k, h, math.inf, 45.0, 0.3, either=True):
        return 0
    return -1


def _stage(rec: dict) -> str:
    """Which stage stopped (or passed) one image of the whole detector."""
    if rec.get("loop"):
        return {1: "right", 0: "near", -1: "wrong"}[int(rec["verdict"])]
    reason = str(rec.get("reason", ""))
    if not rec.get("rejected"):
        return "below_thr"
    if reason.startswith("RGBD/LoopClosureMaxMahalanobis"):
        return "gate"
    if reason.startswith("registration failed"):
        return "registration"
    if reason.startswith("RGBD/OptimizeMaxError"):
        return "optimize_max_error"
    return "other"


def stage_breakdown(records: list[dict]) -> dict[str, object]:
    """Per positive image: the stage that stopped it, split by where its hypothesis pointed
    (`same`: a same place, `near`, `wrong`, `none`); and over every rejected hypothesis (all
    images): how many of the gated / optimiser-rejected ones carried a right transform."""
    names = {1: "same", 0: "near", -1: "wrong"}
    pos: dict[str, dict[str, int]] = {s: {} for s in STAGES}
    for rec in records:
        if not rec.get("positive") or "hyp" not in rec:
            continue
        where = names[int(rec["hyp_verdict"])] if rec.get("hyp") else "none"
        row = pos[_stage(rec)]
        row[where] = row.get(where, 0) + 1
    rejected: dict[str, dict[str, int]] = {}
    for rec in records:
        if "hyp" not in rec or rec.get("loop") or not rec.get("rejected"):
            continue
        stage = _stage(rec)
        row = rejected.setdefault(stage, {})
        kind = "right_transform" if rec.get("rej_right") else (
            "wrong_transform" if "rej_t_err" in rec else "no_transform")
        where = names[int(rec["hyp_verdict"])]
        row[kind] = row.get(kind, 0) + 1
        row[f"{kind}/{where}"] = row.get(f"{kind}/{where}", 0) + 1
        if rec.get("positive"):
            row[f"{kind}/positive"] = row.get(f"{kind}/positive", 0) + 1
    return {"positives": {s: v for s, v in pos.items() if v}, "rejected": rejected}


def rgb_camera(config: KinectConfig) -> CameraIntrinsics:
    """The simulated Kinect RGB camera as the core's model (optical frame in base_footprint)."""
    intr = config.rgb
    local = OPTICAL_ROTATION.copy()
    local[:3, 3] = config.rgb_position
    return CameraIntrinsics(intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height, local)


def run_world(name: str, params: dict[str, str], step: float, turn_step: float,
              seed: int, modes: tuple[str, ...] = ("appearance", "full"),
              full_params: dict[str, str] | None = None,
              max_images: int = 0, records: list[dict] | None = None,
              odom_variance: tuple[float, float] = ODOM_VARIANCE) -> dict[str, object]:
    """Both detectors over the same images: `appearance` (`AppearanceLoopDetector`, images
    only) and `full` (the `Rtabmap` core with registered Kinect depth and wheel odometry:
    Bayes hypothesis ≥ `Rtabmap/LoopThr`, PnP verification, `RGBD/OptimizeMaxError`)."""
    world = load_world(name)
    config = KinectConfig()
    intr = config.rgb
    truth = route_poses(world.start, ROUTES[name], step, turn_step)
    if max_images > 0:
        truth = truth[:max_images]
    rng = np.random.default_rng(seed)
    odom_rng = np.random.default_rng(seed + 1)
    detector = AppearanceLoopDetector(RtabmapParameters.from_dict(params))
    stm = detector.params.mem_stm_size
    slam = None
    if "full" in modes:
        slam = Rtabmap(RtabmapParameters.from_dict({**REPORT_PARAMS, **params,
                                                   **(full_params or {})}))
        stm = slam.params.mem_stm_size
    cam_model = rgb_camera(config)
    views = Views(intr)
    poses: list[tuple[float, float, float]] = []
    app: dict[str, list] = {"values": [], "verdicts": [], "wall": [], "cpu": []}
    full: dict[str, list] = {"values": [], "verdicts": [], "wall": [], "cpu": [],
                             "t_err": [], "r_err": []}
    rejected: dict[str, int] = {}
    positive = 0
    all_records: list[dict] = []
    render_s = 0.0
    odom = np.eye(4)
    lin_var, ang_var = odom_variance
    odom_cov = np.diag([lin_var] * 3 + [ang_var] * 3)
    for k, (x, y, th) in enumerate(truth):
        pose = (x + rng.normal(0, 0.03), y + rng.normal(0, 0.03), th + rng.normal(0, 0.017))
        t0 = time.perf_counter()
        cam = camera_pose(pose, config.rgb_position)
        rgb, depth = render_view(world, cam, intr, shading=config.shading)
        grey_f = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)
        noise = np.asarray(rng.normal(0, 2.0, grey_f.shape))
        grey = np.clip(grey_f + noise, 0, 255).astype(np.uint8)
        render_s += time.perf_counter() - t0
        views.add(cam, depth)
        poses.append(pose)
        # loop candidates: images older than the short-term memory
        has_loop = any(_place(poses, views, k, j, 1.0, 30.0, 0.5) for j in range(k - stm + 1))
        positive += has_loop
        rec: dict[str, object] = {"k": k, "positive": has_loop}
        all_records.append(rec)
        if records is not None:
            records.append(rec)
        if "appearance" in modes:
            t0, c0 = time.perf_counter(), time.process_time()
            det = detector.process(grey)
            app["wall"].append((time.perf_counter() - t0) * 1e3)
            app["cpu"].append((time.process_time() - c0) * 1e3)
            app["values"].append(det.hypothesis_value if det.hypothesis_id else 0.0)
            # node ids are image indices + 1
            app["verdicts"].append(_verdict(poses, views, k, det.hypothesis_id - 1)
                                   if det.hypothesis_id else 0)
            rec.update(app_hyp=det.hypothesis_id, app_value=det.hypothesis_value)
        if slam is not None:
            if k:
                prev = from_xyz_yaw(*poses[k - 1])
                move = se3_inverse(prev) @ from_xyz_yaw(*pose)
                move[:2, 3] *= 1.02  # wheel odometry: 2 % scale error, heading noise
                odom = odom @ move @ from_xyz_yaw(0.0, 0.0, float(odom_rng.normal(0, 0.002)))
            colour = np.clip(rgb.astype(np.float64) + noise[..., None], 0, 255).astype(np.uint8)
            d16 = kinect_depth(depth, config, k)
            t0, c0 = time.perf_counter(), time.process_time()
            r = slam.process(colour, d16, cam_model, odom, k * 1_000_000_000,
                             odom_covariance=odom_cov)
            full["wall"].append((time.perf_counter() - t0) * 1e3)
            full["cpu"].append((time.process_time() - c0) * 1e3)
            rec.update(hyp=r.hypothesis_id, value=r.hypothesis_value, loop=r.loop_closure_id,
                       rejected=r.rejected_loop_id, reason=r.rejection_reason,
                       hyp_verdict=_verdict(poses, views, k, r.hypothesis_id - 1)
                       if r.hypothesis_id else 0)
            if has_loop and r.hypothesis_id and rec["hyp_verdict"] != 1:
                # where the posterior put the same place: rank and share among the locations
                ids, post = slam.bayes.posterior_arrays()
                order = np.argsort(-post[1:], kind="stable")[:20] + 1
                for rank, s in enumerate(order.tolist()):
                    if post[s] > 0 and _place(poses, views, k, int(ids[s]) - 1, 1.0, 30.0, 0.5):
                        rec.update(same_rank=rank, same_post=float(post[s]),
                                   top_post=float(post[order[0]]))
                        break
            if r.rejected_loop_id:
                why = r.rejection_reason.split(":")[0].split(" (")[0]
                rejected[why] = rejected.get(why, 0) + 1
                if r.rejected_transform is not None:
                    # was the turned-away transform right? (against the true relative pose)
                    h = r.rejected_loop_id - 1
                    true_rel = se3_inverse(from_xyz_yaw(*pose)) @ from_xyz_yaw(*poses[h])
                    err = se3_inverse(true_rel) @ r.rejected_transform
                    rt, rr = float(np.hypot(err[0, 3], err[1, 3])), abs(yaw_of(err))
                    rec.update(rej_t_err=rt, rej_r_err=rr,
                               rej_right=rt <= TRANSFORM_TOLERANCE[0]
                               and rr <= TRANSFORM_TOLERANCE[1])
            if not r.loop_closure_id:
                full["values"].append(0.0)
                full["verdicts"].append(0)
                continue
            h = r.loop_closure_id - 1
            verdict = _verdict(poses, views, k, h)
            link = slam.memory.links[r.node_id][r.loop_closure_id].transform
            true_rel = se3_inverse(from_xyz_yaw(*pose)) @ from_xyz_yaw(*poses[h])
            err = se3_inverse(true_rel) @ link
            t_err = float(np.hypot(err[0, 3], err[1, 3]))
            r_err = abs(yaw_of(err))
            full["t_err"].append(t_err)
            full["r_err"].append(r_err)
            if t_err > TRANSFORM_TOLERANCE[0] or r_err > TRANSFORM_TOLERANCE[1]:
                verdict = -1  # a closure with a wrong transform is an error wherever it is
            elif verdict == -1 and _place(poses, views, k, h, math.inf, 90.0, 0.1, either=True):
                verdict = 0  # right transform between views that share a little: not counted
            rec.update(t_err=t_err, r_err=r_err, verdict=verdict,
                       mahalanobis=r.statistics.get("Loop/Mahalanobis/", math.nan))
            full["values"].append(r.hypothesis_value)
            full["verdicts"].append(verdict)
    out: dict[str, object] = {"world": name, "images": len(truth), "positives": positive,
                              "render_s": render_s}
    if "appearance" in modes:
        out.update(_summary(app["values"], app["verdicts"], positive,
                            detector.params.rtabmap_loop_thr, app["cpu"], app["wall"]))
    if slam is not None:
        f = _summary(full["values"], full["verdicts"], positive, slam.params.rtabmap_loop_thr,
                     full["cpu"], full["wall"])
        f["accepted"] = int(sum(v > 0 for v in full["values"]))
        f["rejected"] = rejected
        f["transform_error_median"] = {
            "m": float(np.median(full["t_err"])) if full["t_err"] else math.nan,
            "deg": float(np.degrees(np.median(full["r_err"]))) if full["r_err"] else math.nan}
        f["parameters"] = {**REPORT_PARAMS, **params, **(full_params or {})}
        f["odom_variance"] = list(odom_variance)
        f["stages"] = stage_breakdown(all_records)
        out["full"] = f
    return out


def _row(name: str, label: str, r: dict, images: int, positives: int) -> str:
    d = r["at_default_loop_thr"]
    cpu = r["per_image_cpu_ms"]
    return (f"{name:10s} {label:10s} {images:6d} {positives:6d} "
            f"{r['recall_at_100_precision']:8.3f} {r['threshold_at_100_precision']:6.3f} "
            f"{d['precision']:5.3f}/{d['recall']:5.3f} {r['right']:5d} {r['near']:5d} "
            f"{r['wrong']:5d} {cpu['median']:10.1f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office", "corridor", "warehouse"],
                    choices=sorted(ROUTES))
    ap.add_argument("--modes", nargs="+", default=["appearance", "full"],
                    choices=["appearance", "full"],
                    help="appearance-only detector and/or the whole detector (core + depth)")
    ap.add_argument("--step", type=float, default=0.35, help="metres between images")
    ap.add_argument("--turn-step", type=float, default=0.5, help="radians between images")
    ap.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE",
                    help="RTAB-Map parameter override for both detectors (repeatable)")
    ap.add_argument("--set-full", action="append", default=[], metavar="Group/Name=VALUE",
                    help="override for the whole detector only (repeatable)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-images", type=int, default=0, help="first N images only (debugging)")
    ap.add_argument("--records", action="store_true", help="per-image decisions in the JSON")
    ap.add_argument("--odom-variance", nargs=2, type=float, default=None,
                    metavar=("LINEAR", "ANGULAR"),
                    help="odometry link variances (m², rad²; default: the profile's)")
    ap.add_argument("--profile", choices=sorted(PROFILES), default="product",
                    help="whole detector's odometry variances and SLAM parameters: `product` "
                         "(the SLAM node's for the simulated Eddie) or `gated` (first runs)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    params = dict(item.split("=", 1) for item in args.set)
    profile_variance, profile_params = PROFILES[args.profile]
    full_params = {**profile_params, **dict(item.split("=", 1) for item in args.set_full)}
    odom_variance = tuple(args.odom_variance or profile_variance)
    results: dict[str, object] = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "profile": args.profile, "odom_variance": list(odom_variance),
        "parameters": params, "full_parameters": full_params, "step_m": args.step,
        "turn_step_rad": args.turn_step, "transform_tolerance_m_rad": TRANSFORM_TOLERANCE,
    }
    rows = []
    print(f"{'world':10s} {'detector':10s} {'images':>6s} {'loops':>6s} {'R@100%P':>8s} "
          f"{'thr':>6s} {'P/R @0.11':>12s} {'right':>5s} {'near':>5s} {'wrong':>5s} "
          f"{'ms/img cpu':>10s}")
    for name in args.worlds:
        c0 = time.process_time()
        records: list[dict] | None = [] if args.records else None
        r = run_world(name, params, args.step, args.turn_step, args.seed, tuple(args.modes),
                      full_params, args.max_images, records, odom_variance)
        if records is not None:
            r["records"] = records
        r["cpu_s"] = time.process_time() - c0
        rows.append(r)
        n, pos = int(str(r["images"])), int(str(r["positives"]))
        if "appearance" in args.modes:
            print(_row(name, "appearance", r, n, pos), flush=True)
        if "full" in args.modes:
            f = r["full"]
            assert isinstance(f, dict)
            print(_row(name, "full", f, n, pos) + f"  accepted {f['accepted']}, rejected "
                  f"{f['rejected']}, transform error median {f['transform_error_median']}",
                  flush=True)
            print(f"{'':21s} stages {json.dumps(f['stages'])}", flush=True)
    results["worlds"] = rows
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
