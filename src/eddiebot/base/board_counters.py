"""The board's wheel counters as continuous joint counts (pure: no bus, no clock).

DIST returns the firmware's position counters, which restart at zero when the Propeller
reboots (DTR on port open, a brown-out). ``WheelCounters`` turns the DIST samples into joint
counts that continue across reconnects, reboots and ``reset_encoder``, spots a reboot from
the counters alone, and keeps the last 0.5 s of samples for SPD's average speed.
"""

from __future__ import annotations

__all__ = ["SPD_AVERAGE_S", "WheelCounters"]

#: The firmware's SPD is the speed averaged over this span (s).
SPD_AVERAGE_S = 0.5


class WheelCounters:
    """Joint counts (positions) of the two wheels from DIST samples.

    ``joint`` continues across counter restarts: after start, a reconnect or a reboot
    (``rebase``), the next sample continues from where the joints were (what moved during
    the gap is lost). ``encoder_zero`` is where ``reset_encoder`` put the zero of
    ``/eddie/encoders_data``; ``history`` holds (t_ns, left, right) over the last
    ``SPD_AVERAGE_S``.
    """

    def __init__(self, max_wheel_speed: float) -> None:
        #: fastest the wheels can turn (positions/s): bounds a plausible change between samples
        self.max_wheel_speed = max_wheel_speed
        self.raw: tuple[int, int] | None = None  # last DIST counters as read
        self.offset = [0, 0]  # joint counts = raw + offset
        self.joint = [0, 0]
        self.encoder_zero = [0, 0]
        #: the next sample sets the offset (after start, a reconnect or a reboot)
        self.rebase = True
        self.history: list[tuple[int, int, int]] = []

    def restarted(self, stamp_ns: int, raw: tuple[int, int], silent_since_ns: int | None) -> bool:
        """Whether ``raw`` (read at ``stamp_ns``) means the counters restarted: they jumped
        farther than the wheels could go, or, after a silence that began at
        ``silent_since_ns``, fell back near zero."""
        last = self.raw
        if self.rebase or last is None or not self.history:
            return False
        dt = (stamp_ns - self.history[-1][0]) / 1e9
        reach = 1.5 * self.max_wheel_speed * dt + 5  # farthest the wheels could go
        jumped = max(abs(raw[0] - last[0]), abs(raw[1] - last[1])) > reach
        near_zero = silent_since_ns is not None and all(
            abs(r) <= 1.5 * self.max_wheel_speed * (stamp_ns - silent_since_ns) / 1e9 + 5
            and abs(r) + 10 < abs(v) for r, v in zip(raw, last))
        return jumped or near_zero

    def update(self, stamp_ns: int, raw: tuple[int, int]) -> tuple[int, int]:
        """Take a DIST sample read at ``stamp_ns``; the joint counts (left, right)."""
        if self.rebase or self.raw is None:
            self.offset = [self.joint[0] - raw[0], self.joint[1] - raw[1]]
            self.rebase = False
        self.raw = raw
        left = raw[0] + self.offset[0]
        right = raw[1] + self.offset[1]
        self.joint = [left, right]
        history = self.history
        history.append((stamp_ns, left, right))
        while len(history) > 2 and stamp_ns - history[1][0] >= SPD_AVERAGE_S * 1e9:
            history.pop(0)
        return left, right

    def reset_zero(self) -> None:
        """``reset_encoder``: ``since_zero`` restarts at 0; the joint counts go on."""
        self.encoder_zero = list(self.joint)

    def since_zero(self) -> tuple[int, int]:
        """Counts since the last ``reset_encoder`` (``/eddie/encoders_data``, GetDistance)."""
        return self.joint[0] - self.encoder_zero[0], self.joint[1] - self.encoder_zero[1]

    def average_speed(self) -> tuple[int, int] | None:
        """SPD's meaning: positions/s over the last 0.5 s of samples (None: too few)."""
        h = self.history
        if len(h) >= 2 and h[-1][0] > h[0][0]:
            dt = (h[-1][0] - h[0][0]) / 1e9
            return round((h[-1][1] - h[0][1]) / dt), round((h[-1][2] - h[0][2]) / dt)
        return None
