"""CPU of the visual odometry with the depth ICP (`VO_PARAMETERS`), per frame, on frames
recorded by ``bench_vslam_sim.py --record-vo --record-images --keep DIR``.

For each session: the whole odometry step (recorded features, so without the feature
extraction), the depth cloud (`depth_icp.make_scan`) and the ICP registration
(`depth_icp.icp_register`, on the frames that ran it), in CPU ms (``time.process_time``).
With ``--full`` the features are extracted again from the RGB (the whole VO per frame), and
``--scale 2`` runs on the images upsampled to 640×480 (nearest neighbour; the camera model
scaled, `Icp/DownsamplingStep` doubled so the cloud keeps its density, or ``--step``).
OpenCV runs on one thread (``--cv-threads``; the target is CPU per frame on one core);
``--retain-heap`` keeps freed memory in the heap (glibc ``mallopt``). Also
printed: key frames, the median inliers / features (`Odom/KeyFrameThr` compares the two), frames
lost, the end-point error against the recorded truth and the md5 of all poses.
Writes ``benchmarks/results/vslam_vo_icp_cpu.json``.

    .venv/bin/python benchmarks/bench_vslam_vo_icp.py /tmp/vo/rec/corridor [--full]
        [--scale 2] [--frames N] [--set Group/Name=VALUE]
"""

from __future__ import annotations

import argparse
import ctypes
import datetime as dt
import hashlib
import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

import eddiebot.vslam.odometry as odometry
from eddiebot.demo.vslam_stage import _FEATURE_FIELDS, VO_PARAMETERS
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.parameters import RtabmapParameters

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "vslam_vo_icp_cpu.json"


def _timed(fn: Callable[..., Any], sink: list[float]) -> Callable[..., Any]:
    def wrapper(*a: Any, **k: Any) -> Any:
        c0 = time.process_time()
        try:
            return fn(*a, **k)
        finally:
            sink.append((time.process_time() - c0) * 1e3)
    return wrapper


def _stats(ms: list[float]) -> dict[str, float]:
    if not ms:
        return {"n": 0, "median_ms": float("nan"), "p95_ms": float("nan"), "mean_ms": float("nan")}
    a = np.asarray(ms)
    return {"n": int(a.size), "median_ms": float(np.median(a)),
            "p95_ms": float(np.percentile(a, 95)), "mean_ms": float(a.mean())}


