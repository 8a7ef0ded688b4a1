"""File formats of the 2D SLAM package: CARMEN logs, g2o / TORO pose graphs, TUM trajectories.

These are the package's explicit io modules: the only SLAM code that touches files, apart
from `eddiebot.slam.session`.
"""

from eddiebot.slam.io.carmen import (
    CarmenLog,
    LaserRecord,
    OdomRecord,
    carmen_beam_angles,
    iter_carmen,
    read_carmen,
)
from eddiebot.slam.io.g2o import (
    PoseGraphFile,
    build_pose_graph,
    read_g2o,
    read_pose_graph,
    read_toro,
)
from eddiebot.slam.io.tum import read_tum, write_tum

__all__ = [
    "CarmenLog",
    "LaserRecord",
    "OdomRecord",
    "PoseGraphFile",
    "build_pose_graph",
    "carmen_beam_angles",
    "iter_carmen",
    "read_carmen",
    "read_g2o",
    "read_pose_graph",
    "read_toro",
    "read_tum",
    "write_tum",
]
