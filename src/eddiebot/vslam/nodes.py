"""Graph nodes and links as RTAB-Map keeps them: link types (database values), `Link`, a
node's heavy `NodeData` (features, words, grid, cloud) and the `NodeStore` that holds it in
long-term memory."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import IntEnum
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.occupancy import CloudImages, LocalGrid

__all__ = ["ODOMETRY_LINK_TYPES", "Link", "LinkType", "Node", "NodeData", "NodeStore"]

F64 = NDArray[np.float64]


class LinkType(IntEnum):
    """RTAB-Map link types (database values)."""

    NEIGHBOR = 0
    GLOBAL_CLOSURE = 1
    LOCAL_SPACE_CLOSURE = 2
    LOCAL_TIME_CLOSURE = 3
    USER_CLOSURE = 4
    VIRTUAL_CLOSURE = 5
    NEIGHBOR_MERGED = 6
    POSE_PRIOR = 7
    LANDMARK = 8


#: Odometry links (the only ones that add depth in the Bayes prediction's neighbour search).
ODOMETRY_LINK_TYPES = frozenset((LinkType.NEIGHBOR, LinkType.NEIGHBOR_MERGED))


@dataclass(frozen=True)
class Link:
    """Pose of `to_id` in the base frame of `from_id` (4×4, m) with a 6×6 information matrix."""

    from_id: int
    to_id: int
    type: LinkType
    transform: F64
    information: F64

    @property
    def switchable(self) -> bool:
        """A loop closure (any link but odometry's), which `Optimizer/Robust` may switch off."""
        return self.type not in ODOMETRY_LINK_TYPES

    def inverse(self) -> Link:
        """The same constraint seen from the other end."""
        from eddiebot.vslam.transforms import se3_inverse

        return Link(self.to_id, self.from_id, self.type, se3_inverse(self.transform),
                    self.information)


class NodeData:
    """The heavy part of a node: features, their word ids, local grid, and the decimated,
    compressed images its cloud is rebuilt from on demand.

    The features' 3D points are kept in float32, as RTAB-Map's signature keeps its
    ``cv::Point3f`` words (12 B a feature instead of 24: ≈ 11 kB a node of 900 features;
    rounding under 0.3 µm within 4 m); `features` hands them out as float64."""

    __slots__ = ("_features", "_points", "cloud", "grid", "scan_points", "words")

    def __init__(self, features: FrameFeatures, words: NDArray[np.int64],
                 grid: LocalGrid | None = None, cloud: CloudImages | None = None,
                 scan_points: F64 | None = None) -> None:
        self._points: NDArray[np.float32] = np.ascontiguousarray(features.points, np.float32)
        self._features = replace(features, points=np.zeros((0, 3)))
        self.words = words  # word id per feature, -1 = not quantised
        self.grid = grid
        self.cloud = cloud
        self.scan_points = scan_points  # (N, 2) base frame, for neighbour-link refinement

    @property
    def features(self) -> FrameFeatures:
        """The node's features (a new object; the points as float64)."""
        return replace(self._features, points=self._points.astype(np.float64))

    @property
    def nbytes(self) -> int:
        """RAM held by the arrays and images (not Python object overhead)."""
        f = self._features
        n = sum(a.nbytes for a in (f.uv, f.responses, f.sizes, f.angles, f.octaves,
                                   f.descriptors, self._points)) + self.words.nbytes
        if self.grid is not None:
            n += sum(a.nbytes for a in (self.grid.ground, self.grid.obstacles, self.grid.empty))
        if self.cloud is not None:
            n += self.cloud.nbytes
        if self.scan_points is not None:
            n += self.scan_points.nbytes
        return n

    def word_counts(self) -> dict[int, int]:
        """Word id → occurrences (valid words only)."""
        w = self.words[self.words > 0]
        ids, counts = np.unique(w, return_counts=True)
        return {int(i): int(c) for i, c in zip(ids, counts)}


@dataclass
class Node:
    """A graph node; `odom_pose` is the base pose in the odometry frame (4×4)."""

    id: int
    map_id: int
    stamp_ns: int
    odom_pose: F64
    weight: int = 0
    data: NodeData | None = None
    label: str = ""
    word_counts: dict[int, int] = field(default_factory=dict)


class NodeStore(Protocol):
    """Where LTM node data lives (the session database)."""

    def load_node_data(self, node_id: int) -> NodeData | None:
        """The node's features, words and grid, or None if unknown."""
        ...


