"""2D laser SLAM: pure cores in the manner of Karto / slam_toolbox, on GTSAM.

`SlamCore` is the facade (scans + odometry in, map→odom, pose graph and occupancy map out)
with mapping, localization and lifelong modes; `SlamConfig` carries slam_toolbox's
parameter names and defaults. Beneath it: the multi-resolution correlative scan matcher
(`match_scan`), the SE(2) pose graph (`PoseGraph`, iSAM2 or Levenberg–Marquardt with robust
loop kernels, reusable by the RGB-D SLAM), loop-closure search, and the ray-cast occupancy
grid (`OccupancyGridBuilder`). Sessions save and load with `save_session` / `load_session`;
file formats (CARMEN, g2o/TORO, TUM) live in `eddiebot.slam.io`.
"""

from eddiebot.slam.config import SlamConfig, load_slam_config
from eddiebot.slam.errors import (
    CarmenFormatError,
    ConfigError,
    PoseGraphFormatError,
    SessionError,
    SessionVersionError,
    SlamError,
)
from eddiebot.slam.loop_closure import (
    LoopClosure,
    find_loop_candidates,
    near_linked_nodes,
    verify_loop,
)
from eddiebot.slam.mapper import (
    NodeRecord,
    ProcessResult,
    ProcessStatus,
    SlamCore,
    SlamWarning,
    matcher_params,
)
from eddiebot.slam.occupancy import OccupancyGridBuilder
from eddiebot.slam.pose_graph import Edge, EdgeKind, PoseGraph
from eddiebot.slam.scan import Scan, ScanCheck, check_scan, scan_angles, scan_points
from eddiebot.slam.scan_matcher import (
    CorrelationGrid,
    MatcherParams,
    MatchResult,
    build_correlation_grid,
    match_scan,
    score_pose,
)
from eddiebot.slam.session import SESSION_FORMAT, SESSION_VERSION, load_session, save_session

__all__ = [
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "CarmenFormatError",
    "ConfigError",
    "CorrelationGrid",
    "Edge",
    "EdgeKind",
    "LoopClosure",
    "MatchResult",
    "MatcherParams",
    "NodeRecord",
    "OccupancyGridBuilder",
    "PoseGraph",
    "PoseGraphFormatError",
    "ProcessResult",
    "ProcessStatus",
    "Scan",
    "ScanCheck",
    "SessionError",
    "SessionVersionError",
    "SlamConfig",
    "SlamCore",
    "SlamError",
    "SlamWarning",
    "build_correlation_grid",
    "check_scan",
    "find_loop_candidates",
    "load_session",
    "load_slam_config",
    "match_scan",
    "matcher_params",
    "near_linked_nodes",
    "save_session",
    "scan_angles",
    "scan_points",
    "score_pose",
    "verify_loop",
]
