"""The Parallax Eddie control board: constants, command codec, firmware emulator and driver.

:mod:`~eddiebot.robot.constants` holds every Eddie constant (wheels, encoders, sensors,
firmware ranges); :mod:`~eddiebot.robot.protocol` encodes and decodes the ASCII command set;
:mod:`~eddiebot.robot.emulator` emulates the firmware byte for byte over a
:mod:`~eddiebot.robot.plant` of two wheels; :mod:`~eddiebot.robot.board` is the driver
(protocol core + typed API) over the :mod:`~eddiebot.robot.links` (serial, in-process) and,
for tests, :mod:`~eddiebot.robot.fault_link`.
"""

from eddiebot.robot.board import Board, BoardEvent, ProtocolCore
from eddiebot.robot.constants import FIRMWARE_1_1, FIRMWARE_1_3, FirmwareProfile
from eddiebot.robot.emulator import FirmwareEmulator, FixedSensors, SensorSource
from eddiebot.robot.links import EmulatorLink, Link, SerialLink
from eddiebot.robot.plant import ControlMode, DrivePlant, PlantConfig
from eddiebot.robot.pty_server import PtyServer

__all__ = [
    "FIRMWARE_1_1",
    "FIRMWARE_1_3",
    "Board",
    "BoardEvent",
    "ControlMode",
    "DrivePlant",
    "EmulatorLink",
    "FirmwareEmulator",
    "FirmwareProfile",
    "FixedSensors",
    "Link",
    "PlantConfig",
    "ProtocolCore",
    "PtyServer",
    "SensorSource",
    "SerialLink",
]
