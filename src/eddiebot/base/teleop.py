"""Keyboard teleoperation with teleop_twist_keyboard's keys (pure key → command logic).

```
   u    i    o          q/z : all speeds ±10 %
   j    k    l          w/x : linear speed ±10 %
   m    ,    .          e/c : angular speed ±10 %
anything else: stop     Ctrl-C: quit (sends a zero command)
```

:class:`KeyTeleop` says what to publish when, as ROS 1 teleop_twist_keyboard with its
``key_timeout`` and ``repeat_rate`` parameters: every key event publishes (a held key
publishes at the terminal's key-repeat rate), a key that is not a binding publishes one zero
command, and once no key has arrived for ``key_timeout`` (default 0.5 s) one zero command
goes out and then nothing — releasing a key stops the robot within ``key_timeout`` and an
idle teleop never holds the twist mux. Unlike ROS 1, ``repeat_rate`` repeats only a moving
command, never the zero. Time is integer nanoseconds passed in by the caller.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["MOVE_BINDINGS", "SPEED_BINDINGS", "STOP_KEYS", "USAGE", "KeyTeleop", "TeleopState"]

#: key → (x, th) direction, as teleop_twist_keyboard's moveBindings (non-holonomic part)
MOVE_BINDINGS: dict[str, tuple[int, int]] = {
    "i": (1, 0),
    "o": (1, -1),
    "j": (0, 1),
    "l": (0, -1),
    "u": (1, 1),
    ",": (-1, 0),
    ".": (-1, 1),
    "m": (-1, -1),
}
#: key → (linear factor, angular factor), as teleop_twist_keyboard's speedBindings
SPEED_BINDINGS: dict[str, tuple[float, float]] = {
    "q": (1.1, 1.1),
    "z": (0.9, 0.9),
    "w": (1.1, 1.0),
    "x": (0.9, 1.0),
    "e": (1.0, 1.1),
    "c": (1.0, 0.9),
}
#: the keys the usage names for stopping; any other non-binding key stops as well
STOP_KEYS = {"k", " "}

USAGE = """Reading from the keyboard and publishing Twist on {topic}.
---------------------------
Moving around:
   u    i    o
   j    k    l
   m    ,    .

q/z : increase/decrease max speeds by 10%
w/x : increase/decrease only linear speed by 10%
e/c : increase/decrease only angular speed by 10%
k, space or anything else : stop
CTRL-C to quit (the robot is stopped)
"""

_ZERO = (0.0, 0.0)


@dataclass
class TeleopState:
    """Current speeds (m/s, rad/s) and direction; ``key()`` applies one key press."""

    speed: float = 0.5
    turn: float = 1.0
    x: int = 0
    th: int = 0
    max_speed: float = 1.2
    max_turn: float = 4.0

    def key(self, k: str) -> bool:
        """Apply a key; True if it is a binding. Any other key stops (teleop_twist_keyboard's
        "anything else: stop")."""
        if k in MOVE_BINDINGS:
            self.x, self.th = MOVE_BINDINGS[k]
            return True
        if k in SPEED_BINDINGS:
            fs, ft = SPEED_BINDINGS[k]
            self.speed = min(self.max_speed, self.speed * fs)
            self.turn = min(self.max_turn, self.turn * ft)
            return True
        self.x = self.th = 0
        return False

    def command(self) -> tuple[float, float]:
        """(linear m/s, angular rad/s) for the current keys."""
        return self.x * self.speed, self.th * self.turn


@dataclass
class KeyTeleop:
    """What to publish, as a function of key events and time (ns).

    ``on_key`` for every key read (always publishes), ``on_idle`` whenever the caller wakes
    without a key (publishes the repeat or the one timeout zero, else nothing),
    ``next_wakeup_ns`` for how long the caller may wait for a key. ``key_timeout`` ≤ 0
    never times out; ``repeat_rate`` 0 publishes on key events only.
    """

    state: TeleopState = field(default_factory=TeleopState)
    key_timeout: float = 0.5
    """s without a key after which the robot is stopped (ROS 1 ``key_timeout``)."""
    repeat_rate: float = 0.0
    """Hz at which a moving command is repeated between keys (ROS 1 ``repeat_rate``)."""
    last_key_ns: int | None = None
    last_publish_ns: int | None = None
    last_published: tuple[float, float] | None = None

    @property
    def _timeout_ns(self) -> int:
        return round(self.key_timeout * 1e9) if self.key_timeout > 0 else 0

    @property
    def _repeat_ns(self) -> int:
        return round(1e9 / self.repeat_rate) if self.repeat_rate > 0 else 0

    def _publish(self, cmd: tuple[float, float], now_ns: int) -> tuple[float, float]:
        self.last_publish_ns, self.last_published = now_ns, cmd
        return cmd

    def on_key(self, key: str, now_ns: int) -> tuple[float, float]:
        """Apply ``key`` at ``now_ns``; the (linear, angular) to publish now."""
        self.state.key(key)
        self.last_key_ns = now_ns
        return self._publish(self.state.command(), now_ns)

    def on_idle(self, now_ns: int) -> tuple[float, float] | None:
        """The (linear, angular) to publish at ``now_ns`` when no key came, or None."""
        if self.last_key_ns is None:
            return None
        timeout, repeat = self._timeout_ns, self._repeat_ns
        if timeout and now_ns - self.last_key_ns >= timeout:
            self.state.x = self.state.th = 0
            if self.last_published not in (None, _ZERO):
                return self._publish(_ZERO, now_ns)
            return None
        cmd = self.state.command()
        if (repeat and cmd != _ZERO and self.last_publish_ns is not None
                and now_ns - self.last_publish_ns >= repeat):
            return self._publish(cmd, now_ns)
        return None

    def next_wakeup_ns(self) -> int | None:
        """When ``on_idle`` may next publish (ns); None: nothing happens until a key."""
        if self.last_key_ns is None:
            return None
        times = []
        if self._timeout_ns and self.last_published not in (None, _ZERO):
            times.append(self.last_key_ns + self._timeout_ns)
        if self._repeat_ns and self.state.command() != _ZERO and self.last_publish_ns is not None:
            times.append(self.last_publish_ns + self._repeat_ns)
        return min(times, default=None)
