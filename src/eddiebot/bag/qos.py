"""QoS profiles as rosbag2 stores them (``offered_qos_profiles``) and back.

rosbag2 (Jazzy) writes rmw's infinite duration (``RMW_DURATION_INFINITE``, INT64_MAX ns) split
into seconds and nanoseconds: ``{sec: 9223372036, nsec: 854775807}``; so do we.
"""

from __future__ import annotations

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from eddiebot.core.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["INFINITE_DURATION", "qos_from_rosbags", "qos_to_rosbags"]

#: rmw's "infinite" duration as rosbag2 writes it into metadata.yaml and the MCAP channels.
INFINITE_DURATION = QosTime(9223372036, 854775807)


def qos_to_rosbags(qos: QoSProfile) -> Qos:
    """Our QoS profile as rosbags' ``Qos`` (offered profile in the bag's metadata)."""
    return Qos(
        QosHistory(int(qos.history)),
        int(qos.depth),
        QosReliability(int(qos.reliability)),
        QosDurability(int(qos.durability)),
        INFINITE_DURATION,
        INFINITE_DURATION,
        QosLiveliness.AUTOMATIC,
        INFINITE_DURATION,
        False,
    )


def qos_from_rosbags(qos: Qos) -> QoSProfile:
    """A bag's offered ``Qos`` as our profile (unknown policies become the defaults)."""
    history = (
        HistoryPolicy.KEEP_ALL if qos.history == QosHistory.KEEP_ALL else HistoryPolicy.KEEP_LAST
    )
    depth = max(1, int(qos.depth)) if history == HistoryPolicy.KEEP_LAST else int(qos.depth)
    reliability = (
        ReliabilityPolicy.BEST_EFFORT
        if qos.reliability == QosReliability.BEST_EFFORT
        else ReliabilityPolicy.RELIABLE
    )
    durability = (
        DurabilityPolicy.TRANSIENT_LOCAL
        if qos.durability == QosDurability.TRANSIENT_LOCAL
        else DurabilityPolicy.VOLATILE
    )
    return QoSProfile(depth=depth, reliability=reliability, durability=durability, history=history)
