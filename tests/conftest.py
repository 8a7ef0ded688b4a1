"""Test-wide settings: nothing from the user's own configuration leaks into a test."""

import os

os.environ["EDDIE_CALIBRATION"] = os.devnull + ".absent"
