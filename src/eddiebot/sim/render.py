"""Kinect RGB and depth rendering: a numba column caster over the 2.5-D world.

For each image column the caster intersects one horizontal ray with every prism (quads by
Cyrus-Beck clipping, circles analytically), sorts the entry distances, and fills the
column's rows front to back with a per-row depth buffer: a prism's side face covers the rows
whose ray height at the entry lies within [bottom, top]; its top (bottom) face covers the
rows looking down (up) onto that plane inside the prism; floor and ceiling planes fill what
is left. The first floor-to-ceiling prism ends the column. Depth is the optical-axis z (the
Kinect reports z, not the ray length). Textures are mip-mapped (level chosen from the
pixel's footprint per face column and per floor row) and shifted along each object's faces
by a per-object offset, so equal walls do not repeat the same posters in the same places.
Columns are cast into a 16-column tile that is flushed into the row-major outputs. The
camera looks along +x of its frame with no pitch or roll, the optical frames being
camera_*_frame rotated by rpy (−π/2, 0, −π/2).

`kinect_depth` turns an ideal depth image into what a Kinect v1 reports (see
`eddiebot.sim.camera.KinectConfig`): disparity-quantised, noisy, edge drop-outs, no return
outside [min_range, max_range]; deterministic for a given seed and frame index; the
disparity noise independent per pixel or correlated over a window (``noise_correlation_px``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.sim.camera import KINECT_DEPTH, CameraIntrinsics, KinectConfig
from eddiebot.sim.textures import TEXTURES, texture_atlas
from eddiebot.sim.world import World

__all__ = ["KinectFrame", "Renderer", "camera_pose", "kinect_depth", "noise_boxes",
           "noise_correlation", "noise_window_px", "render_view"]

_MAX_HITS = 96
_TILE = 16  # columns per output tile
_MIP_LEVELS = 5  # 256, 128, 64, 32, 16 texels per tile side
# fast-math without the no-NaN/no-Inf assumptions: Inf marks 'nothing hit'
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}
_TEX_SIZE = 256  # texture tiles are 256 × 256 (a power of two: coordinates wrap by masking)
_LIGHT = (0.6, 0.8)


@njit(cache=True, fastmath=_FAST, error_model="numpy", inline="always")
def _texel(mip: npt.NDArray[np.uint32], mip_off: npt.NDArray[np.int64], level: int, tex: int,
           isc: float, s: float, t: float, k: int, out: npt.NDArray[np.uint32], i: int) -> None:
    """Write the shaded texel at surface coordinates (s, t) m into out[i] (packed 0x00BBGGRR)
    from mip ``level``; ``isc`` is that level's texels per metre, ``k`` the shade in 1/256."""
    n = _TEX_SIZE >> level
    iu = math.floor(s * isc) & (n - 1)  # n is a power of two
    iv = n - 1 - (math.floor(t * isc) & (n - 1))
    p = np.uint32(mip[mip_off[level] + (tex * n + iu) * n + iv])  # column-major tiles
    kk = np.uint32(k)
    rb = ((p & np.uint32(0xFF00FF)) * kk >> np.uint32(8)) & np.uint32(0xFF00FF)
    g = ((p & np.uint32(0x00FF00)) * kk >> np.uint32(8)) & np.uint32(0x00FF00)
    out[i] = rb | g


@njit(cache=True, fastmath=_FAST, error_model="numpy", inline="always")
def _level(texels_per_pixel: float) -> int:
    """Mip level for a footprint: the finest level with at most ~2 texels per pixel."""
    if texels_per_pixel < 2.0:
        return 0
    return min(_MIP_LEVELS - 1, math.floor(math.log2(texels_per_pixel)))


