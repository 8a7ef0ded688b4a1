"""What `Rtabmap` hands out and stores: the result of one `Rtabmap.process` call, the record of
a frame written to the map database, and that database's protocol."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.memory import Link, Node, NodeData
from eddiebot.vslam.occupancy import Scan2D

if TYPE_CHECKING:
    from eddiebot.vslam.rtabmap import Rtabmap

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ProcessResult:
    """Outcome of one `Rtabmap.process` call.

    `map_to_odom`: correction (4×4) to publish as map→odom; `pose`: base pose in the map frame
    (None if the frame was rejected); ids are 0 when absent.
    """

    node_id: int
    added: bool
    map_to_odom: F64
    pose: F64 | None
    loop_closure_id: int = 0
    proximity_id: int = 0
    hypothesis_id: int = 0
    hypothesis_value: float = 0.0
    rejected_loop_id: int = 0
    rejection_reason: str = ""
    localized: bool = False
    statistics: dict[str, float] = field(default_factory=dict)
    #: the registered transform (new node → old node, 4×4) of a hypothesis that passed the
    #: registration but was rejected after it (gate or `RGBD/OptimizeMaxError`), else None
    rejected_transform: F64 | None = None
    #: the frame's map (a new one after an odometry reset), whether this frame started it,
    #: and whether an accepted closure joined two maps
    map_id: int = 0
    new_map: bool = False
    maps_merged: bool = False


class _Verification(NamedTuple):
    """What `Rtabmap._verify` found for one candidate place."""

    link: Link | None  # the closure, None when rejected
    reason: str  # why it was rejected
    registered: Link | None = None  # the registered link, also when rejected after registration
    mahalanobis: float = float("nan")  # its distance from the graph's prediction (σ), if gated


@dataclass(frozen=True)
class FrameRecord:
    """Everything written to the database for one kept node (one transaction)."""

    node: Node
    image: NDArray[np.uint8] | None
    depth: NDArray[np.generic] | None
    camera: CameraIntrinsics
    scan: Scan2D | None
    links: tuple[Link, ...]
    word_ids: NDArray[np.int64]  # unique word ids the node uses
    word_descriptors: NDArray[np.uint8]  # their descriptors (N, 32)
    statistics: dict[str, float]
    #: (id, weight) of earlier nodes whose weight changed since the last record
    weights: tuple[tuple[int, int], ...] = ()




class MapDatabase(Protocol):
    """What the core needs from a session database (see `SessionDatabase`)."""

    def load_into(self, rtabmap: Rtabmap) -> None:
        """Fill a fresh core with the stored map."""
        ...

    def write_frame(self, record: FrameRecord) -> None:
        """Persist one kept node, atomically."""
        ...

    def load_node_data(self, node_id: int) -> NodeData | None:
        """Heavy data of an LTM node."""
        ...

    def frame(self, node_id: int) -> tuple[NDArray[np.uint8] | None, NDArray[np.uint16] | None,
                                           CameraIntrinsics | None]:
        """The stored RGB image, depth (mm) and camera of a node."""
        ...
