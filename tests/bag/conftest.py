"""The recording most rosbag2 tests start from: the talker for 2 s of sim time."""

from __future__ import annotations

from pathlib import Path

import pytest

from _support.bags import record_talker


@pytest.fixture
def recorded(tmp_path: Path) -> Path:
    bag = tmp_path / "run"
    record_talker(bag)
    return bag
