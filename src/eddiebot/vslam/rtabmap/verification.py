"""Loop-closure verification: registration of a hypothesis (visual, then ICP with
`Reg/Strategy` 1 or 2), `RGBD/MaxLoopClosureDistance`, `RGBD/LoopCovLimited` and the
Mahalanobis gate, and the further hypotheses of `RGBD/LoopClosureHypotheses`."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.closure_check import closure_mahalanobis
from eddiebot.vslam.depth_icp import (
    IcpResult,
    icp_register,
    make_scan,
    registration_covariance,
)
from eddiebot.vslam.memory import Link, LinkType, Node
from eddiebot.vslam.records import _Verification
from eddiebot.vslam.registration.pipeline import register
from eddiebot.vslam.rtabmap.outputs import MapOutputs
from eddiebot.vslam.rtabmap.state import F64
from eddiebot.vslam.transforms import se3_inverse

_REG_ICP, _REG_VIS_ICP = 1, 2  # Reg/Strategy
#: `RGBD/LoopClosureHypotheses`: a further hypothesis is not within this many links of one
#: already verified (the span where `Bayes/PredictionLC` gives a place's neighbours ≥ 1 %)
_HYPOTHESIS_MARGIN = 4


class LoopVerification(MapOutputs):
    """Registers and checks loop-closure candidates."""

    def _next_hypotheses(self, top: int, count: int) -> list[int]:
        """Up to `count` further places to verify after `top` was rejected, in decreasing
        posterior: each the best location not within `_HYPOTHESIS_MARGIN` links of one
        already chosen (the posterior spreads over a place's neighbours), with data in RAM."""
        if count <= 0:
            return []
        ids, post = self.bayes.posterior_arrays()
        order = np.argsort(-post[1:], kind="stable") + 1
        taken = {top: 0} | self.memory.neighbours(top, _HYPOTHESIS_MARGIN)
        out: list[int] = []
        for k in order.tolist():
            if post[k] <= 0.0 or len(out) >= count:
                break
            i = int(ids[k])
            node = self.memory.nodes.get(i)
            if i in taken or node is None or node.data is None:
                continue
            out.append(i)
            taken.update(self.memory.neighbours(i, _HYPOTHESIS_MARGIN))
            taken[i] = 0
        return out

    def _verify(self, old: Node, new: Node, camera: CameraIntrinsics,
                link_type: LinkType) -> _Verification:
        if old.data is None or new.data is None:
            return _Verification(None, "no data")
        reg = register(old.data.features, new.data.features, camera, self.params)
        if reg.transform is None:
            return _Verification(None, f"registration failed: {reg.reason} ({reg.inliers} inliers)")
        transform, covariance = reg.transform, reg.covariance
        if self.params.reg_strategy in (_REG_ICP, _REG_VIS_ICP):
            # as upstream's Memory::computeTransform: the visual result is ICP's guess
            icp = self._icp_refine(old, new, transform)
            if icp.transform is None:
                return _Verification(None, f"ICP failed: {icp.reason or 'no transform'}")
            transform, covariance = icp.transform, icp.covariance
        limit = self.params.rgbd_max_loop_closure_distance
        if limit > 0 and float(np.linalg.norm(transform[:3, 3])) > limit:
            return _Verification(None, "RGBD/MaxLoopClosureDistance exceeded")
        info = np.asarray(np.linalg.inv(covariance), dtype=np.float64)
        if self.params.rgbd_loop_cov_limited and self._odom_max_info is not None:
            # RGBD/LoopCovLimited: no axis more certain than the best odometry link
            cap = self._odom_max_info
            idx = np.flatnonzero((np.diag(info) > cap) & (cap > 0))
            info[idx, idx] = cap[idx]
        link = Link(new.id, old.id, link_type, se3_inverse(transform), info)
        gate = self.params.rgbd_loop_closure_max_mahalanobis
        if gate > 0 and not self.localization_mode and self.frame_of(old.id) == self.frame_of(new.id):
            old_pose = self.optimized_poses.get(old.id)
            if old_pose is not None:
                d = closure_mahalanobis(link, self.map_to_odom @ new.odom_pose, old_pose,
                                        self.memory.links,
                                        heading_sigma=self.params.rgbd_odom_heading_sigma)
                if d is not None and d > gate:
                    return _Verification(None, f"RGBD/LoopClosureMaxMahalanobis exceeded "
                                               f"({d:.1f} > {gate:g})", link, d)
                if d is not None:
                    return _Verification(link, "", link, d)
        return _Verification(link, "", link)

    def _icp_refine(self, old: Node, new: Node, guess: F64) -> IcpResult:
        """ICP of the new node's depth cloud against the old one's from `guess` (new node in
        the old one's frame); clouds rebuilt from the nodes' decimated depth."""
        a, b = self._cloud_images(old), self._cloud_images(new)
        if a is None or b is None:
            return IcpResult(None, reason="no depth")
        target = make_scan(a.depth(), a.camera, self._icp)
        source = make_scan(b.depth(), b.camera, self._icp)
        result = icp_register(target, source, guess, self._icp)
        if result.transform is None:
            return result
        # upstream's RegistrationIcp covariance on every axis (no free-axis term: a closure
        # along a wall keeps the fit's variance there, as before)
        covariance = registration_covariance(target, source, result.transform, self._icp)
        return replace(result, covariance=covariance)
