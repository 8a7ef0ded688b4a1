"""A tf2-like transform buffer, listener and broadcasters.

``Buffer`` keeps, for every child frame, a time-sorted history of its transform to its
parent (``cache_time`` long) and, separately, static transforms that hold at every time.
``lookup_transform(target, source, time)`` walks both frames up to their common ancestor,
interpolating each edge at ``time`` (linear in translation, slerp in rotation), and
returns the geometry_msgs/TransformStamped that maps points in ``source`` into ``target``
(``header.frame_id = target``, ``child_frame_id = source``), as tf2 does. ``time`` 0
(``Time()``) means the latest time at which every edge of the chain is known.

Failures raise tf2's exception types: ``LookupException`` (a frame nobody published),
``ConnectivityException`` (frames in two trees), ``ExtrapolationException`` (a time
outside the cached range, into the past or the future) and ``TimeoutException``.

Frame ids carry no leading ``/`` (one is stripped, as tf2 does). Times are integer
nanoseconds internally; the public API accepts ``Time``, builtin_interfaces/Time, or
int nanoseconds.
"""

from eddiebot.core.tf.buffer import MAX_GRAPH_DEPTH as MAX_GRAPH_DEPTH
from eddiebot.core.tf.buffer import Buffer
from eddiebot.core.tf.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TimeoutException,
    TransformException,
)
from eddiebot.core.tf.ros import TF_QOS as TF_QOS
from eddiebot.core.tf.ros import TF_STATIC_BROADCASTER_QOS as TF_STATIC_BROADCASTER_QOS
from eddiebot.core.tf.ros import TF_STATIC_QOS as TF_STATIC_QOS
from eddiebot.core.tf.ros import (
    StaticTransformBroadcaster,
    TransformBroadcaster,
    TransformListener,
    make_transform,
    make_transform_2d,
)

__all__ = [
    "Buffer",
    "ConnectivityException",
    "ExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "StaticTransformBroadcaster",
    "TimeoutException",
    "TransformBroadcaster",
    "TransformException",
    "TransformListener",
    "make_transform",
    "make_transform_2d",
]
