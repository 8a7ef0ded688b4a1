"""ROS 2 message, service and action types, and their CDR encoding.

One type store holds the ROS 2 Jazzy standard messages (from rosbags) and the
interfaces this package ships (``eddiebot_msgs``, ``std_srvs``, ``nav2_msgs``,
``slam_toolbox``, ``rcl_interfaces`` services, ``lifecycle_msgs`` services, ...).
Import classes per package, as in ROS 2: ``from eddiebot.msgs.geometry_msgs import Twist``.
Every field has a default, arrays are numpy arrays, and the same objects go to the
bus, to the CDR serializer and to rosbag2 files. A type missing from the store is looked
up once, when first asked for, in the ``.msg``/``.srv``/``.action`` files under the folders of
``EDDIE_INTERFACE_PATH`` and ``AMENT_PREFIX_PATH`` (``share/<pkg>/msg/...``) and registered.
"""

from eddiebot.msgs._described import register_type_description
from eddiebot.msgs._store import (
    ACTIONS,
    SERVICES,
    TYPESTORE,
    ActionType,
    ServiceType,
    deserialize,
    get_action,
    get_message,
    get_service,
    load_type,
    message_definition,
    normalize_type_name,
    raw_message_type,
    serialize,
    type_hash,
    type_name,
)
from eddiebot.msgs.errors import MessageError, UnknownTypeError

__all__ = [
    "ACTIONS",
    "SERVICES",
    "TYPESTORE",
    "ActionType",
    "MessageError",
    "ServiceType",
    "UnknownTypeError",
    "deserialize",
    "get_action",
    "get_message",
    "get_service",
    "load_type",
    "message_definition",
    "normalize_type_name",
    "raw_message_type",
    "register_type_description",
    "serialize",
    "type_hash",
    "type_name",
]
