"""RGB-D graph SLAM in the manner of RTAB-Map, as pure cores: GFTT/ORB features with depth,
frame-to-map / frame-to-frame visual odometry (PnP RANSAC), an incremental bag-of-words
vocabulary with a TF-IDF likelihood and a Bayes filter for loop closure, geometric verification,
short/working/long-term memory, a gtsam pose graph, local and global occupancy grids, a SQLite
session database, and TUM RGB-D replay tools. Parameters use RTAB-Map's ``Group/Name`` keys.
"""

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.errors import (
    DatabaseCorruptError,
    DatabaseError,
    DatabaseLockedError,
    DatabaseVersionError,
    ParameterError,
    TumFormatError,
    VslamError,
)
from eddiebot.vslam.export import write_ply
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.loops import AppearanceLoopDetector, detect_loops, write_loop_rows
from eddiebot.vslam.memory import Link, LinkType
from eddiebot.vslam.occupancy import GlobalGrid, LocalGrid, Scan2D
from eddiebot.vslam.odometry import OdometryResult, VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration import RegistrationResult, register
from eddiebot.vslam.replay import ReplayReport, replay_tum
from eddiebot.vslam.rtabmap import ProcessResult, Rtabmap
from eddiebot.vslam.tum import read_tum_sequence, write_tum_trajectory

__all__ = [
    "AppearanceLoopDetector",
    "CameraIntrinsics",
    "DatabaseCorruptError",
    "DatabaseError",
    "DatabaseLockedError",
    "DatabaseVersionError",
    "FeatureExtractor",
    "FrameFeatures",
    "GlobalGrid",
    "Link",
    "LinkType",
    "LocalGrid",
    "OdometryResult",
    "ParameterError",
    "ProcessResult",
    "RegistrationResult",
    "ReplayReport",
    "Rtabmap",
    "RtabmapParameters",
    "Scan2D",
    "SessionDatabase",
    "TumFormatError",
    "VisualOdometry",
    "VslamError",
    "detect_loops",
    "read_tum_sequence",
    "register",
    "replay_tum",
    "write_loop_rows",
    "write_ply",
    "write_tum_trajectory",
]
