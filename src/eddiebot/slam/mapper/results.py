"""What `SlamCore` returns: the outcome of one scan, its warnings, and the record of a node."""


from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.slam.scan import Scan

FloatArray = npt.NDArray[np.float64]


class ProcessStatus(str, enum.Enum):
    """What happened to a scan."""

    ADDED = "added"
    """Became a new graph node (mapping, lifelong)."""
    LOCALIZED = "localized"
    """Matched against the loaded graph (localization)."""
    NOT_MOVED = "not_moved"
    """Skipped: the robot has not moved enough since the last processed scan."""
    SKIPPED = "skipped"
    """Skipped: bad input (see the warnings)."""
    LOST = "lost"
    """Localization: global relocalisation found no pose passing the loop-closure thresholds
    (the odometry pose is kept when there was one)."""


@dataclass(frozen=True)
class SlamWarning:
    """A warning raised while processing; ``kind`` is a stable machine-readable tag."""

    kind: str
    message: str
    stamp_ns: int = 0


@dataclass(frozen=True)
class ProcessResult:
    """Outcome of `SlamCore.process`.

    ``pose``: robot (base) pose in the map frame for this scan (None when skipped);
    ``map_to_odom``: correction to publish (map frame ← odom frame, x, y, theta).
    """

    status: ProcessStatus
    map_to_odom: FloatArray
    pose: FloatArray | None = None
    node_id: int | None = None
    response: float = 0.0
    covariance: FloatArray | None = None
    loop_closed: bool = False
    warnings: tuple[SlamWarning, ...] = ()

    @property
    def processed(self) -> bool:
        """True when the scan was used (a node was added or the robot was localised)."""
        return self.status in (ProcessStatus.ADDED, ProcessStatus.LOCALIZED)


@dataclass
class NodeRecord:
    """A graph node's scan and bookkeeping (its pose lives in the `PoseGraph`)."""

    scan: Scan
    points: FloatArray
    """Valid end points in the sensor frame (M, 2), m."""
    odom_pose: FloatArray
    """Robot pose in the odom frame when the scan was taken."""
    retired: bool = False
