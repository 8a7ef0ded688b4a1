"""`RGBD/LoopClosureHypotheses`: further places of the posterior are verified when the top
hypothesis is rejected (not upstream; 1 = upstream)."""

import numpy as np
import pytest
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.memory import Link
from eddiebot.vslam.parameters import ParameterError, RtabmapParameters
from eddiebot.vslam.records import _Verification
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import se3_inverse

CAM = kinect_camera(320, 240)
PARAMS = {"RGBD/LinearUpdate": "0.0", "RGBD/AngularUpdate": "0.0", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05",
          "RGBD/OptimizeMaxError": "0"}


def _revisit(hypotheses: int):
    """A full turn in place (24 views), then view 4 again. The top hypothesis is turned away
    (as a registration failure); any other place is accepted at its true relative pose.
    Returns the result, the places verified in order and the posterior."""
    slam = Rtabmap({**PARAMS, "RGBD/LoopClosureHypotheses": str(hypotheses)})
    for k in range(24):
        slam.process(*frame(4, 4.0, 3.0, 0.26 * k), CAM, planar_pose(0.0, 0.0, 0.26 * k),
                     k * 1_000_000_000)
    verified: list[int] = []

    def verify(old, new, camera, link_type):
        verified.append(old.id)
        if len(verified) == 1:
            return _Verification(None, "registration failed: too few inliers (3 inliers)")
        info = np.diag([1e4, 1e4, 1e4, 1e4, 1e4, 1e4])
        link = Link(new.id, old.id, link_type, se3_inverse(new.odom_pose) @ old.odom_pose, info)
        return _Verification(link, "", link)

    slam._verify = verify  # type: ignore[method-assign]
    r = slam.process(*frame(4, 4.0, 3.0, 0.26 * 3 + 0.03), CAM,
                     planar_pose(0.0, 0.0, 0.26 * 3 + 0.03), 24_000_000_000)
    ids, post = slam.bayes.posterior_arrays()
    return r, verified, dict(zip(ids.tolist(), post.tolist()))


def test_only_the_top_hypothesis_is_verified_by_default():
    assert RtabmapParameters().rgbd_loop_closure_hypotheses == 1
    r, verified, _ = _revisit(1)
    assert r.hypothesis_value >= 0.05 and verified == [r.hypothesis_id]
    assert r.loop_closure_id == 0 and r.rejected_loop_id == r.hypothesis_id
    assert r.rejection_reason.startswith("registration failed")


def test_the_next_place_of_the_posterior_is_verified_after_a_rejection():
    r, verified, post = _revisit(3)
    top = r.hypothesis_id
    assert verified[0] == top and len(verified) == 2
    second = verified[1]
    # the best place of the posterior more than 4 links (consecutive views) from the top one
    far = {i: p for i, p in post.items() if i > 0 and abs(i - top) > 4}
    assert second == max(far, key=far.get)
    assert r.loop_closure_id == second and r.rejected_loop_id == 0 and r.rejection_reason == ""
    assert r.statistics["Loop/Hypotheses_verified/"] == 2.0
    assert r.hypothesis_id == top  # the reported hypothesis stays the top one
    with pytest.raises(ParameterError):
        RtabmapParameters.from_dict({"RGBD/LoopClosureHypotheses": "0"})
