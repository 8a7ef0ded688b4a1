"""Depth registration: re-project a depth image into the RGB camera, as depth_image_proc's
register node does.

Each depth pixel is back-projected with the depth intrinsics, moved into the RGB optical
frame by ``T_rgb_depth`` (4×4, maps points in the depth optical frame to the RGB optical
frame) and projected with the RGB intrinsics; it fills the rectangle its pixel's footprint
covers there (centre ± half a depth pixel, scaled by the focal ratio and the depth change),
keeping the nearest depth (z-buffer), so a magnified image has no holes. The output has the RGB camera's size and
the input's unit (16UC1 mm or 32FC1 m); pixels nothing lands on are 0 (16UC1) or NaN (32FC1).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.perception._image import DEPTH_ENCODINGS, check_size, image_to_array

__all__ = ["register_depth", "register_depth_array"]


@njit(cache=True, error_model="numpy")
def _register(
    depth: npt.NDArray[Any],
    unit: float,
    dk: npt.NDArray[np.float64],
    rk: npt.NDArray[np.float64],
    t: npt.NDArray[np.float64],
    out_h: int,
    out_w: int,
) -> npt.NDArray[np.float32]:
    out = np.full((out_h, out_w), np.inf, np.float32)
    h, w = depth.shape
    dfx, dfy, dcx, dcy = dk[0], dk[1], dk[2], dk[3]
    rfx, rfy, rcx, rcy = rk[0], rk[1], rk[2], rk[3]
    for v in range(h):
        yn = (v - dcy) / dfy
        for u in range(w):
            z = depth[v, u] * unit
            if not (z > 0.0 and z < 1e30):  # 0, NaN and Inf are no return
                continue
            x = (u - dcx) / dfx * z
            y = yn * z
            xr = t[0, 0] * x + t[0, 1] * y + t[0, 2] * z + t[0, 3]
            yr = t[1, 0] * x + t[1, 1] * y + t[1, 2] * z + t[1, 3]
            zr = t[2, 0] * x + t[2, 1] * y + t[2, 2] * z + t[2, 3]
            if zr <= 0.0:
                continue
            inv = 1.0 / zr
            pu = rfx * xr * inv + rcx
            pv = rfy * yr * inv + rcy
            # the depth pixel's footprint (±0.5 px) as seen from the RGB camera
            hu = 0.5 * rfx / dfx * z * inv
            hv = 0.5 * rfy / dfy * z * inv
            u0 = max(math.ceil(pu - hu), 0)
            u1 = min(math.floor(pu + hu), out_w - 1)
            v0 = max(math.ceil(pv - hv), 0)
            v1 = min(math.floor(pv + hv), out_h - 1)
            zf = np.float32(zr)
            for vv in range(v0, v1 + 1):
                for uu in range(u0, u1 + 1):
                    if zf < out[vv, uu]:
                        out[vv, uu] = zf
    return out


@njit(cache=True)
def _to_mm(z: npt.NDArray[np.float32]) -> npt.NDArray[np.uint16]:
    out = np.zeros(z.shape, np.uint16)
    for v in range(z.shape[0]):
        for u in range(z.shape[1]):
            m = z[v, u] * 1000.0 + 0.5
            if m < 65535.0:
                out[v, u] = np.uint16(m)
    return out


def register_depth_array(
    depth: npt.NDArray[Any],
    depth_k: tuple[float, float, float, float],
    rgb_k: tuple[float, float, float, float],
    rgb_size: tuple[int, int],
    T_rgb_depth: npt.NDArray[np.float64],
) -> npt.NDArray[Any]:
    """Array form: intrinsics as (fx, fy, cx, cy), ``rgb_size`` as (width, height)."""
    mm = depth.dtype == np.uint16
    out = _register(
        np.ascontiguousarray(depth),
        0.001 if mm else 1.0,
        np.asarray(depth_k, dtype=np.float64),
        np.asarray(rgb_k, dtype=np.float64),
        np.asarray(T_rgb_depth, dtype=np.float64),
        int(rgb_size[1]),
        int(rgb_size[0]),
    )
    if mm:
        return _to_mm(out)
    out[np.isinf(out)] = np.nan
    return out


def _k(info: Any) -> tuple[float, float, float, float]:
    k = np.asarray(info.k, dtype=np.float64)
    return float(k[0]), float(k[4]), float(k[2]), float(k[5])


def register_depth(
    depth: Any, depth_info: Any, rgb_info: Any, T_rgb_depth: npt.NDArray[np.float64]
) -> Any:
    """Register a depth ``Image`` to the RGB camera; returns an ``Image`` with the RGB
    camera's size and frame (``rgb_info.header.frame_id``) and the depth image's stamp."""
    from eddiebot.msgs.sensor_msgs import Image

    check_size(depth, depth_info)
    arr = image_to_array(depth, DEPTH_ENCODINGS)
    out = register_depth_array(
        arr, _k(depth_info), _k(rgb_info), (int(rgb_info.width), int(rgb_info.height)),
        T_rgb_depth,
    )
    header = type(depth.header)(stamp=depth.header.stamp, frame_id=rgb_info.header.frame_id)
    return Image(
        header=header,
        height=out.shape[0],
        width=out.shape[1],
        encoding=depth.encoding,
        is_bigendian=0,
        step=out.shape[1] * out.dtype.itemsize,
        data=np.ascontiguousarray(out).view(np.uint8).reshape(-1),
    )
