"""The LCM messages of the hardware interface, as plain functions.

Each message kind has an `encode_*` function (numbers -> bytes) and a
`decode_*` function (bytes -> `Decoded`) that checks everything the
controller relies on and raises `MessageError` otherwise: bytes that are
not the message (another type's fingerprint, too short or too long), a
wrong number of joints, a NaN or an infinity. Whether a time stamp is in
sequence, and whether a command comes from the sender the robot obeys,
are matters of the sequence, judged by the receivers (drake_wbc.hardware.
codecs). The commands carry their sender's identity (`sender`, see
drake_wbc/hardware/README.md).

The types are in lcmtypes/*.lcm (package drake_wbc_lcm, Python generated
by lcm-gen beside them); the wrist's wrench is Drake's lcmt_force_torque.
Time stamps are microseconds (`utime`; lcmt_force_torque's `timestamp`).

`RawBytesSerializer` lets Drake's LcmPublisherSystem send the bytes that
the encoders made (the receivers take the bytes from their own
subscriptions, so that a malformed message reaches the decoder, which
rejects it: drake_wbc.hardware.codecs).
"""

import struct
from typing import NamedTuple

import numpy as np
from drake import lcmt_force_torque
from pydrake.common.value import AbstractValue
from pydrake.systems.lcm import SerializerInterface

from drake_wbc.hardware.lcmtypes.drake_wbc_lcm import (
    arm_command_t,
    arm_status_t,
    base_state_t,
    base_velocity_command_t,
    obstacle_points_t,
    signal_bundle_t,
)


class MessageError(ValueError):
    """Bytes that are not a usable message."""


class Decoded(NamedTuple):
    """A checked message: its time stamp and its values.

    Attributes:
        utime: the sender's time stamp, microseconds.
        values: a tuple of numpy arrays, one per output of the message
            kind (e.g. positions and velocities of an arm status).
        sender: the sender's identity (commands only; None for the
            robot's messages, which carry none).
    """

    utime: int
    values: tuple
    sender: int | None = None


class RawBytesSerializer(SerializerInterface):
    """A Drake LCM serializer whose value is the message's bytes: a
    publisher sends them as they are (encoding and decoding happen in
    drake_wbc.hardware.codecs)."""

    def __init__(self):
        SerializerInterface.__init__(self)

    def __repr__(self):
        return "RawBytesSerializer()"

    def CreateDefaultValue(self):
        return AbstractValue.Make(b"")

    def Deserialize(self, buffer, abstract_value):
        abstract_value.set_value(bytes(buffer))

    def Serialize(self, abstract_value):
        return bytes(abstract_value.get_value())


def _decode(lcm_type, data):
    """`lcm_type.decode(data)`, with every failure a MessageError; also
    rejects trailing bytes (a message of another layout)."""
    if not isinstance(data, (bytes, bytearray)) or not data:
        raise MessageError("no message (empty bytes)")
    try:
        message = lcm_type.decode(bytes(data))
    except (ValueError, struct.error, IndexError, UnicodeDecodeError,
            OverflowError, MemoryError) as error:
        raise MessageError(
            f"{len(data)} bytes are not a valid {lcm_type.__name__}: "
            f"{error}") from None
    if len(message.encode()) != len(data):
        raise MessageError(f"{len(data)} bytes are not a valid "
                           f"{lcm_type.__name__}: bytes left over after "
                           "the message")
    return message


def _finite(name, values, size=None):
    """`values` as a float array, checked finite and of `size`."""
    array = np.asarray(values, dtype=float)
    if size is not None and array.shape != (size,):
        raise MessageError(f"{name} has {array.size} entries, which is not "
                           f"allowed: must have {size}")
    if not np.all(np.isfinite(array)):
        raise MessageError(f"{name} = {array} is not allowed: every entry "
                           "must be finite (no NaN or infinity)")
    return array


def _utime(t):
    return int(round(float(t)))


def encode_base_command(utime, velocity, sender=0):
    """base_velocity_command_t bytes for `velocity` [vx, vy, wz] in T_b,
    from `sender` (an int64)."""
    message = base_velocity_command_t()
    message.utime = _utime(utime)
    message.sender = int(sender)
    message.vx, message.vy, message.wz = (float(v) for v in velocity)
    return message.encode()


def decode_base_command(data):
    """Decoded (velocity (3,)) of base_velocity_command_t bytes."""
    m = _decode(base_velocity_command_t, data)
    return Decoded(m.utime, (_finite("velocity", [m.vx, m.vy, m.wz]),),
                   m.sender)


def encode_base_state(utime, state):
    """base_state_t bytes for `state` [x, y, yaw, vx, vy, wz] (the
    station's base.state_estimated)."""
    message = base_state_t()
    message.utime = _utime(utime)
    (message.x, message.y, message.yaw, message.vx, message.vy,
     message.wz) = (float(v) for v in state)
    return message.encode()


def decode_base_state(data):
    """Decoded (state (6,)) of base_state_t bytes."""
    m = _decode(base_state_t, data)
    return Decoded(m.utime, (_finite(
        "state", [m.x, m.y, m.yaw, m.vx, m.vy, m.wz]),))


