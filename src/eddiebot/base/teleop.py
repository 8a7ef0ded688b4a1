"""Keyboard teleoperation with teleop_twist_keyboard's keys (pure key → command logic).

```
   u    i    o          q/z : all speeds ±10 %
   j    k    l          w/x : linear speed ±10 %
   m    ,    .          e/c : angular speed ±10 %
k or space: stop        Ctrl-C: quit (sends a zero command)
```
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MOVE_BINDINGS", "SPEED_BINDINGS", "USAGE", "TeleopState"]

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
k or space : stop
CTRL-C to quit (the robot is stopped)
"""


@dataclass
class TeleopState:
    """Current speeds and direction; ``key()`` applies one key press."""

    speed: float = 0.5
    turn: float = 1.0
    x: int = 0
    th: int = 0
    max_speed: float = 1.2
    max_turn: float = 4.0

    def key(self, k: str) -> bool:
        """Apply a key; True if it was a known key."""
        if k in MOVE_BINDINGS:
            self.x, self.th = MOVE_BINDINGS[k]
            return True
        if k in SPEED_BINDINGS:
            fs, ft = SPEED_BINDINGS[k]
            self.speed = min(self.max_speed, self.speed * fs)
            self.turn = min(self.max_turn, self.turn * ft)
            return True
        if k in STOP_KEYS:
            self.x = self.th = 0
            return True
        return False

    def command(self) -> tuple[float, float]:
        """(linear m/s, angular rad/s) to publish now."""
        return self.x * self.speed, self.th * self.turn