@njit(cache=True, fastmath=_FAST, error_model="numpy")
def _cast(
    ox: float, oy: float, oz: float, yaw: float,
    width: int, height: int, fx: float, fy: float, cx: float, cy: float,
    quads: npt.NDArray[np.float64], quad_z: npt.NDArray[np.float64],
    quad_tex: npt.NDArray[np.int64], quad_toff: npt.NDArray[np.float64],
    circles: npt.NDArray[np.float64], circle_z: npt.NDArray[np.float64],
    circle_tex: npt.NDArray[np.int64], circle_toff: npt.NDArray[np.float64],
    floor_tex: int, ceil_tex: int, ceil_h: float,
    mip: npt.NDArray[np.uint32], mip_off: npt.NDArray[np.int64],
    tex_scale: npt.NDArray[np.float64], want_rgb: bool, shading: bool,
    rgb: npt.NDArray[np.uint8], depth: npt.NDArray[np.float32],
) -> None:
    fwx, fwy = math.cos(yaw), math.sin(yaw)
    lfx, lfy = -fwy, fwx
    h_in = np.empty(_MAX_HITS)
    h_out = np.empty(_MAX_HITS)
    h_b = np.empty(_MAX_HITS)
    h_t = np.empty(_MAX_HITS)
    h_tex = np.empty(_MAX_HITS, np.int64)
    h_s = np.empty(_MAX_HITS)  # texture coordinate along the entry face
    h_shade = np.empty(_MAX_HITS)
    order = np.empty(_MAX_HITS, np.int64)
    lx, ly = _LIGHT
    # Cull: the image columns each quad can cover, from its corners' bearings.
    nq = quads.shape[0]
    q_u0 = np.empty(nq, np.int64)
    q_u1 = np.empty(nq, np.int64)
    for k in range(nq):
        lo, hi, behind, front = 1e30, -1e30, 0, 0
        for e in range(4):
            dx, dy = quads[k, e, 0] - ox, quads[k, e, 1] - oy
            f = dx * fwx + dy * fwy
            lft = dx * lfx + dy * lfy
            if f <= 1e-6:
                behind += 1
                continue
            front += 1
            uu = cx - fx * lft / f
            lo, hi = min(lo, uu), max(hi, uu)
        if front == 0:
            q_u0[k], q_u1[k] = 1, 0  # entirely behind the camera
        elif behind > 0:
            q_u0[k], q_u1[k] = 0, width - 1
        else:
            q_u0[k] = max(0, math.floor(lo) - 1)
            q_u1[k] = min(width - 1, math.ceil(hi) + 1)
    n_tex = _TEX_SIZE
    inv_scale = n_tex / tex_scale
    # per-row tables: height drop per metre of depth, and depth per metre of height drop
    rowk = np.empty(height)
    inv_rowk = np.empty(height)
    # the floor (below the horizon) and ceiling (above) per row: depth, texture, shade
    plane_d = np.empty(height)
    plane_tex = np.empty(height, np.int64)
    plane_k = np.empty(height, np.int64)
    plane_lvl = np.empty(height, np.int64)
    plane_isc = np.empty(height)
    for v in range(height):
        rowk[v] = (v - cy) / fy
        inv_rowk[v] = fy / (v - cy) if v != cy else 1e30
        if v > cy:
            plane_d[v], plane_tex[v], base = oz * inv_rowk[v], floor_tex, 0.85
        elif v < cy:
            plane_d[v], plane_tex[v], base = (oz - ceil_h) * inv_rowk[v], ceil_tex, 0.95
        else:
            plane_d[v], plane_tex[v], base = np.inf, floor_tex, 0.0
        plane_k[v] = min(256, int(256.0 * base / (1.0 + 0.04 * plane_d[v]))) if shading else 256
        # footprint: d/fy across the ray, foreshortened by d/h along it (geometric mean)
        h = oz if v > cy else ceil_h - oz
        x = inv_scale[plane_tex[v]] * plane_d[v] / fy * math.sqrt(plane_d[v] / h) if v != cy else 1.0
        plane_lvl[v] = _level(x)
        plane_isc[v] = inv_scale[plane_tex[v]] / (1 << plane_lvl[v])
    # Columns are cast into a small column-major tile that is flushed row by row into the
    # row-major outputs: no separate transpose pass, and the tile stays in L1.
    tile_rgb = np.empty((_TILE, height), np.uint32)
    tile_d = np.empty((_TILE, height), np.float32)
    packed = np.empty((height, width) if want_rgb else (1, 1), np.uint32)
    for u in range(width):
        tj = u % _TILE
        a = (u - cx) / fx
        rx, ry = fwx - a * lfx, fwy - a * lfy  # ray per unit of forward depth
        nh = 0
        for k in range(nq):
            if u < q_u0[k] or u > q_u1[k]:
                continue
            d_in, d_out, edge = -1e30, 1e30, -1
            ok = True
            for e in range(4):
                ax, ay = quads[k, e, 0], quads[k, e, 1]
                bx, by = quads[k, (e + 1) % 4, 0], quads[k, (e + 1) % 4, 1]
                nx, ny = by - ay, -(bx - ax)  # outward for counter-clockwise
                num = nx * (ox - ax) + ny * (oy - ay)
                den = nx * rx + ny * ry
                if den == 0.0:
                    if num > 0.0:
                        ok = False
                        break
                    continue
                t = -num / den
                if den < 0.0:
                    if t > d_in:
                        d_in, edge = t, e
                elif t < d_out:
                    d_out = t
                if d_in > d_out:
                    ok = False
                    break
            if not ok or d_out <= 1e-6 or d_in <= 1e-6 or nh >= _MAX_HITS:
                continue
            ax, ay = quads[k, edge, 0], quads[k, edge, 1]
            bx, by = quads[k, (edge + 1) % 4, 0], quads[k, (edge + 1) % 4, 1]
            px, py = ox + d_in * rx, oy + d_in * ry
            elen = math.hypot(bx - ax, by - ay)
            h_in[nh], h_out[nh] = d_in, d_out
            h_b[nh], h_t[nh] = quad_z[k, 0], quad_z[k, 1]
            h_tex[nh] = quad_tex[k]
            # continuous along walls: measure from a world-anchored origin along the edge
            h_s[nh] = (px * (bx - ax) + py * (by - ay)) / elen + quad_toff[k]
            h_shade[nh] = 0.6 + 0.4 * abs((by - ay) * lx - (bx - ax) * ly) / elen
            nh += 1
        for k in range(circles.shape[0]):
            fxo, fyo = ox - circles[k, 0], oy - circles[k, 1]
            qa = rx * rx + ry * ry
            qb = 2.0 * (fxo * rx + fyo * ry)
            qc = fxo * fxo + fyo * fyo - circles[k, 2] * circles[k, 2]
            disc = qb * qb - 4 * qa * qc
            if disc <= 0.0 or nh >= _MAX_HITS:
                continue
            sq = math.sqrt(disc)
            d_in, d_out = (-qb - sq) / (2 * qa), (-qb + sq) / (2 * qa)
            if d_in <= 1e-6:
                continue
            px, py = ox + d_in * rx - circles[k, 0], oy + d_in * ry - circles[k, 1]
            ang = math.atan2(py, px)
            h_in[nh], h_out[nh] = d_in, d_out
            h_b[nh], h_t[nh] = circle_z[k, 0], circle_z[k, 1]
            h_tex[nh] = circle_tex[k]
            h_s[nh] = ang * circles[k, 2] + circle_toff[k]
            h_shade[nh] = 0.6 + 0.4 * abs(px * lx + py * ly) / circles[k, 2]
            nh += 1
        # insertion sort by entry depth
        for i in range(nh):
            order[i] = i
        for i in range(1, nh):
            j = i
            while j > 0 and h_in[order[j - 1]] > h_in[order[j]]:
                order[j - 1], order[j] = order[j], order[j - 1]
                j -= 1
        zbuf = tile_d[tj]  # the column doubles as the depth buffer
        col = tile_rgb[tj]
        for v in range(height):
            zbuf[v] = np.inf
        for oi in range(nh):
            k = order[oi]
            d_in, d_out, zb, zt = h_in[k], h_out[k], h_b[k], h_t[k]
            tex = h_tex[k]
            isc = inv_scale[tex]
            fall = 1.0 / (1.0 + 0.04 * d_in) if shading else 1.0
            # side face: rows whose height at d_in lies in [zb, zt]
            v0 = max(0, math.ceil(cy + (oz - zt) * fy / d_in))
            v1 = min(height - 1, math.floor(cy + (oz - zb) * fy / d_in))
            ksh = min(256, int(256.0 * (h_shade[k] * fall if shading else 1.0)))
            s_face = h_s[k]
            lvl = _level(isc * d_in / fy)
            isc_l = isc / (1 << lvl)
            for v in range(v0, v1 + 1):
                if d_in < zbuf[v]:
                    zbuf[v] = d_in
                    if want_rgb:
                        _texel(mip, mip_off, lvl, tex, isc_l, s_face, oz - d_in * rowk[v], ksh,
                               col, v)
            # top face (seen from above) and bottom face (seen from below)
            for face in range(2):
                plane = zt if face == 0 else zb
                dz = oz - plane
                if (face == 0 and dz <= 0.0) or (face == 1 and dz >= 0.0):
                    continue
                lo = cy + dz * fy / d_out
                hi = cy + dz * fy / d_in
                if lo > hi:
                    lo, hi = hi, lo
                v0 = max(0, math.ceil(lo))
                v1 = min(height - 1, math.floor(hi))
                ksh = min(256, int(256.0 * ((1.0 if face == 0 else 0.55) * fall))) if shading else 256
                for v in range(v0, v1 + 1):
                    d = dz * inv_rowk[v]
                    if d < d_in or d > d_out or d >= zbuf[v]:
                        continue
                    zbuf[v] = d
                    if want_rgb:
                        lvl = _level(isc * d / fy * math.sqrt(d / abs(dz)))
                        _texel(mip, mip_off, lvl, tex, isc / (1 << lvl), ox + d * rx, oy + d * ry,
                               ksh, col, v)
            if zb <= 0.0 and zt >= ceil_h:
                break
        # floor below the horizon, ceiling above it, wherever nothing was hit
        for v in range(height):
            if zbuf[v] < np.inf:
                continue
            d = plane_d[v]
            zbuf[v] = d
            if want_rgb:
                if d == np.inf:
                    col[v] = 0
                else:
                    _texel(mip, mip_off, plane_lvl[v], plane_tex[v], plane_isc[v], ox + d * rx,
                           oy + d * ry, plane_k[v], col, v)
        if tj == _TILE - 1 or u == width - 1:
            u0 = u - tj
            for v in range(height):
                for jj in range(tj + 1):
                    depth[v, u0 + jj] = tile_d[jj, v]
                if want_rgb:
                    for jj in range(tj + 1):
                        packed[v, u0 + jj] = tile_rgb[jj, v]
    if want_rgb:
        # unpack 0x00BBGGRR into rgb8 in one sequential pass
        flat = packed.reshape(-1)
        out = rgb.reshape(-1)
        for i in range(flat.shape[0]):
            p = flat[i]
            out[3 * i] = p & 0xFF
            out[3 * i + 1] = (p >> 8) & 0xFF
            out[3 * i + 2] = (p >> 16) & 0xFF


