"""`SlamCore`: the 2D SLAM facade the node, the replay CLI and the benchmarks call.

``process(scan, odom_pose)`` takes a scan (sensor frame) and the robot's odometry pose
(``odom → base_footprint``) and returns a `ProcessResult`; ``map_to_odom`` is the correction
to publish. Modes are strategies composed into the core, not subclasses:

* ``mapping``: each accepted scan becomes a node, matched against the running buffer of
  recent nodes, linked to the previous node, checked for loop closures, optimised;
* ``localization``: scans are matched against a loaded graph's scans near the prior and a
  rolling buffer of the last localised scans; the graph is never extended; without a pose,
  or when the map stops supporting it, the scan is searched for over the whole map
  (`eddiebot.slam.mapper.localization`);
* ``lifelong``: mapping on top of a loaded session; each new node re-scores the older nodes
  its scan overlaps with slam_toolbox's ``lifelong_*`` scores (`eddiebot.slam.mapper.lifelong`),
  and a node whose score falls below ``lifelong_node_removal_score`` leaves the map, the match
  and loop searches and memory at once, and the pose graph by marginalisation (in batches of
  ten): unlike upstream, which deletes the node with its edges, its edges are replaced by
  edges between its neighbours carrying what they said (`PoseGraph.marginalize`).

Which scans are processed: the first, then any whose *sensor* pose moved at least
``minimum_travel_distance`` **or** turned at least ``minimum_travel_heading`` since the last
processed one — in every mode. (Deviation from slam_toolbox, whose sync and localization
modes add a node-level gate that needs translation, so a robot turning on the spot is never
re-localised there; the time gate ``minimum_time_interval`` and ``throttle_scans`` are left
to the node.)

Bad input never raises and never reaches the graph: a scan with a beam count that does not
match its angles or its announced count, too few valid ranges, non-finite angles, a stamp
older than the previous scan's, a beam count or angle range other than the first scan's (as
Karto's laser check), or a non-finite odometry pose is skipped with one warning. NaN and ±Inf
ranges are ignored beam by beam (one warning, then counted in ``nonfinite_range_scans``). An
odometry step between consecutive scans (those skipped for their ranges count: their odometry
is as good) beyond ``max_odometry_jump`` (m) or
``max_odometry_jump_heading`` (rad) is not integrated: the robot is taken to be where it was,
the odometry is re-anchored there, and the scan starts a new chain that scan matching links to
the nearest recent node (a weak link where the match fails); ``odometry_jumps`` counts them.
"""

from __future__ import annotations

from eddiebot.slam.mapper.core import SlamCore
from eddiebot.slam.mapper.measurement import (
    constrained_information,
    fuse_increments,
    matcher_params,
    scan_position_covariance,
)
from eddiebot.slam.mapper.results import NodeRecord, ProcessResult, ProcessStatus, SlamWarning
from eddiebot.slam.mapper.warm_up import valid_point_count, warm_up

__all__ = [
    "NodeRecord",
    "ProcessResult",
    "ProcessStatus",
    "SlamCore",
    "SlamWarning",
    "constrained_information",
    "fuse_increments",
    "matcher_params",
    "scan_position_covariance",
    "valid_point_count",
    "warm_up",
]