def encode_arm_command(utime, positions, sender=0):
    """arm_command_t bytes for joint `positions` (rad), from `sender` (an
    int64)."""
    message = arm_command_t()
    message.utime = _utime(utime)
    message.sender = int(sender)
    message.position = [float(q) for q in positions]
    message.num_joints = len(message.position)
    return message.encode()


def decode_arm_command(data, num_joints=None):
    """Decoded (positions (n,)) of arm_command_t bytes; a message for
    another number of joints than `num_joints` (any if None) is
    refused."""
    m = _decode(arm_command_t, data)
    return Decoded(m.utime, (_finite("position", m.position, num_joints),),
                   m.sender)


def encode_arm_status(utime, positions, velocities):
    """arm_status_t bytes for joint `positions` and `velocities`."""
    message = arm_status_t()
    message.utime = _utime(utime)
    message.position = [float(q) for q in positions]
    message.velocity = [float(v) for v in velocities]
    message.num_joints = len(message.position)
    if len(message.velocity) != message.num_joints:
        raise ValueError(
            f"velocities has {len(message.velocity)} entries, which is not "
            f"allowed: must have one per position ({message.num_joints})")
    return message.encode()


def decode_arm_status(data, num_joints=None):
    """Decoded (positions (n,), velocities (n,)) of arm_status_t bytes; a
    message for another number of joints than `num_joints` (any if None)
    is refused."""
    m = _decode(arm_status_t, data)
    return Decoded(m.utime, (_finite("position", m.position, num_joints),
                             _finite("velocity", m.velocity, num_joints)))


def encode_wrench(utime, wrench):
    """lcmt_force_torque bytes for `wrench` [fx, fy, fz, tx, ty, tz]."""
    message = lcmt_force_torque()
    message.timestamp = _utime(utime)
    (message.fx, message.fy, message.fz, message.tx, message.ty,
     message.tz) = (float(v) for v in wrench)
    return message.encode()


def decode_wrench(data):
    """Decoded (wrench (6,)) of lcmt_force_torque bytes."""
    m = _decode(lcmt_force_torque, data)
    return Decoded(m.timestamp, (_finite(
        "wrench", [m.fx, m.fy, m.fz, m.tx, m.ty, m.tz]),))


def encode_obstacle_points(utime, points):
    """obstacle_points_t bytes for (M, 2) `points` in T_b (no points: any
    empty array).

    Raises:
        ValueError: for points of another shape (an (M, 3) array was read
            as 3 M / 2 points of mixed coordinates).
    """
    points = np.asarray(points, dtype=float)
    if not points.size:
        points = np.zeros((0, 2))
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"points has shape {points.shape}, which is not "
                         "allowed: must be (M, 2), the x and y of each "
                         "point in T_b")
    message = obstacle_points_t()
    message.utime = _utime(utime)
    message.num_points = len(points)
    message.x = points[:, 0].tolist()
    message.y = points[:, 1].tolist()
    return message.encode()


def decode_obstacle_points(data, max_points=None):
    """Decoded (points (M, 2)) of obstacle_points_t bytes; more than
    `max_points` points (None: any number) are refused, since the
    controller's tick grows with them
    (HardwareOptions.max_obstacle_points)."""
    m = _decode(obstacle_points_t, data)
    if max_points is not None and m.num_points > max_points:
        raise MessageError(
            f"num_points = {m.num_points} is not allowed: must be at most "
            f"{max_points} (hardware.max_obstacle_points)")
    x = _finite("x", m.x, m.num_points)
    y = _finite("y", m.y, m.num_points)
    return Decoded(m.utime, (np.column_stack([x, y]),))


def encode_signal_bundle(utime, time, signals):
    """signal_bundle_t bytes for `signals`, a dict name -> vector, sampled
    at the sender's `time` (s)."""
    message = signal_bundle_t()
    message.utime = _utime(utime)
    message.time = float(time)
    vectors = [np.ravel(np.asarray(v, dtype=float)) for v in signals.values()]
    message.names = list(signals)
    message.sizes = [len(v) for v in vectors]
    message.num_signals = len(vectors)
    message.values = (np.concatenate(vectors).tolist() if vectors else [])
    message.num_values = len(message.values)
    return message.encode()


def decode_signal_bundle(data):
    """(utime, time, dict name -> (k,) array) of signal_bundle_t bytes.
    NaN and infinities are kept (they are logged, not acted upon)."""
    m = _decode(signal_bundle_t, data)
    if sum(m.sizes) != m.num_values or min(m.sizes, default=0) < 0:
        raise MessageError(f"sizes = {list(m.sizes)} is not allowed: must "
                           f"add up to num_values = {m.num_values}")
    values = np.asarray(m.values, dtype=float)
    offsets = np.concatenate([[0], np.cumsum(m.sizes)]).astype(int)
    signals = {name: values[offsets[i]:offsets[i + 1]]
               for i, name in enumerate(m.names)}
    return m.utime, m.time, signals