@njit(cache=True, fastmath=_FAST, error_model="numpy")
def _kinect(ideal: npt.NDArray[np.float32], gauss: npt.NDArray[np.float32],
            uniform: npt.NDArray[np.float32], offset: int, goffset: int, min_range: float,
            max_range: float, step_coeff: float, sigma: float, edge_thr: float,
            edge_factor: float, edge_drop: float, drop: float) -> npt.NDArray[np.uint16]:
    # Branch-free inner loop so LLVM vectorises it (≈ 0.6 ms for 640 × 480).
    h, w = ideal.shape
    out = np.zeros((h, w), np.uint16)
    c = np.float32(1.0 / step_coeff)  # z = c / disparity; one disparity step = 1
    sig, sig_e = np.float32(sigma), np.float32(sigma * edge_factor)
    thr = np.float32(edge_thr)
    p_drop, p_edge = np.float32(drop), np.float32(drop + edge_drop)
    zmin, zmax = np.float32(min_range), np.float32(max_range)
    for v in range(h):
        base, gbase = offset + v * w, goffset + v * w
        row = ideal[v]
        up = ideal[max(v - 1, 0)]
        dn = ideal[min(v + 1, h - 1)]
        orow = out[v]
        g = gauss[gbase : gbase + w]
        pr = uniform[base : base + w]
        for u in range(w):
            z = row[u]
            ul = row[u - 1] if u > 0 else z
            ur = row[u + 1] if u < w - 1 else z
            dmax = max(max(abs(up[u] - z), abs(dn[u] - z)), max(abs(ul - z), abs(ur - z)))
            edge = dmax > thr * z
            s = sig_e if edge else sig
            dropped = pr[u] < (p_edge if edge else p_drop)
            di = math.floor(c / z + s * g[u] + np.float32(0.5))
            zq = c / di
            ok = (zq >= zmin) & (zq <= zmax) & (di > 0) & (not dropped)
            orow[u] = np.uint16(zq * np.float32(1000.0) + np.float32(0.5)) if ok else np.uint16(0)
    return out


