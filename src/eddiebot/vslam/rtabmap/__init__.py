"""RTAB-Map-style RGB-D graph SLAM core: one call per synchronised frame.

`Rtabmap.process(rgb, depth, camera, odom_pose, stamp_ns, scan)` creates a node, runs the
bag-of-words Bayes loop-closure detector over working memory, verifies a hypothesis with PnP,
optionally adds proximity links, optimises the graph and returns the map→odom correction.
One module per part: `core` (the per-frame loop), `odometry_links`, `verification`,
`proximity`, `graph_update`, `multi_map`, `localize`, `memory_management` and `outputs`,
over the attributes `state` declares.
"""

from eddiebot.vslam.closure_check import closure_mahalanobis, path_covariance
from eddiebot.vslam.odometry_frames import (
    ODOM_FRAME_ID_OFFSET,
    OdometryFrames,
    odometry_frame_graph,
)
from eddiebot.vslam.records import FrameRecord, ProcessResult
from eddiebot.vslam.rtabmap.core import Rtabmap

__all__ = ["ODOM_FRAME_ID_OFFSET", "FrameRecord", "OdometryFrames", "ProcessResult", "Rtabmap",
           "closure_mahalanobis", "odometry_frame_graph", "path_covariance"]
