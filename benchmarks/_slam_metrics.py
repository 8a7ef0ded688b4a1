"""Trajectory metrics for the SLAM benchmarks (SE(2) alignment, relative pose errors)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_between, wrap_angle

FloatArray = npt.NDArray[np.float64]


def align_se2(est: FloatArray, ref: FloatArray) -> FloatArray:
    """``est`` moved by the one SE(2) transform that best fits its positions onto ``ref``."""
    a, b = est[:, :2], ref[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    h = (a - ca).T @ (b - cb)
    u, _, vt = np.linalg.svd(h)
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    t = cb - r @ ca
    yaw = np.arctan2(r[1, 0], r[0, 0])
    out = est.copy()
    out[:, :2] = a @ r.T + t
    out[:, 2] = wrap_angle(est[:, 2] + yaw)
    return out


def _pair_errors(
    est: FloatArray, ref: FloatArray, i: npt.NDArray[np.int64], j: npt.NDArray[np.int64]
) -> tuple[FloatArray, FloatArray]:
    de = se2_between(est[i], est[j])
    dr = se2_between(ref[i], ref[j])
    trans = np.hypot(de[:, 0] - dr[:, 0], de[:, 1] - dr[:, 1])
    rot = np.abs(wrap_angle(de[:, 2] - dr[:, 2]))
    return trans, rot


def rpe_by_time(
    est: FloatArray, ref: FloatArray, stamps: FloatArray, delta_s: float
) -> dict[str, float]:
    """Relative pose error over pairs ``delta_s`` apart (first pose at or after t + delta)."""
    i = np.arange(len(stamps))
    j = np.searchsorted(stamps, stamps + delta_s)
    ok = j < len(stamps)
    trans, rot = _pair_errors(est, ref, i[ok], j[ok])
    return _summary(trans, rot)


def rpe_by_distance(
    est: FloatArray, ref: FloatArray, dmin: float = 1.0, dmax: float = 10.0
) -> dict[str, float]:
    """Relative pose error over every pair whose path length along ``ref`` is in [dmin, dmax] m."""
    step = np.hypot(*np.diff(ref[:, :2], axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(step)])
    ii, jj = np.triu_indices(len(s), k=1)
    d = s[jj] - s[ii]
    keep = (d >= dmin) & (d <= dmax)
    trans, rot = _pair_errors(est, ref, ii[keep], jj[keep])
    return _summary(trans, rot)


def revisit_error(
    est: FloatArray, ref: FloatArray, near: float = 3.0, apart: float = 30.0
) -> dict[str, float]:
    """Relative pose error of revisits: pairs within ``near`` m of each other on ``ref`` but at
    least ``apart`` m apart along its path — the pairs only a closed loop gets right."""
    step = np.hypot(*np.diff(ref[:, :2], axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(step)])
    ii, jj = np.triu_indices(len(s), k=1)
    gap = np.hypot(ref[jj, 0] - ref[ii, 0], ref[jj, 1] - ref[ii, 1])
    keep = (s[jj] - s[ii] >= apart) & (gap <= near)
    trans, rot = _pair_errors(est, ref, ii[keep], jj[keep])
    out = _summary(trans, rot)
    if trans.size:
        out["trans_p95_m"] = float(np.percentile(trans, 95))
    return out


def _summary(trans: FloatArray, rot: FloatArray) -> dict[str, float]:
    if trans.size == 0:
        return {"pairs": 0}
    return {
        "pairs": int(trans.size),
        "trans_mean_m": float(trans.mean()),
        "trans_std_m": float(trans.std()),
        "trans_rmse_m": float(np.sqrt(np.mean(trans**2))),
        "rot_mean_deg": float(np.degrees(rot.mean())),
        "rot_rmse_deg": float(np.degrees(np.sqrt(np.mean(rot**2)))),
    }


def evo_ape_rmse(stamps: FloatArray, est: FloatArray, ref: FloatArray) -> float | None:
    """APE RMSE (m) from evo after SE(3) alignment, or None if evo is unavailable."""
    try:
        from evo.core import metrics, sync  # noqa: F401
        from evo.core.trajectory import PoseTrajectory3D
    except ImportError:
        return None

    def traj(p: FloatArray) -> PoseTrajectory3D:
        xyz = np.column_stack([p[:, 0], p[:, 1], np.zeros(len(p))])
        quat = np.column_stack(
            [np.cos(p[:, 2] / 2), np.zeros(len(p)), np.zeros(len(p)), np.sin(p[:, 2] / 2)]
        )
        return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat, timestamps=stamps)

    t_est, t_ref = traj(est), traj(ref)
    t_est.align(t_ref)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((t_ref, t_est))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))


def scan_consistency(
    poses: FloatArray, points: list[FloatArray], window: int = 10, cap: float = 0.15
) -> dict[str, float]:
    """How well a trajectory's scans agree with each other, without any reference.

    Each scan's end points (sensor frame) are placed by ``poses`` (sensor poses, map frame)
    and compared with the ``window`` scans before it, placed the same way: the mean distance
    from each end point to the nearest earlier end point, counting only distances below
    ``cap`` m (farther points see parts of the room the earlier scans did not). Returns the
    mean and median over scans (m); lower means a sharper, more self-consistent map.
    """
    from scipy.spatial import cKDTree

    from eddiebot.geometry import se2_transform_points

    per_scan = []
    for k in range(window, len(poses)):
        ref = np.concatenate(
            [se2_transform_points(poses[j], points[j]) for j in range(k - window, k)]
        )
        if ref.shape[0] == 0 or points[k].shape[0] == 0:
            continue
        d, _ = cKDTree(ref).query(se2_transform_points(poses[k], points[k]))
        d = d[d < cap]
        if d.size:
            per_scan.append(float(d.mean()))
    if not per_scan:
        return {"scans": 0}
    v = np.array(per_scan)
    return {"scans": int(v.size), "mean_m": float(v.mean()), "median_m": float(np.median(v))}
