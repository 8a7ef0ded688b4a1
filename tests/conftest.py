"""Test-wide settings: nothing from the user's own configuration leaks into a test."""

import os

os.environ["EDDIE_CALIBRATION"] = os.devnull + ".absent"
# No test talks to other processes unless it sets up its own router (tests/transport does).
os.environ.setdefault("EDDIE_TRANSPORT", "none")
