"""The runtime: nodes, topics, services, actions, parameters, time, TF and executors.

Names mirror rclpy (``Node``, ``create_publisher``, ``create_subscription``,
``create_timer``, ``create_service``, ``create_client``, ``declare_parameter``,
``get_clock``, ``get_logger``) so a ROS 2 user reads this code without a manual. Time is
integer nanoseconds from an injected clock; a ``SingleThreadedExecutor`` on a simulated
clock jumps straight to the next due timer, so simulated runs are deterministic and as
fast as the CPU allows.
"""

from eddiebot.core.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from eddiebot.core.context import Context, get_default_context, init, shutdown
from eddiebot.core.errors import (
    InvalidParameterTypeError,
    InvalidParameterValueError,
    ParameterError,
    ParameterFileError,
    ParameterNotDeclaredError,
    ServiceCallTimeoutError,
    ServiceUnavailableError,
    TopicTypeMismatchError,
)
from eddiebot.core.executors import (
    Executor,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
    spin,
    spin_once,
    spin_until_future_complete,
)
from eddiebot.core.lifecycle import LifecycleNode, TransitionCallbackReturn
from eddiebot.core.node import (
    CallbackGroup,
    Client,
    GuardCondition,
    MutuallyExclusiveCallbackGroup,
    Node,
    Publisher,
    ReentrantCallbackGroup,
    Service,
    Subscription,
    Timer,
)
from eddiebot.core.parameters import (
    Parameter,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from eddiebot.core.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_latched,
    qos_profile_sensor_data,
    qos_profile_system_default,
)
from eddiebot.core.task import Future, Task
from eddiebot.core.tf import (
    Buffer,
    StaticTransformBroadcaster,
    TransformBroadcaster,
    TransformListener,
)
from eddiebot.core.time import (
    Clock,
    ClockChange,
    ClockType,
    Duration,
    JumpHandle,
    JumpThreshold,
    SimClock,
    Time,
    TimeJump,
    ns_to_stamp,
    stamp_to_ns,
)

__all__ = [
    "ActionClient",
    "ActionServer",
    "Buffer",
    "CallbackGroup",
    "CancelResponse",
    "Client",
    "Clock",
    "ClockChange",
    "ClockType",
    "Context",
    "DurabilityPolicy",
    "Duration",
    "Executor",
    "Future",
    "GoalResponse",
    "GuardCondition",
    "HistoryPolicy",
    "InvalidParameterTypeError",
    "InvalidParameterValueError",
    "JumpHandle",
    "JumpThreshold",
    "LifecycleNode",
    "MultiThreadedExecutor",
    "MutuallyExclusiveCallbackGroup",
    "Node",
    "Parameter",
    "ParameterDescriptor",
    "ParameterError",
    "ParameterFileError",
    "ParameterNotDeclaredError",
    "ParameterType",
    "Publisher",
    "QoSProfile",
    "ReentrantCallbackGroup",
    "ReliabilityPolicy",
    "Service",
    "ServiceCallTimeoutError",
    "ServiceUnavailableError",
    "SetParametersResult",
    "SimClock",
    "SingleThreadedExecutor",
    "StaticTransformBroadcaster",
    "Subscription",
    "Task",
    "Time",
    "TimeJump",
    "Timer",
    "TopicTypeMismatchError",
    "TransformBroadcaster",
    "TransformListener",
    "TransitionCallbackReturn",
    "get_default_context",
    "init",
    "ns_to_stamp",
    "qos_profile_latched",
    "qos_profile_sensor_data",
    "qos_profile_system_default",
    "shutdown",
    "spin",
    "spin_once",
    "spin_until_future_complete",
    "stamp_to_ns",
]
