"""rosbag2: recording, playback, ``bag info``, reading and recovery of damaged bags.

``BagWriter`` (``writer``) writes rosbag2 (Jazzy) MCAP directories that ``ros2 bag`` and
Foxglove read; ``RecorderNode`` (``recorder``) is ``ros2 bag record`` as a node;
``BagReader`` (``reader``) reads MCAP and sqlite3 bags and, through ``recovery``, the
readable prefix of truncated or damaged MCAP files; ``Player`` (``player``) is
``ros2 bag play`` as a node; ``bag_info`` / ``format_bag_info`` (``info``) are
``ros2 bag info``. Value types are in ``records``, QoS conversion in ``qos``.
"""

from eddiebot.bag.errors import BagError
from eddiebot.bag.info import bag_info, format_bag_info
from eddiebot.bag.player import Player
from eddiebot.bag.qos import qos_from_rosbags, qos_to_rosbags
from eddiebot.bag.reader import BagReader
from eddiebot.bag.recorder import RecorderNode
from eddiebot.bag.records import (
    BagConnection,
    BagInfo,
    BagMessage,
    BagProblem,
    ServiceSummary,
    TopicSummary,
    ensure_type,
)
from eddiebot.bag.writer import BagWriter

__all__ = [
    "BagConnection",
    "BagError",
    "BagInfo",
    "BagMessage",
    "BagProblem",
    "BagReader",
    "BagWriter",
    "Player",
    "RecorderNode",
    "ServiceSummary",
    "TopicSummary",
    "bag_info",
    "ensure_type",
    "format_bag_info",
    "qos_from_rosbags",
    "qos_to_rosbags",
]
