"""Procedural, deterministic surface textures.

Every texture is a 256×256 RGB tile generated from its name alone (seeded by a CRC of the
name), so a world looks the same on every machine and every run. ``TEXTURE_SIZES`` gives the
tile's size on the surface in metres. Most textures carry corners and blobs so that feature
detectors (ORB, GFTT) find something to track; ``plain`` is nearly uniform on purpose, for
low-feature scenes such as the ``corridor`` world.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from functools import cache

import cv2
import numpy as np
import numpy.typing as npt

__all__ = ["TEXTURES", "TEXTURE_SIZES", "texture", "texture_atlas"]

N = 256
_Tex = npt.NDArray[np.uint8]


def _rng(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def _smooth_noise(rng: np.random.Generator, cells: int, amp: float) -> npt.NDArray[np.float32]:
    small = rng.standard_normal((cells, cells)).astype(np.float32)
    small = np.pad(small, 2, mode="wrap")
    big = cv2.resize(small, (N + 4 * N // cells, N + 4 * N // cells), interpolation=cv2.INTER_CUBIC)
    off = 2 * N // cells
    return big[off : off + N, off : off + N] * np.float32(amp)


def _base(color: tuple[int, int, int]) -> npt.NDArray[np.float32]:
    return np.broadcast_to(np.array(color, np.float32), (N, N, 3)).copy()


def _finish(img: npt.NDArray[np.float32]) -> _Tex:
    return np.clip(img, 0, 255).astype(np.uint8)


def _speckle(rng: np.random.Generator, img: npt.NDArray[np.float32], amp: float) -> None:
    img += rng.standard_normal((N, N, 1)).astype(np.float32) * np.float32(amp)


def _plaster(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((205, 200, 188))
    img += _smooth_noise(rng, 8, 10.0)[..., None]
    # posters, notices and frames: rectangles with inner detail give corners to track
    for _ in range(5):
        w, h = int(rng.integers(25, 80)), int(rng.integers(30, 90))
        x, y = rng.integers(0, N - w), rng.integers(60, N - h - 40)
        col = rng.integers(30, 230, 3).astype(np.float32)
        img[y : y + h, x : x + w] = col
        for _ in range(rng.integers(3, 9)):
            sw, sh = int(rng.integers(4, max(5, w // 2))), int(rng.integers(3, max(4, h // 3)))
            sx, sy = x + rng.integers(0, w - sw), y + rng.integers(0, h - sh)
            img[sy : sy + sh, sx : sx + sw] = rng.integers(0, 255, 3).astype(np.float32)
    _speckle(rng, img, 3.0)
    return _finish(img)


def _plain(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((196, 196, 190))
    img += _smooth_noise(rng, 4, 2.0)[..., None]
    img[N - 12 :, :] = (150, 150, 150)  # skirting board
    return _finish(img)


def _brick(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((200, 195, 185))  # mortar
    bh, bw = 16, 48
    for r in range(N // bh):
        shift = (bw // 2) * (r % 2)
        for c in range(-1, N // bw + 1):
            x0, y0 = c * bw + shift + 2, r * bh + 2
            col = np.array([150, 70, 50], np.float32) + rng.normal(0, 18, 3).astype(np.float32)
            xa, xb = max(x0, 0), min(x0 + bw - 4, N)
            if xb > xa:
                img[y0 : y0 + bh - 4, xa:xb] = col
    _speckle(rng, img, 6.0)
    return _finish(img)


def _wood(name: str) -> _Tex:
    rng = _rng(name)
    y = np.arange(N, dtype=np.float32)[:, None]
    grain = np.sin(y * 0.35 + _smooth_noise(rng, 6, 3.0)) * 14
    img = _base((150, 105, 60)) + grain[..., None]
    for _ in range(6):  # knots
        cx, cy, r = rng.integers(0, N), rng.integers(0, N), int(rng.integers(3, 8))
        cv2.circle(img, (int(cx), int(cy)), r, (90.0, 55.0, 30.0), -1)
    for x in range(0, N, 64):  # plank joints
        img[:, x : x + 2] = (70, 45, 25)
    return _finish(img)


def _concrete(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((150, 150, 148)) + _smooth_noise(rng, 16, 14.0)[..., None]
    for _ in range(40):
        cx, cy = rng.integers(0, N, 2)
        cv2.circle(img, (int(cx), int(cy)), int(rng.integers(1, 4)), (95.0, 95.0, 95.0), -1)
    _speckle(rng, img, 6.0)
    return _finish(img)


def _carpet(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((95, 100, 120)) + _smooth_noise(rng, 32, 12.0)[..., None]
    _speckle(rng, img, 14.0)
    return _finish(img)


def _tiles(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((215, 210, 200))
    t = 64
    for r in range(N // t):
        for c in range(N // t):
            shade = rng.normal(0, 10)
            img[r * t + 2 : (r + 1) * t - 2, c * t + 2 : (c + 1) * t - 2] += np.float32(shade)
            if rng.random() < 0.3:
                cx, cy = c * t + rng.integers(8, t - 8), r * t + rng.integers(8, t - 8)
                cv2.circle(img, (int(cx), int(cy)), 3, (120.0, 115.0, 105.0), -1)
    img[::t, :] = img[:, ::t] = 120
    _speckle(rng, img, 4.0)
    return _finish(img)


def _metal(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((165, 170, 175))
    streaks = rng.normal(0, 8, (1, N)).astype(np.float32)
    img += np.repeat(streaks, N, axis=0)[..., None]
    for x in range(0, N, 64):
        for y in range(16, N, 64):
            cv2.circle(img, (x + 8, y), 3, (80.0, 80.0, 85.0), -1)  # rivets
    _speckle(rng, img, 3.0)
    return _finish(img)


def _shelf(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((60, 60, 70))
    level = N // 4
    for lv in range(4):
        y1 = (lv + 1) * level - 6
        x = 4
        while x < N - 10:
            w = int(rng.integers(18, 50))
            h = int(rng.integers(20, level - 10))
            col = rng.choice([[180, 140, 90], [200, 170, 120], [90, 120, 170], [170, 60, 50],
                              [220, 220, 210]]).astype(np.float32)
            img[y1 - h : y1, x : min(x + w, N - 4)] = col + rng.normal(0, 10, 3).astype(np.float32)
            if rng.random() < 0.6:  # labels
                lx, ly = x + 4, y1 - h + 4
                img[ly : ly + 6, lx : min(lx + 12, N - 4)] = (250, 250, 250)
            x += w + int(rng.integers(2, 8))
        img[y1 : y1 + 6, :] = (200, 120, 30)  # orange beam
    img[:, :4] = img[:, -4:] = (40, 80, 160)  # uprights
    _speckle(rng, img, 4.0)
    return _finish(img)


def _door(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((135, 95, 60)) + _smooth_noise(rng, 8, 6.0)[..., None]
    for y0, y1 in ((20, 110), (140, 236)):
        cv2.rectangle(img, (30, y0), (N - 30, y1), (100.0, 68.0, 40.0), 3)
    cv2.circle(img, (N - 40, 128), 6, (210.0, 200.0, 120.0), -1)
    return _finish(img)


def _person(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((40, 60, 120))
    img[: N // 5] = (200, 160, 130)  # head
    img[N // 5 : N // 2] = (170, 40, 40)  # shirt
    for _ in range(12):
        x, y = rng.integers(0, N - 20), rng.integers(N // 5, N // 2)
        img[y : y + 10, x : x + 20] = (230, 230, 230)
    _speckle(rng, img, 5.0)
    return _finish(img)


def _ceiling(name: str) -> _Tex:
    rng = _rng(name)
    img = _base((225, 225, 220)) + _smooth_noise(rng, 16, 4.0)[..., None]
    img[::128, :] = img[:, ::128] = 160
    for y in (64,):
        for x in (32, 160):
            img[y - 10 : y + 10, x : x + 64] = (255, 255, 245)  # light panels
    return _finish(img)


_GENERATORS: dict[str, tuple[Callable[[str], _Tex], float]] = {
    "plaster": (_plaster, 2.5),
    "plain": (_plain, 2.0),
    "brick": (_brick, 1.5),
    "wood": (_wood, 1.0),
    "concrete": (_concrete, 2.0),
    "carpet": (_carpet, 1.5),
    "tiles": (_tiles, 1.2),
    "metal": (_metal, 1.0),
    "shelf": (_shelf, 2.0),
    "door": (_door, 2.0),
    "person": (_person, 1.8),
    "ceiling": (_ceiling, 2.4),
}
TEXTURES: tuple[str, ...] = tuple(_GENERATORS)
TEXTURE_SIZES: dict[str, float] = {k: v[1] for k, v in _GENERATORS.items()}


@cache
def texture(name: str) -> _Tex:
    """The (256, 256, 3) uint8 tile of ``name``; on walls row 0 is the top of the tile."""
    gen = _GENERATORS[name][0]
    img = gen(name)
    img.setflags(write=False)
    return img


@cache
def texture_atlas() -> tuple[_Tex, npt.NDArray[np.float64]]:
    """All textures stacked (T, 256, 256, 3) in `TEXTURES` order, and their tile sizes (m)."""
    atlas = np.stack([texture(n) for n in TEXTURES])
    sizes = np.array([TEXTURE_SIZES[n] for n in TEXTURES], dtype=np.float64)
    atlas.setflags(write=False)
    return atlas, sizes
