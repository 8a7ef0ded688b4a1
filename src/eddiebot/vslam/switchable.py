"""Vertigo switchable constraints for `Optimizer/Robust` (upstream adds them with g2o or GTSAM):
a switch variable s per loop closure (starting at 1, clamped to [0, 1], with a prior of 1 at
σ = 1) scales the closure's whitened residual and is optimised with the poses, so a closure
the rest of the graph contradicts is switched off (s → 0) instead of bending the map.
gtsam's Python wrapper has no Vertigo factor: `switchable_between` is a `CustomFactor` with
the analytic Jacobians."""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph_links import F64, _pose2, _pose3

__all__ = ["SWITCH_KEY_BASE", "add_switchable", "clamped_switch", "switchable_between"]

#: Vertigo's switch prior (upstream: a switch starting at 1, prior 1 with σ = 1)
_SWITCH_PRIOR = gtsam.noiseModel.Isotropic.Sigma(1, 1.0)
#: keys of switch variables (gtsam symbol 's'), above every node id
SWITCH_KEY_BASE = gtsam.symbol("s", 0)


def add_switchable(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, from_id: int,
                   to_id: int, transform: F64, noise: gtsam.noiseModel.Base, switch_key: int,
                   three_dof: bool) -> None:
    """A Vertigo switchable constraint: the switch variable `switch_key` (initial 1) with its
    prior, then the link's factor scaled by the switch (`switchable_between`)."""
    values.insert(switch_key, np.array([1.0]))
    graph.add(gtsam.PriorFactorVector(switch_key, np.array([1.0]), _SWITCH_PRIOR))
    graph.add(switchable_between(from_id, to_id, switch_key, transform, noise, three_dof))


def switchable_between(from_id: int, to_id: int, switch_key: int, transform: F64,
                       noise: gtsam.noiseModel.Base, three_dof: bool) -> gtsam.CustomFactor:
    """Vertigo's `BetweenFactorSwitchableLinear`: s · (gtsam BetweenFactor's error), s the
    switch clamped to [0, 1] (Vertigo's `SwitchVariableLinear` clamps on retract; here the
    value is clamped where used, and its Jacobian stays the unscaled error so a switch pushed
    past a bound can come back)."""
    if three_dof:
        measured2 = _pose2(np.asarray(transform, dtype=np.float64))

        def error2(this: gtsam.CustomFactor, v: gtsam.Values,
                   jacobians: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
            a, b = v.atPose2(from_id), v.atPose2(to_id)
            s = clamped_switch(v.atVector(switch_key))
            ha, hb = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
            hx = a.between(b, ha, hb)
            hm1, hm2 = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
            delta = measured2.between(hx, hm1, hm2)
            hlog = np.zeros((3, 3), order="F")
            e = np.asarray(gtsam.Pose2.Logmap(delta, hlog), dtype=np.float64)
            if jacobians is not None:
                d = hlog @ hm2
                jacobians[0] = s * (d @ ha)
                jacobians[1] = s * (d @ hb)
                jacobians[2] = e.reshape(3, 1)
            return s * e

        return gtsam.CustomFactor(noise, [from_id, to_id, switch_key], error2)
    measured3 = _pose3(np.asarray(transform, dtype=np.float64))

    def error3(this: gtsam.CustomFactor, v: gtsam.Values,
               jacobians: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
        a, b = v.atPose3(from_id), v.atPose3(to_id)
        s = clamped_switch(v.atVector(switch_key))
        ha, hb = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
        hx = a.between(b, ha, hb)
        hm1, hm2 = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
        delta = measured3.between(hx, hm1, hm2)
        hlog = np.zeros((6, 6), order="F")
        e = np.asarray(gtsam.Pose3.Logmap(delta, hlog), dtype=np.float64)
        if jacobians is not None:
            d = hlog @ hm2
            jacobians[0] = s * (d @ ha)
            jacobians[1] = s * (d @ hb)
            jacobians[2] = e.reshape(6, 1)
        return s * e

    return gtsam.CustomFactor(noise, [from_id, to_id, switch_key], error3)


def clamped_switch(switch: NDArray[np.float64]) -> float:
    """A switch variable's value as used: clamped to [0, 1]."""
    return min(max(float(switch[0]), 0.0), 1.0)

