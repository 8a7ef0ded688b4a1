"""Seeded odometry degradation for SLAM benchmarks on corrected CARMEN logs.

From a reference trajectory (the corrected laser poses) build odometry whose increments carry
5 % of the distance travelled as translation noise, 3°/m heading noise, and a few wheel
slips (0.3 m along the heading, 15° of rotation, random sign) — a known answer for real scans.

    python benchmarks/degrade_odometry.py IN.log.gz OUT.log [--seed 1]

writes a copy of the log whose FLASER odometry triplets are degraded.
"""

from __future__ import annotations

import argparse
import gzip
import math
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from eddiebot.geometry import se2_between, se2_compose

FloatArray = npt.NDArray[np.float64]


def degrade_odometry(
    poses: FloatArray,
    *,
    seed: int = 1,
    distance_noise: float = 0.05,
    heading_noise_per_m: float = math.radians(3.0),
    slips: int = 4,
    slip_distance: float = 0.3,
    slip_heading: float = math.radians(15.0),
) -> FloatArray:
    """Odometry poses (N, 3) from reference poses (N, 3), deterministic for a seed."""
    rng = np.random.default_rng(seed)
    n = poses.shape[0]
    slip_at = set(
        rng.choice(
            np.arange(n // 10, n - 1), size=min(slips, max(n - 2, 0)), replace=False
        ).tolist()
    )
    out = np.zeros_like(poses)
    out[0] = poses[0]
    for k in range(1, n):
        z = se2_between(poses[k - 1], poses[k])
        d = math.hypot(z[0], z[1])
        noisy = z + np.array(
            [
                rng.normal(0.0, distance_noise * d),
                rng.normal(0.0, distance_noise * d),
                rng.normal(0.0, heading_noise_per_m * d),
            ]
        )
        if k in slip_at:
            sign = rng.choice([-1.0, 1.0])
            noisy = noisy + np.array([sign * slip_distance, 0.0, sign * slip_heading])
        out[k] = se2_compose(out[k - 1], noisy)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("input", type=Path)
    parser.add_argument("output", type=Path)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    from eddiebot.slam.io import read_carmen

    log = read_carmen(args.input)
    ref = np.array([r.laser_pose for r in log.lasers])
    odom = degrade_odometry(ref, seed=args.seed)
    opener = gzip.open if args.input.suffix == ".gz" else open
    k = 0
    with opener(args.input, "rt") as src, args.output.open("w") as dst:  # type: ignore[operator]
        for line in src:
            tok = line.split()
            if tok and tok[0] == "FLASER":
                n = int(tok[1])
                tok[2 + n + 3 : 2 + n + 6] = [f"{v:.6f}" for v in odom[k]]
                k += 1
                line = " ".join(tok) + "\n"
            dst.write(line)
    print(f"wrote {args.output}: {k} scans, seed {args.seed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