_POOL = 1 << 20


@lru_cache(maxsize=8)
def _noise_pool(seed: int) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    rng = np.random.default_rng(seed)
    return (rng.standard_normal(_POOL, dtype=np.float32), rng.random(_POOL, dtype=np.float32))


def noise_boxes(window: float) -> tuple[tuple[int, float], ...]:
    """(box side in pixels, variance share) of the correlated-noise field for a ``window``
    pixels wide: one box of side ``window`` when it is a whole number, else a mix of
    independent boxes of sides ⌊window⌋ and ⌊window⌋ + 1 whose shares make the correlation
    at lag d (pixels, along a row or column) exactly 1 − d / window for d ≤ ⌊window⌋
    (a box's is 1 − d / side). ``window`` ≤ 1: independent noise, ((1, 1.0),)."""
    if window <= 1.0:
        return ((1, 1.0),)
    n = math.floor(window)
    if window == n:
        return ((n, 1.0),)
    a = (1.0 / window - 1.0 / (n + 1)) * n * (n + 1)
    return ((n, a), (n + 1, 1.0 - a))


def noise_correlation(window: float, lag: int) -> float:
    """Correlation of the noise of two pixels ``lag`` apart along a row or column."""
    return float(sum(share * max(0.0, 1.0 - lag / side) for side, share in noise_boxes(window)))