def run(folder: Path, overrides: dict[str, str], full: bool, scale: int, frames: int,
        step: int | None) -> dict[str, Any]:
    """Replay one session with timing wrappers around the cloud and the ICP."""
    data = np.load(folder / "vo_frames.npz")
    w, h = (int(v) for v in data["size"])
    cam = CameraIntrinsics.from_k(data["k"].ravel(), w, h, data["local_transform"])
    n = min(frames, len(data["stamps"])) if frames > 0 else len(data["stamps"])
    with np.load(folder / "vo_images.npz") as img:
        depth = img["depth"][:n]
        rgb = img["rgb"][:n] if full else None
    params = {**VO_PARAMETERS, **overrides}
    if scale > 1:
        cam = cam.scaled(scale)
        base_step = int(params.get("Icp/DownsamplingStep", "1"))
        params["Icp/DownsamplingStep"] = str(step if step else base_step * scale)
    scan_ms: list[float] = []
    icp_ms: list[float] = []
    frame_ms: list[float] = []
    keyframes, lost, inliers, features = 0, 0, [], []
    md5 = hashlib.md5()
    poses: list[tuple[int, Any]] = []
    orig_scan, orig_icp = odometry.make_scan, odometry.icp_register
    odometry.make_scan = _timed(orig_scan, scan_ms)  # type: ignore[assignment]
    odometry.icp_register = _timed(orig_icp, icp_ms)  # type: ignore[assignment]
    try:
        vo = odometry.VisualOdometry(RtabmapParameters.from_dict(params))
        offsets = np.concatenate([[0], np.cumsum(data["counts"])])
        fields = {name: data[name] for name in _FEATURE_FIELDS}
        for i in range(n):
            d = depth[i]
            if scale > 1:
                d = np.repeat(np.repeat(d, scale, axis=0), scale, axis=1)
            c0 = time.process_time()
            if rgb is not None:
                im = rgb[i]
                if scale > 1:
                    im = np.repeat(np.repeat(im, scale, axis=0), scale, axis=1)
                r = vo.process(im, d, cam, int(data["stamps"][i]))
            else:
                a, b = offsets[i], offsets[i + 1]
                feats = FrameFeatures(*(fields[name][a:b] for name in _FEATURE_FIELDS))
                if scale > 1:
                    feats = FrameFeatures(feats.uv * scale, *(getattr(feats, f) for f in
                                                              _FEATURE_FIELDS[1:]))
                r = vo.process_features(feats, cam, int(data["stamps"][i]), depth=d)
            frame_ms.append((time.process_time() - c0) * 1e3)
            keyframes += int(r.keyframe)
            lost += int(r.pose is None)
            md5.update(b"lost" if r.pose is None else r.pose.tobytes())
            if r.pose is not None:
                poses.append((i, r.pose))
                inliers.append(r.inliers)
                features.append(r.features)
    finally:
        odometry.make_scan, odometry.icp_register = orig_scan, orig_icp  # type: ignore[assignment]
    end_error = math.nan
    if len(poses) > 1:
        (i0, first), (i1, last) = poses[0], poses[-1]
        rel = np.linalg.inv(first) @ last
        truth = data["truth"]
        c, s_ = math.cos(truth[i0][2]), math.sin(truth[i0][2])
        end = truth[i0][:2] + np.array([c * rel[0, 3] - s_ * rel[1, 3], s_ * rel[0, 3] + c * rel[1, 3]])
        end_error = float(np.hypot(*(end - truth[i1][:2])))
    path = float(np.sum(np.hypot(*np.diff(data["truth"][:n, :2], axis=0).T)))
    return {"session": str(folder), "frames": n, "image": f"{cam.width}x{cam.height}",
            "features": "extracted" if full else "recorded",
            "icp_downsampling_step": params.get("Icp/DownsamplingStep"),
            "keyframes": keyframes, "lost": lost,
            "inliers_median": float(np.median(inliers)) if inliers else math.nan,
            "features_median": float(np.median(features)) if features else math.nan,
            "end_error_m": end_error, "path_m": path, "poses_md5": md5.hexdigest(),
            "vo_per_frame": _stats(frame_ms), "depth_cloud_per_frame": _stats(scan_ms),
            "icp_per_registration": _stats(icp_ms)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sessions", nargs="+", type=Path)
    ap.add_argument("--full", action="store_true", help="extract the features from the RGB")
    ap.add_argument("--scale", type=int, default=1, help="upsample the images (2: 640x480)")
    ap.add_argument("--step", type=int, default=None, help="Icp/DownsamplingStep when scaled")
    ap.add_argument("--frames", type=int, default=0, help="first N frames only (0 = all)")
    ap.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE")
    ap.add_argument("--cv-threads", type=int, default=1, help="cv2.setNumThreads (0 = OpenCV's)")
    ap.add_argument("--retain-heap", action="store_true",
                    help="keep freed memory in the heap (glibc mallopt, as "
                         "eddiebot.vslam.features.retain_freed_memory)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    if args.cv_threads > 0:
        cv2.setNumThreads(args.cv_threads)
    if args.retain_heap:  # done here, not imported: an older tree under PYTHONPATH lacks it
        mallopt = ctypes.CDLL("libc.so.6").mallopt
        mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD
        mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD
    overrides = dict(item.split("=", 1) for item in args.set)
    rows = [run(d, overrides, args.full, args.scale, args.frames, args.step)
            for d in args.sessions]
    print(f"{'session':28s} {'image':>8s} {'features':>9s} {'VO ms med/p95':>14s} "
          f"{'cloud ms':>9s} {'ICP ms med/p95 (n)':>20s}")
    for r in rows:
        v, c, i = r["vo_per_frame"], r["depth_cloud_per_frame"], r["icp_per_registration"]
        print(f"{r['session'][-28:]:28s} {r['image']:>8s} {r['features']:>9s} "
              f"{v['median_ms']:6.1f}/{v['p95_ms']:6.1f} {c['median_ms']:9.1f} "
              f"{i['median_ms']:7.1f}/{i['p95_ms']:6.1f} ({i['n']})")
        print(f"{'':28s} key frames {r['keyframes']}/{r['frames']}, lost {r['lost']}, inliers "
              f"{r['inliers_median']:.0f} of {r['features_median']:.0f} features (median), end "
              f"error {r['end_error_m']:.3f} m over {r['path_m']:.1f} m, poses md5 "
              f"{r['poses_md5'][:12]}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    previous: dict[str, Any] = {}
    if args.out.exists():
        previous = json.loads(args.out.read_text())
    key = f"{rows[0]['image']}_{rows[0]['features']}" + ("_retain_heap" if args.retain_heap else "")
    previous[key] = {"date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                     "overrides": overrides, "cv_threads": args.cv_threads,
                     "retain_heap": args.retain_heap,
                     "load_avg": list(os.getloadavg()), "runs": rows}
    args.out.write_text(json.dumps(previous, indent=2))
    print(f"wrote {args.out} [{key}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
