"""XXH3-128, the hash rmw_zenoh turns a liveliness key into an entity's 16-byte GID with.

A plain port of the portable scalar path of xxHash's ``XXH3_128bits`` (default secret, no
seed), the same reduced form rmw_zenoh ships as ``simplified_xxhash3.cpp``. GIDs are made
once per entity, so speed does not matter and no extra dependency is needed.
"""

from __future__ import annotations

__all__ = ["xxh3_128"]

_M64 = (1 << 64) - 1

_P32_1 = 0x9E3779B1
_P32_2 = 0x85EBCA77
_P32_3 = 0xC2B2AE3D
_P64_1 = 0x9E3779B185EBCA87
_P64_2 = 0xC2B2AE3D27D4EB4F
_P64_3 = 0x165667B19E3779F9
_P64_4 = 0x85EBCA77C2B2AE63
_P64_5 = 0x27D4EB2F165667C5
_PRIME_MX1 = 0x165667919E3779F9
_PRIME_MX2 = 0x9FB21C651E98DF25

_SECRET = bytes.fromhex(
    "b8fe6c3923a44bbe7c01812cf721ad1cded46de9839097db7240a4a4b7b3671f"
    "cb79e64eccc0e578825ad07dccff7221b8084674f743248ee03590e6813a264c"
    "3c2852bb91c300cb88d0658b1b532ea371644897a20df94e3819ef46a9deacd8"
    "a8fa763fe39c343ff9dcbbc7c70b4f1d8a51e04bcdb45931c89f7ec9d9787364"
    "eac5ac8334d3ebc3c581a0fffa1363eb170ddd51b7f0da49d316552629d4689e"
    "2b16be587d47a1fc8ff8b8d17ad031ce45cb3a8f95160428afd7fbcabb4b407e"
)
_STRIPE_LEN = 64
_SECRET_CONSUME_RATE = 8
_ACC_NB = 8
_SECRET_SIZE_MIN = 136
_MIDSIZE_STARTOFFSET = 3
_MIDSIZE_LASTOFFSET = 17
_SECRET_LASTACC_START = 7
_SECRET_MERGEACCS_START = 11


def _r64(b: bytes, i: int) -> int:
    return int.from_bytes(b[i:i + 8], "little")


def _r32(b: bytes, i: int) -> int:
    return int.from_bytes(b[i:i + 4], "little")


def _mul128(a: int, b: int) -> tuple[int, int]:
    """(low64, high64) of the 128-bit product."""
    p = a * b
    return p & _M64, (p >> 64) & _M64


def _fold64(a: int, b: int) -> int:
    lo, hi = _mul128(a, b)
    return lo ^ hi


def _avalanche(h: int) -> int:
    h ^= h >> 37
    h = (h * _PRIME_MX1) & _M64
    return h ^ (h >> 32)


def _xxh64_avalanche(h: int) -> int:
    h ^= h >> 33
    h = (h * _P64_2) & _M64
    h ^= h >> 29
    h = (h * _P64_3) & _M64
    return h ^ (h >> 32)


def _swap64(x: int) -> int:
    return int.from_bytes(x.to_bytes(8, "little"), "big")


def _swap32(x: int) -> int:
    return int.from_bytes(x.to_bytes(4, "little"), "big")


def _len_1to3(data: bytes) -> tuple[int, int]:
    n = len(data)
    c1, c2, c3 = data[0], data[n >> 1], data[n - 1]
    combined_l = (c1 << 16) | (c2 << 24) | c3 | (n << 8)
    s = _swap32(combined_l)
    combined_h = ((s << 13) | (s >> 19)) & 0xFFFFFFFF
    bitflip_l = _r32(_SECRET, 0) ^ _r32(_SECRET, 4)
    bitflip_h = _r32(_SECRET, 8) ^ _r32(_SECRET, 12)
    return _xxh64_avalanche(combined_l ^ bitflip_l), _xxh64_avalanche(combined_h ^ bitflip_h)


def _len_4to8(data: bytes) -> tuple[int, int]:
    n = len(data)
    input64 = _r32(data, 0) + (_r32(data, n - 4) << 32)
    keyed = input64 ^ (_r64(_SECRET, 16) ^ _r64(_SECRET, 24))
    lo, hi = _mul128(keyed, (_P64_1 + (n << 2)) & _M64)
    hi = (hi + (lo << 1)) & _M64
    lo ^= hi >> 3
    lo ^= lo >> 35
    lo = (lo * _PRIME_MX2) & _M64
    lo ^= lo >> 28
    return lo, _avalanche(hi)


def _len_9to16(data: bytes) -> tuple[int, int]:
    n = len(data)
    bitflip_l = _r64(_SECRET, 32) ^ _r64(_SECRET, 40)
    bitflip_h = _r64(_SECRET, 48) ^ _r64(_SECRET, 56)
    input_lo = _r64(data, 0)
    input_hi = _r64(data, n - 8)
    m_lo, m_hi = _mul128(input_lo ^ input_hi ^ bitflip_l, _P64_1)
    m_lo = (m_lo + ((n - 1) << 54)) & _M64
    input_hi ^= bitflip_h
    m_hi = (m_hi + input_hi + (input_hi & 0xFFFFFFFF) * (_P32_2 - 1)) & _M64
    m_lo ^= _swap64(m_hi)
    h_lo, h_hi = _mul128(m_lo, _P64_2)
    h_hi = (h_hi + m_hi * _P64_2) & _M64
    return _avalanche(h_lo), _avalanche(h_hi)


