"""Where every input frame of a run is in the graph: its key frame and the odometry since.

A replay (TUM folder or rosbag2) writes a pose for every input frame, not only for the key
frames the core kept: the optimised pose of the frame's key frame (the latest node added up to
it) composed with the odometry between the two, as RTAB-Map's ``map → odom`` correction places
the robot between nodes. A frame without odometry (lost, no transform, rejected input) is
counted as lost and keeps the last frame's pose; frames before the first key frame have none.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.records import ProcessResult
from eddiebot.vslam.transforms import se3_inverse

__all__ = ["FrameTrack"]

F64 = NDArray[np.float64]


@dataclass
class FrameTrack:
    """Per input frame (stamp, odometry as the core uses it, or None when lost), the key
    frames, and what the core found. Frames may be recorded out of stamp order (a node sees
    the odometry of a throttled frame after it processed a later one): a frame's key frame is
    the latest key frame at or before its stamp.

    `loop_closures` counts appearance (global) loop closures, `proximity_links`
    proximity-by-space links, `rejected_hypotheses` loop hypotheses that failed registration
    or `RGBD/OptimizeMaxError`, `map_merges` closures that joined two maps, `new_maps` frames
    that started a map after an odometry reset.
    """

    records: list[tuple[float, F64 | None]] = field(default_factory=list)
    key_stamps: dict[int, float] = field(default_factory=dict)
    key_odom: dict[int, F64] = field(default_factory=dict)
    lost: int = 0
    loop_closures: int = 0
    proximity_links: int = 0
    rejected_hypotheses: int = 0
    map_merges: int = 0
    new_maps: int = 0

    @property
    def frames(self) -> int:
        return len(self.records)

    @property
    def has_key_frame(self) -> bool:
        return bool(self.key_stamps)

    def tracked(self, stamp: float, result: ProcessResult, odom: F64) -> None:
        """A frame the core processed with odometry `odom` (as the core uses it: 3-DoF when
        ``Reg/Force3DoF``); a rejected one (no pose) counts as lost."""
        if result.pose is None:
            self.lost_frame(stamp)
            return
        if result.added:
            self.key_odom[result.node_id] = np.asarray(odom, np.float64)
            self.key_stamps[result.node_id] = stamp
        self.skipped(stamp, odom)
        self.loop_closures += bool(result.loop_closure_id)
        self.proximity_links += bool(result.proximity_id)
        self.rejected_hypotheses += bool(result.rejected_loop_id)
        self.map_merges += bool(result.maps_merged)
        self.new_maps += bool(result.new_map)

    def skipped(self, stamp: float, odom: F64) -> None:
        """A frame with odometry the core did not process (``Rtabmap/DetectionRate``)."""
        self.records.append((stamp, np.asarray(odom, np.float64)))

    def lost_frame(self, stamp: float) -> None:
        """A frame without odometry: counted, keeps the previous frame's pose."""
        self.lost += 1
        self.records.append((stamp, None))

    def frame_poses(self, optimized: Mapping[int, F64]) -> tuple[list[float], list[F64]]:
        """Map-frame base pose of every input frame, by stamp: the optimised pose of its key
        frame (or of the latest earlier key frame still in the graph, when the core merged it
        away) composed with the odometry between the two; a lost frame repeats the previous
        frame's pose. Frames before the first key frame have none."""
        keys = sorted(self.key_stamps, key=lambda i: (self.key_stamps[i], i))
        out_stamps: list[float] = []
        out_poses: list[F64] = []
        n = -1  # index in keys of the latest key frame at or before the record
        last: F64 | None = None
        for stamp, odom in sorted(self.records, key=lambda r: r[0]):
            while n + 1 < len(keys) and self.key_stamps[keys[n + 1]] <= stamp:
                n += 1
            if odom is None:
                if last is not None:
                    out_stamps.append(stamp)
                    out_poses.append(last)
                continue
            m = n
            while m >= 0 and keys[m] not in optimized:
                m -= 1
            if m < 0:
                last = None
                continue
            anchor = keys[m]
            last = optimized[anchor] @ se3_inverse(self.key_odom[anchor]) @ odom
            out_stamps.append(stamp)
            out_poses.append(last)
        return out_stamps, out_poses

    def keyframe_poses(self, optimized: Mapping[int, F64]) -> tuple[list[float], list[F64]]:
        """(stamps, optimised base poses) of the key frames still in the graph, by id."""
        ids = sorted(i for i in optimized if i in self.key_stamps)
        return [self.key_stamps[i] for i in ids], [optimized[i] for i in ids]
