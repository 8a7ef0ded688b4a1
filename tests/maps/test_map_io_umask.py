"""Saved maps are as readable as any file the user writes (the temporary file is 0600)."""

import os

import numpy as np

from eddiebot.maps import OccupancyMap, save_map


def test_saved_map_files_keep_the_umask(tmp_path):
    grid = np.full((20, 30), -1, dtype=np.int8)
    grid[5:10, 5:10] = 0
    old = os.umask(0o027)
    try:
        yaml_path = save_map(OccupancyMap(grid, 0.05, (0.0, 0.0, 0.0)), tmp_path / "m")
    finally:
        os.umask(old)
    for path in (tmp_path / "m.yaml", tmp_path / "m.pgm", yaml_path):
        assert os.stat(path).st_mode & 0o777 == 0o640
