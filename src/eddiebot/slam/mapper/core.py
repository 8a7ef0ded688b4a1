"""`SlamCore`: one call per scan, dispatching to mapping or localization (see the package docstring)."""


from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_compose, se2_inverse
from eddiebot.slam.mapper.mapping import Mapping
from eddiebot.slam.mapper.measurement import corrected_scan
from eddiebot.slam.mapper.results import FloatArray, ProcessResult, ProcessStatus, SlamWarning
from eddiebot.slam.mapper.se2_rows import _compose1, _inverse1
from eddiebot.slam.scan import Scan, check_scan, scan_points


class SlamCore(Mapping):
    """2D graph SLAM over laser scans and odometry (pure: no clock, no bus, no files).

    ``sensor_offset`` is the laser's pose in the base frame (x, y, theta).
    ``on_warning`` is called for every warning (e.g. the node logs them); warnings are also
    returned in each `ProcessResult`.
    """

    def process_ranges(
        self,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        odom_pose: npt.ArrayLike,
        stamp_ns: int,
        *,
        range_min: float = 0.0,
        range_max: float = math.inf,
        expected_beams: int | None = None,
    ) -> ProcessResult:
        """`process` with the scan given as arrays."""
        scan = Scan(
            np.asarray(ranges, dtype=np.float64),
            np.asarray(angles, dtype=np.float64),
            float(range_min),
            float(range_max),
            int(stamp_ns),
        )
        return self.process(scan, odom_pose, expected_beams=expected_beams)


    def process(
        self,
        scan: Scan,
        odom_pose: npt.ArrayLike,
        *,
        expected_beams: int | None = None,
    ) -> ProcessResult:
        """Process one scan taken at robot pose ``odom_pose`` (odom frame, m/rad)."""
        warnings: list[SlamWarning] = []
        st = self._state
        stamp = int(scan.stamp_ns)
        odom = np.asarray(odom_pose, dtype=np.float64).reshape(-1)
        if odom.size != 3 or not np.all(np.isfinite(odom)):
            self._warn(
                warnings, "bad_odometry", f"non-finite or malformed odometry pose {odom}", stamp
            )
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        check = check_scan(
            scan,
            expected_beams=expected_beams,
            last_stamp_ns=st.last_stamp_ns,
            max_laser_range=self.config.max_laser_range,
        )
        if not check.ok:
            kind = "time_backwards" if "backwards" in check.reason else "bad_scan"
            self._warn(warnings, kind, f"scan at {stamp} ns skipped: {check.reason}", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        shape_error = self._scan_shape_error(scan)
        if shape_error:
            self._warn(
                warnings, "scan_shape", f"scan at {stamp * 1e-9:.3f} s skipped: {shape_error}", stamp
            )
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        nan = int(np.count_nonzero(np.isnan(scan.ranges)))
        inf = int(np.count_nonzero(np.isinf(scan.ranges)))
        if nan or inf:
            self.nonfinite_range_scans += 1
            if self.nonfinite_range_scans == 1:
                self._warn(
                    warnings,
                    "nonfinite_ranges",
                    f"scan at {stamp * 1e-9:.3f} s has {nan} NaN and {inf} ±Inf ranges of "
                    f"{scan.ranges.size}: those beams are ignored (counted in "
                    "nonfinite_range_scans; not repeated)",
                    stamp,
                )
        st.last_stamp_ns = stamp
        if st.pending_start is not None:
            st.map_to_odom = _compose1(st.pending_start, _inverse1(odom))
            st.pending_start = None
        else:
            jump = self._odometry_jumped(odom)
            if jump is not None:
                self._reanchor(odom, jump, warnings, stamp)
        st.last_seen_odom = odom.copy()
        if self.config.scan_range_bias_quadratic > 0.0:
            scan = corrected_scan(scan, self.config.scan_range_bias_quadratic)
        if not self._moved_enough(odom):
            return ProcessResult(
                ProcessStatus.NOT_MOVED, self.map_to_odom, warnings=tuple(warnings)
            )
        if self.mode == "localization":
            return self._localize(scan, odom, warnings)
        return self._map(scan, odom, warnings)

    # -- localization
    def _localize(self, scan: Scan, odom: FloatArray, warnings: list[SlamWarning]) -> ProcessResult:
        cfg = self.config
        st = self._state
        stamp = int(scan.stamp_ns)
        if not self.nodes:
            self._warn(warnings, "no_map", "localization mode without a loaded session", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        if st.last_pose is None:
            st.last_pose = self.graph.pose(0)
            st.map_to_odom = se2_compose(st.last_pose, se2_inverse(odom))
        points = scan_points(scan, cfg.max_laser_range)
        prior = self._prior(odom)
        prior_sensor = se2_compose(prior, self.sensor_offset)
        positions = self._positions()
        active = np.flatnonzero(self.active_mask())
        d = np.hypot(positions[active, 0] - prior_sensor[0], positions[active, 1] - prior_sensor[1])
        near = active[d <= cfg.scan_buffer_maximum_scan_distance]
        near = near[
            np.argsort(
                np.hypot(positions[near, 0] - prior_sensor[0], positions[near, 1] - prior_sensor[1])
            )
        ]
        ref_nodes = [int(i) for i in near[: 2 * cfg.scan_buffer_size]]
        pose = prior
        response = 0.0
        covariance = None
        if ref_nodes:
            match = self._match_against(ref_nodes, points, prior_sensor, self._seq_params)
            if match.response < self._weak_response:
                wide = self._match_against(ref_nodes, points, prior_sensor, self._loop_coarse)
                if wide.response > match.response:
                    match = self._match_against(ref_nodes, points, wide.pose, self._loop_fine)
            response, covariance = match.response, match.covariance
            if match.response >= cfg.link_match_minimum_response_fine:
                pose = se2_compose(match.pose, se2_inverse(self.sensor_offset))
                self._check_covariance(match, warnings, stamp)
            else:
                self._warn(
                    warnings,
                    "weak_match",
                    f"localization match response {match.response:.2f}; using odometry",
                    stamp,
                )
        else:
            self._warn(
                warnings, "off_map", "no map nodes near the predicted pose; using odometry", stamp
            )
        st.last_pose = pose.copy()
        st.last_processed_odom = odom.copy()
        st.map_to_odom = se2_compose(pose, se2_inverse(odom))
        return ProcessResult(
            ProcessStatus.LOCALIZED,
            self.map_to_odom,
            pose=pose.copy(),
            response=response,
            covariance=covariance,
            warnings=tuple(warnings),
        )
