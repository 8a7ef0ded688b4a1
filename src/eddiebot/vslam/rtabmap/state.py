"""The state the parts of `Rtabmap` share: declared here once, set in `Rtabmap.__init__`."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.bayes import BayesFilter
from eddiebot.vslam.depth_icp import IcpSettings
from eddiebot.vslam.graph import PoseGraphOptimizer
from eddiebot.vslam.localization import OdometryCache
from eddiebot.vslam.memory import Memory
from eddiebot.vslam.odometry_frames import OdometryFrames
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.records import MapDatabase
from eddiebot.vslam.vocabulary import Vocabulary

__all__ = ["F64", "RtabmapState"]

F64 = NDArray[np.float64]


class RtabmapState:
    """Attributes of the SLAM core; each part of `Rtabmap` (multi-map, verification,
    proximity, graph update, localization, memory management, outputs) works on these."""

    params: RtabmapParameters
    vocabulary: Vocabulary
    memory: Memory
    bayes: BayesFilter
    optimizer: PoseGraphOptimizer
    #: node id → optimised pose (map frame of the node's map, 4×4)
    optimized_poses: dict[int, F64]
    map_to_odom: F64
    maps_started: int
    #: covariance (6×6) of the last accepted localization, None before one
    localization_covariance: F64 | None
    _timer: Callable[[], float]
    _db: MapDatabase | None
    _icp: IcpSettings
    _next_id: int
    _map_id: int
    _map_frames: dict[int, int]
    _last_node_id: int
    _weights_changed: set[int]
    _localized: bool
    _odom_max_info: F64 | None
    _frame_poses: dict[int, F64]
    _frames: OdometryFrames
    _odom_cache: OdometryCache | None
    _graph_live: bool

    @property
    def localization_mode(self) -> bool:
        """`Mem/IncrementalMemory` false."""
        return not self.params.mem_incremental_memory
