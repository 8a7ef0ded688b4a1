"""A small session database: six key frames of a straight drive, mapped and closed."""

from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.rtabmap import Rtabmap

CAM = kinect_camera(320, 240)
SEC = 1_000_000_000


def write_session_database(path, n=6):
    with SessionDatabase(path, delete_on_start=True) as db:
        slam = Rtabmap({"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
                        "Reg/Force3DoF": "true", "RGBD/CreateOccupancyGrid": "true"}, database=db)
        for k in range(n):
            slam.process(*frame(3, 2.0 + 0.2 * k, 3.0, 0.0), CAM, planar_pose(0.2 * k, 0, 0),
                         k * SEC)
        db.close(slam)
