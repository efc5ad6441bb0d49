"""Device interfaces (`drivers.base`), typed errors (`drivers.errors`), discovery, real drivers.

The real drivers live in their own modules (`v4l2_camera`, `serial_laser`, `modbus_laser`,
`ur_arm`) and are imported only when used, so importing `drivers` stays cheap and needs no
hardware library.
"""

from drivers.base import (
    Arm,
    ArmState,
    Camera,
    Device,
    Frame,
    Gripper,
    LaserSwitch,
    MotionLimits,
    SafetyStatus,
    pose_matrix,
    pose_vector,
)
from drivers.errors import (
    BadReplyError,
    DeviceBusyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceNotReadyError,
    DeviceTimeoutError,
    MotionLimitError,
    SafetyStopError,
    UnsupportedError,
)

__all__ = [
    "Arm",
    "ArmState",
    "BadReplyError",
    "Camera",
    "Device",
    "DeviceBusyError",
    "DeviceConfigError",
    "DeviceDisconnectedError",
    "DeviceError",
    "DeviceNotFoundError",
    "DeviceNotReadyError",
    "DeviceTimeoutError",
    "Frame",
    "Gripper",
    "LaserSwitch",
    "MotionLimitError",
    "MotionLimits",
    "SafetyStatus",
    "SafetyStopError",
    "UnsupportedError",
    "pose_matrix",
    "pose_vector",
]