def _mix16(data: bytes, i: int, secret_at: int) -> int:
    return _fold64(_r64(data, i) ^ _r64(_SECRET, secret_at),
                   _r64(data, i + 8) ^ _r64(_SECRET, secret_at + 8))


def _mix32(acc: tuple[int, int], data: bytes, i1: int, i2: int, secret_at: int) -> tuple[int, int]:
    lo, hi = acc
    lo = (lo + _mix16(data, i1, secret_at)) & _M64
    lo ^= (_r64(data, i2) + _r64(data, i2 + 8)) & _M64
    hi = (hi + _mix16(data, i2, secret_at + 16)) & _M64
    hi ^= (_r64(data, i1) + _r64(data, i1 + 8)) & _M64
    return lo, hi


def _finish_mid(acc: tuple[int, int], n: int) -> tuple[int, int]:
    lo, hi = acc
    h_lo = (lo + hi) & _M64
    h_hi = (lo * _P64_1 + hi * _P64_4 + n * _P64_2) & _M64
    return _avalanche(h_lo), (-_avalanche(h_hi)) & _M64


def _len_17to128(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * _P64_1) & _M64, 0)
    if n > 32:
        if n > 64:
            if n > 96:
                acc = _mix32(acc, data, 48, n - 64, 96)
            acc = _mix32(acc, data, 32, n - 48, 64)
        acc = _mix32(acc, data, 16, n - 32, 32)
    acc = _mix32(acc, data, 0, n - 16, 0)
    return _finish_mid(acc, n)


def _len_129to240(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * _P64_1) & _M64, 0)
    for i in range(32, 160, 32):
        acc = _mix32(acc, data, i - 32, i - 16, i - 32)
    acc = (_avalanche(acc[0]), _avalanche(acc[1]))
    for i in range(160, n + 1, 32):
        acc = _mix32(acc, data, i - 32, i - 16, _MIDSIZE_STARTOFFSET + i - 160)
    acc = _mix32(acc, data, n - 16, n - 32, _SECRET_SIZE_MIN - _MIDSIZE_LASTOFFSET - 16)
    return _finish_mid(acc, n)


def _accumulate_512(acc: list[int], data: bytes, at: int, secret_at: int) -> None:
    for lane in range(_ACC_NB):
        value = _r64(data, at + lane * 8)
        key = value ^ _r64(_SECRET, secret_at + lane * 8)
        acc[lane ^ 1] = (acc[lane ^ 1] + value) & _M64
        acc[lane] = (acc[lane] + (key & 0xFFFFFFFF) * (key >> 32)) & _M64


def _scramble(acc: list[int], secret_at: int) -> None:
    for lane in range(_ACC_NB):
        a = acc[lane]
        a ^= a >> 47
        a ^= _r64(_SECRET, secret_at + lane * 8)
        acc[lane] = (a * _P32_1) & _M64


def _merge(acc: list[int], secret_at: int, start: int) -> int:
    result = start
    for i in range(4):
        result = (result + _fold64(acc[2 * i] ^ _r64(_SECRET, secret_at + 16 * i),
                                   acc[2 * i + 1] ^ _r64(_SECRET, secret_at + 16 * i + 8))) & _M64
    return _avalanche(result)


def _long(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = [_P32_3, _P64_1, _P64_2, _P64_3, _P64_4, _P32_2, _P64_5, _P32_1]
    stripes_per_block = (len(_SECRET) - _STRIPE_LEN) // _SECRET_CONSUME_RATE
    block_len = _STRIPE_LEN * stripes_per_block
    nb_blocks = (n - 1) // block_len
    for b in range(nb_blocks):
        for s in range(stripes_per_block):
            _accumulate_512(acc, data, b * block_len + s * _STRIPE_LEN, s * _SECRET_CONSUME_RATE)
        _scramble(acc, len(_SECRET) - _STRIPE_LEN)
    nb_stripes = ((n - 1) - block_len * nb_blocks) // _STRIPE_LEN
    for s in range(nb_stripes):
        _accumulate_512(acc, data, nb_blocks * block_len + s * _STRIPE_LEN,
                        s * _SECRET_CONSUME_RATE)
    _accumulate_512(acc, data, n - _STRIPE_LEN,
                    len(_SECRET) - _STRIPE_LEN - _SECRET_LASTACC_START)
    low = _merge(acc, _SECRET_MERGEACCS_START, (n * _P64_1) & _M64)
    high = _merge(acc, len(_SECRET) - 64 - _SECRET_MERGEACCS_START, ~(n * _P64_2) & _M64)
    return low, high


def xxh3_128(data: bytes) -> tuple[int, int]:
    """XXH3-128 of ``data`` (default secret, seed 0) as (low64, high64)."""
    n = len(data)
    if n == 0:
        bitflip_l = _r64(_SECRET, 64) ^ _r64(_SECRET, 72)
        bitflip_h = _r64(_SECRET, 80) ^ _r64(_SECRET, 88)
        return _xxh64_avalanche(bitflip_l), _xxh64_avalanche(bitflip_h)
    if n <= 3:
        return _len_1to3(data)
    if n <= 8:
        return _len_4to8(data)
    if n <= 16:
        return _len_9to16(data)
    if n <= 128:
        return _len_17to128(data)
    if n <= 240:
        return _len_129to240(data)
    return _long(data)
