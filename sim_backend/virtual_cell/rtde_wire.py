"""RTDE wire format (protocol version 2), as UR's RTDE guide and its Python client define it.

Every message is `uint16 size (header included) | uint8 type | payload`, big-endian. The
controller answers the setup requests with the RTDE type of each named field (`NOT_FOUND` for
a name it does not know, `IN_USE` for an input another client already writes) and streams
output data packages `uint8 recipe id | fields` at the requested frequency once started.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

HEADER = struct.Struct(">HB")

# RTDE type -> struct format of its value.
TYPE_FORMAT = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
TYPE_WIDTH = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}

_V6 = "VECTOR6D"
OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE",
    **{
        name: _V6
        for name in (
            "target_q",
            "target_qd",
            "target_qdd",
            "target_current",
            "target_moment",
            "actual_q",
            "actual_qd",
            "actual_qdd",
            "actual_current",
            "actual_current_as_torque",
            "actual_moment",
            "joint_control_output",
            "actual_TCP_pose",
            "actual_TCP_speed",
            "actual_TCP_force",
            "target_TCP_pose",
            "target_TCP_speed",
            "joint_temperatures",
            "actual_joint_voltage",
            "ft_raw_wrench",
            "payload_inertia",
        )
    },
    "actual_digital_input_bits": "UINT64",
    "actual_digital_output_bits": "UINT64",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "runtime_state": "UINT32",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    **{f"output_int_register_{i}": "INT32" for i in range(48)},
    **{f"output_double_register_{i}": "DOUBLE" for i in range(48)},
    **{f"output_bit_register_{i}": "BOOL" for i in range(64, 128)},
}

INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "external_force_torque": "VECTOR6D",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    **{f"input_int_register_{i}": "INT32" for i in range(48)},
    **{f"input_double_register_{i}": "DOUBLE" for i in range(48)},
    **{f"input_bit_register_{i}": "BOOL" for i in range(64, 128)},
}


def message(kind: int, payload: bytes = b"") -> bytes:
    """One framed RTDE message."""
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def recipe_struct(types: Sequence[str]) -> struct.Struct:
    """The struct of a data package's fields (after the recipe id byte)."""
    return struct.Struct(">" + "".join(TYPE_FORMAT[t] for t in types))


def flatten(types: Sequence[str], values: Sequence[object]) -> list[object]:
    """Field values -> the flat list `recipe_struct(types).pack` takes (vectors spread out)."""
    flat: list[object] = []
    for kind, value in zip(types, values, strict=True):
        if kind in TYPE_WIDTH:
            flat.extend(value)  # type: ignore[arg-type]
        else:
            flat.append(value)
    return flat


def unflatten(types: Sequence[str], flat: Sequence[object]) -> list[object]:
    """The inverse of `flatten`: vectors regrouped into lists."""
    out: list[object] = []
    i = 0
    for kind in types:
        n = TYPE_WIDTH.get(kind, 0)
        if n:
            out.append(list(flat[i : i + n]))
            i += n
        else:
            out.append(flat[i])
            i += 1
    return out


def text_message(text: str, source: str = "virtual-cell", level: int = 1) -> bytes:
    """A protocol-2 text message ('M'): length-prefixed message and source, warning level."""
    m, s = text.encode()[:255], source.encode()[:255]
    return message(TEXT_MESSAGE, bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))