def noise_window_px(config: KinectConfig, width: int) -> float:
    """The disparity-noise correlation window in pixels of an image ``width`` wide."""
    return float(config.noise_correlation_px) * width / KINECT_DEPTH.width


@lru_cache(maxsize=8)
def _correlated_pool(seed: int, width: int, window: float) -> npt.NDArray[np.float32]:
    """Unit-σ Gaussian noise, spatially correlated over a ``window``-pixel square, laid out
    as ``_POOL // width`` rows of ``width``: white noise (its own seeded stream) summed over
    square boxes (`noise_boxes`), each divided by its analytic σ (the side) and weighted by
    the square root of its share, so every sample has σ 1 exactly in distribution; a margin
    makes the pool stationary (no wrap at the image's sides)."""
    rows = _POOL // width
    rng = np.random.default_rng([seed, width, 0x6B696E])
    field = np.zeros((rows, width), np.float32)
    for side, share in noise_boxes(window):
        white = rng.standard_normal((rows + side - 1, width + side - 1), dtype=np.float32)
        across = np.zeros((rows + side - 1, width), np.float32)
        for i in range(side):
            across += white[:, i : i + width]
        box = np.zeros((rows, width), np.float32)
        for i in range(side):
            box += across[i : i + rows]
        field += np.float32(math.sqrt(share) / side) * box
    return field.reshape(-1)


