"""`SlamCore`: one call per scan, dispatching to mapping or localization (see the package docstring)."""


from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from eddiebot.slam.mapper.localization import Localization
from eddiebot.slam.mapper.results import ProcessResult, ProcessStatus, SlamWarning
from eddiebot.slam.mapper.se2_rows import _compose1, _inverse1
from eddiebot.slam.scan import Scan, check_scan


class SlamCore(Localization):
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
            backwards = "backwards" in check.reason
            if not backwards:
                self._follow_odometry(odom, warnings, stamp)
            kind = "time_backwards" if backwards else "bad_scan"
            self._warn(warnings, kind, f"scan at {stamp} ns skipped: {check.reason}", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        shape_error = self._scan_shape_error(scan)
        if shape_error:
            self._follow_odometry(odom, warnings, stamp)
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
            st.last_seen_odom = odom.copy()
        else:
            self._follow_odometry(odom, warnings, stamp)
        if not self._moved_enough(odom):
            return ProcessResult(
                ProcessStatus.NOT_MOVED, self.map_to_odom, warnings=tuple(warnings)
            )
        if self.mode == "localization":
            return self._localize(scan, odom, warnings)
        return self._map(scan, odom, warnings)