def kinect_depth(ideal: npt.NDArray[np.float32], config: KinectConfig | None = None,
                 frame_index: int = 0) -> npt.NDArray[np.uint16]:
    """Kinect v1 behaviour on an ideal depth image (float32 m, +Inf = nothing) → 16UC1
    millimetres (0 = no return). Deterministic in (``config.seed``, ``frame_index``): noise
    comes from a seeded pool of 2²⁰ samples read at a per-frame offset. With
    ``config.noise_correlation_px`` the disparity noise comes from a pool correlated over
    that window (`noise_window_px`), read at a per-frame row offset."""
    config = config or KinectConfig()
    h, w = ideal.shape
    if h * w > _POOL // 2:
        raise ValueError(f"depth image {w}x{h} is larger than the noise pool supports")
    gauss, uniform = _noise_pool(int(config.seed))
    mixed = (int(config.seed) * 0x9E3779B97F4A7C15 + int(frame_index) * 0xBF58476D1CE4E5B9)
    offset = (mixed ^ (mixed >> 29)) % (_POOL - h * w)
    goffset = offset
    window = noise_window_px(config, w)
    if window > 1.0:
        gauss = _correlated_pool(int(config.seed), w, round(window, 6))
        goffset = ((mixed ^ (mixed >> 31)) % (_POOL // w - h + 1)) * w
    return _kinect(np.ascontiguousarray(ideal, dtype=np.float32), gauss, uniform, offset,
                   goffset, config.min_range, config.max_range, config.disparity_step_coeff,
                   config.noise_disparity_sigma, config.edge_threshold,
                   config.edge_noise_factor, config.edge_dropout, config.dropout)


def camera_pose(robot_pose: tuple[float, float, float] | npt.ArrayLike,
                position: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """World (x, y, z, yaw) of a camera mounted at ``position`` on base_footprint."""
    x, y, th = (float(v) for v in np.asarray(robot_pose, dtype=np.float64)[:3])
    c, s = math.cos(th), math.sin(th)
    px, py, pz = position
    return x + c * px - s * py, y + s * px + c * py, pz, th


def _cast_into(world: World, cam: tuple[float, float, float, float], intr: CameraIntrinsics,
               want_rgb: bool, shading: bool, people: npt.NDArray[np.float64] | None,
               people_height: npt.NDArray[np.float64] | None,
               ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]:
    arr = world.arrays
    mip, mip_off, scale = _packed_atlas()
    circles, circle_z, circle_tex = arr.circles, arr.circle_z, arr.circle_tex
    circle_toff = arr.circle_toff
    if people is not None and len(people):
        n = len(people)
        ph = people_height if people_height is not None else np.full(n, 1.7)
        circles = np.concatenate([circles, np.asarray(people, dtype=np.float64).reshape(-1, 3)])
        circle_z = np.concatenate([circle_z, np.column_stack([np.zeros(n), ph])])
        circle_tex = np.concatenate([circle_tex, np.full(n, TEXTURES.index("person"))])
        circle_toff = np.concatenate([circle_toff, np.zeros(n)])
    rgb = np.empty((intr.height, intr.width, 3) if want_rgb else (1, 1, 3), np.uint8)
    depth = np.empty((intr.height, intr.width), np.float32)  # every pixel gets written
    _cast(cam[0], cam[1], cam[2], cam[3], intr.width, intr.height, intr.fx, intr.fy,
          intr.cx, intr.cy, arr.quads, arr.quad_z, arr.quad_tex, arr.quad_toff, circles,
          circle_z, circle_tex, circle_toff, TEXTURES.index(world.floor_texture),
          TEXTURES.index(world.ceiling_texture),
          world.ceiling_height, mip, mip_off, scale, want_rgb, shading, rgb, depth)
    return rgb, depth


def render_view(
    world: World,
    cam: tuple[float, float, float, float],
    intr: CameraIntrinsics,
    *,
    want_rgb: bool = True,
    shading: bool = True,
    people: npt.NDArray[np.float64] | None = None,
    people_height: npt.NDArray[np.float64] | None = None,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]:
    """Render from a camera at world (x, y, z, yaw): (H, W, 3) uint8 RGB and (H, W) float32
    ideal optical-z depth (m; +Inf where nothing is hit). ``people`` (N, 3) x, y, radius are
    drawn as cylinders from the floor to ``people_height`` (default 1.7 m)."""
    rgb, depth = _cast_into(world, cam, intr, want_rgb, shading, people, people_height)
    return (rgb if want_rgb else np.zeros((0, 0, 3), np.uint8)), depth


@lru_cache(maxsize=1)
def _packed_atlas() -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """All textures as a mip chain of packed 0x00BBGGRR texels, column-major per tile, in
    one flat array; offsets of each level; tile sizes (m)."""
    atlas, scale = texture_atlas()
    levels, offsets, off = [], [], 0
    for level in range(_MIP_LEVELS):
        n = _TEX_SIZE >> level
        tiles = atlas if n == atlas.shape[1] else np.stack(
            [cv2.resize(t, (n, n), interpolation=cv2.INTER_AREA) for t in atlas])
        rgba = np.zeros((*tiles.shape[:3], 4), np.uint8)
        rgba[..., :3] = tiles
        packed = np.ascontiguousarray(rgba).view("<u4")[..., 0].transpose(0, 2, 1)
        levels.append(np.ascontiguousarray(packed).reshape(-1))
        offsets.append(off)
        off += levels[-1].size
    return np.concatenate(levels), np.array(offsets, dtype=np.int64), scale


@dataclass(frozen=True)
class KinectFrame:
    """One simulated Kinect frame: rgb8 (H, W, 3) from camera_rgb_frame and 16UC1 depth
    (H, W) mm from camera_depth_frame (unregistered, as the real sensor)."""

    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]


class Renderer:
    """Renders Kinect frames of one world with one `KinectConfig`."""

    def __init__(self, world: World, config: KinectConfig | None = None):
        self.world = world
        self.config = config or KinectConfig()

    def _people(self, people: npt.NDArray[np.float64] | None) -> npt.NDArray[np.float64] | None:
        if people is None or not len(people):
            return None
        known = [p.height for p in self.world.people][: len(people)]
        return np.array(known + [1.7] * (len(people) - len(known)))

    def rgb(self, robot_pose: npt.ArrayLike, people: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.uint8]:
        """rgb8 (H, W, 3) from camera_rgb_frame for a robot pose (x, y, theta)."""
        cam = camera_pose(robot_pose, self.config.rgb_position)
        return render_view(self.world, cam, self.config.rgb, shading=self.config.shading,
                           people=people, people_height=self._people(people))[0]

    def ideal_depth(self, robot_pose: npt.ArrayLike, people: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float32]:
        """Noise-free optical-z depth (H, W) float32 m from camera_depth_frame."""
        cam = camera_pose(robot_pose, self.config.depth_position)
        return render_view(self.world, cam, self.config.depth, want_rgb=False, people=people,
                           people_height=self._people(people))[1]

    def depth(self, robot_pose: npt.ArrayLike, frame_index: int = 0,
              people: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.uint16]:
        """16UC1 (H, W) mm with Kinect v1 behaviour; deterministic in (seed, frame_index)."""
        cam = camera_pose(robot_pose, self.config.depth_position)
        ideal = _cast_into(self.world, cam, self.config.depth, False, False, people,
                           self._people(people))[1]
        return kinect_depth(ideal, self.config, frame_index)

    def frame(self, robot_pose: npt.ArrayLike, frame_index: int = 0,
              people: npt.NDArray[np.float64] | None = None) -> KinectFrame:
        """Both streams for a robot pose (x, y, theta) in the world frame."""
        return KinectFrame(self.rgb(robot_pose, people), self.depth(robot_pose, frame_index, people))
