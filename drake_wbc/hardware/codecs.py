"""Drake systems between LCM bytes and the station's ports.

A `MessageDecoder` sits behind an `LcmSubscriberSystem` that carries the
message's bytes (messages.RawBytesSerializer) and offers the message's
values on vector ports named like the station's, keeping the last good
message; a `MessageEncoder` turns vector ports into bytes for an
`LcmPublisherSystem`. `SignalBundleEncoder` packs named signals for the
logs. The pure part, `receive`, decides what a new message changes.

These are plain double LeafSystems, as the station's sensors are: they
compare bytes and time stamps, carry abstract values, and are no part of
what the controller linearises.
"""

import logging
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_wbc.hardware import messages
from drake_wbc.math.validation import as_vector, non_negative, positive

LOG = logging.getLogger("drake_wbc.hardware")


class MessageFormat(NamedTuple):
    """One message kind: its functions and the ports of its values.

    Attributes:
        name: the kind's name (in diagnostics and messages).
        encode: (utime, *values) -> bytes.
        decode: bytes -> messages.Decoded, raising MessageError.
        ports: (port name, size) per value; size None is an (M, 2) array
            of points on an abstract port (the station's
            lidar.obstacle_points).
    """

    name: str
    encode: object
    decode: object
    ports: tuple


FORMATS = {f.name: f for f in (
    MessageFormat("base_command", messages.encode_base_command,
                  messages.decode_base_command, (("velocity", 3),)),
    MessageFormat("arm_command", messages.encode_arm_command,
                  messages.decode_arm_command, (("positions", 6),)),
    MessageFormat("base_state", messages.encode_base_state,
                  messages.decode_base_state, (("state", 6),)),
    MessageFormat("arm_status", messages.encode_arm_status,
                  messages.decode_arm_status,
                  (("positions", 6), ("velocities", 6))),
    MessageFormat("wrist_wrench", messages.encode_wrench,
                  messages.decode_wrench, (("wrench", 6),)),
    MessageFormat("obstacle_points", messages.encode_obstacle_points,
                  messages.decode_obstacle_points, (("points", None),)),
)}
"""The message kinds of the protocol, by name."""


def _format(message_format):
    """`message_format`, or the one of FORMATS it names."""
    if isinstance(message_format, MessageFormat):
        return message_format
    if message_format not in FORMATS:
        raise ValueError(f"message_format = {message_format!r} is not "
                         f"allowed: must be a MessageFormat or one of "
                         f"{', '.join(FORMATS)}")
    return FORMATS[message_format]


class Reception(NamedTuple):
    """What a decoder knows of its channel.

    Attributes:
        seen: the bytes of the last message looked at (good or not).
        utime: the time stamp of the last good message (None: none yet).
        values: the last good message's values (the defaults before).
        received: when the last good message was taken in, s of the
            receiver's clock (-inf: never).
        rejected: how many messages were rejected.
        reason: why the last one was rejected ("" if none was).
    """

    seen: bytes
    utime: int | None
    values: tuple
    received: float
    rejected: int
    reason: str = ""


def receive(reception, data, now, decode):
    """The Reception after the subscriber holds `data` at time `now`.

    Bytes already seen change nothing. New bytes are rejected (counted,
    the last good values kept) when `decode` raises MessageError (not the
    message, wrong size, NaN) or when their time stamp is older than the
    last good message's; a repeat of the last good time stamp is ignored;
    anything else is the new last good message, received `now`.
    """
    if data == reception.seen:
        return reception
    try:
        decoded = decode(data)
    except messages.MessageError as error:
        return reception._replace(seen=data, rejected=reception.rejected + 1,
                                  reason=str(error))
    if reception.utime is not None and decoded.utime < reception.utime:
        return reception._replace(
            seen=data, rejected=reception.rejected + 1,
            reason=f"utime = {decoded.utime} goes backwards (the last good "
                   f"message had {reception.utime})")
    if decoded.utime == reception.utime:
        return reception._replace(seen=data)
    return Reception(data, decoded.utime, decoded.values, float(now),
                     reception.rejected)


def _points_value(points=None):
    return AbstractValue.Make(np.zeros((0, 2)) if points is None
                              else np.asarray(points, dtype=float))


class MessageDecoder(LeafSystem):
    """The values of the last good message on an LCM channel.

    ::

                        ┌────────────────┐
                        │                ├──► <value ports of the format>
            message ───►│ MessageDecoder ├──► age
                        │                ├──► rejected
                        └────────────────┘

    - message: abstract, the message's bytes (an LcmSubscriberSystem with
      messages.RawBytesSerializer).
    - value ports: as the format names them (e.g. `positions`,
      `velocities` of an arm status), the last good message's values;
      the defaults until one arrives.
    - age: (1) s since the last good message was taken in (inf before
      the first).
    - rejected: (1) how many messages were rejected (see `receive`).

    The outputs take in a new message at once (direct feedthrough from
    the subscriber's state, itself state, so no algebraic loop); a
    per-step unrestricted update then stores it, so `age` counts from the
    first simulator step after the message arrived (at most one step
    late). Each rejection is logged on the `drake_wbc.hardware` logger.

    Args:
        message_format: a MessageFormat or the name of one of FORMATS.
        defaults: the values before the first message (zeros, no points
            if None), one per value port.
        timeout: if given, s: once the last good message is older than
            this, the value ports give `defaults` again (the robot's own
            command timeout); None keeps the last values forever.
        update_period: None (the default) for the per-step update above;
            a period in s stores the message periodically instead (fewer
            updates where the simulator steps often; `age` is then up to
            one period late).
    """

    def __init__(self, message_format, defaults=None, timeout=None,
                 update_period=None):
        super().__init__()
        self.format = message_format = _format(message_format)
        ports = message_format.ports
        if defaults is None:
            defaults = [np.zeros((0, 2)) if size is None else np.zeros(size)
                        for _, size in ports]
        if len(defaults) != len(ports):
            raise ValueError(f"defaults has {len(defaults)} entries, which "
                             f"is not allowed: must have {len(ports)}")
        self.defaults = tuple(
            np.asarray(value, dtype=float) if size is None
            else as_vector(f"defaults[{i}]", value, size)
            for i, ((_, size), value) in enumerate(
                zip(ports, defaults, strict=True)))
        self.timeout = None if timeout is None else non_negative(
            "timeout", timeout)
        self._message = self.DeclareAbstractInputPort(
            "message", AbstractValue.Make(b""))
        self._state = self.DeclareAbstractState(AbstractValue.Make(
            Reception(b"", None, self.defaults, -np.inf, 0)))
        for i, (name, size) in enumerate(ports):
            if size is None:
                self.DeclareAbstractOutputPort(
                    name, _points_value, lambda c, o, i=i: o.set_value(
                        self._values(c)[i]))
            else:
                self.DeclareVectorOutputPort(
                    name, size, lambda c, o, i=i: o.SetFromVector(
                        self._values(c)[i]))
        self.DeclareVectorOutputPort("age", 1, self._age)
        self.DeclareVectorOutputPort("rejected", 1, self._rejected)
        if update_period is None:
            self.DeclarePerStepUnrestrictedUpdateEvent(self._update)
        else:
            self.DeclarePeriodicUnrestrictedUpdateEvent(
                positive("update_period", update_period), 0.0, self._update)

    def reception(self, context):
        """The Reception at `context` (the subscriber's message taken in)."""
        stored = context.get_abstract_state(0).get_value()
        return receive(stored, self._message.Eval(context),
                       context.get_time(), self.format.decode)

    def _values(self, context):
        reception = self.reception(context)
        if (self.timeout is not None
                and context.get_time() - reception.received > self.timeout):
            return self.defaults
        return reception.values

    def _age(self, context, output):
        output.SetAtIndex(0, context.get_time()
                          - self.reception(context).received)

    def _rejected(self, context, output):
        output.SetAtIndex(0, self.reception(context).rejected)

    def _update(self, context, state):
        stored = context.get_abstract_state(0).get_value()
        reception = self.reception(context)
        if reception.rejected > stored.rejected:
            LOG.warning("%s: message rejected (%d so far): %s",
                        self.get_name(), reception.rejected, reception.reason)
        state.get_mutable_abstract_state(0).set_value(reception)


class MessageEncoder(LeafSystem):
    """A message's bytes from its values, for an LcmPublisherSystem.

    ::

                             ┌────────────────┐
        <value ports> ──────►│ MessageEncoder ├──► message
                             └────────────────┘

    - value ports: named as the format's (vector, or abstract (M, 2)
      points).
    - message: abstract, the bytes, stamped utime = 1e6 (t + offset),
      with t the context's time and offset the numeric parameter
      `time_offset` (0; `set_time_offset` sets it, e.g. to the wall
      clock at the start of a run).

    Args:
        message_format: a MessageFormat or the name of one of FORMATS.
    """

    def __init__(self, message_format):
        super().__init__()
        self.format = message_format = _format(message_format)
        self._inputs = [
            self.DeclareAbstractInputPort(name, _points_value())
            if size is None else self.DeclareVectorInputPort(name, size)
            for name, size in message_format.ports]
        self._offset = self.DeclareNumericParameter(BasicVector([0.0]))
        self.DeclareAbstractOutputPort(
            "message", lambda: AbstractValue.Make(b""), self._encode)

    def set_time_offset(self, context, offset):
        """Stamps messages with 1e6 (t + offset) in `context` (this
        system's or the root's)."""
        set_time_offset(self, context, offset)

    def _encode(self, context, output):
        values = [port.Eval(context) for port in self._inputs]
        output.set_value(self.format.encode(_utime(self, context), *values))


class SignalBundleEncoder(LeafSystem):
    """Named vector signals as one signal_bundle_t, for the logs.

    ::

                          ┌─────────────────────┐
        <signal ports> ──►│ SignalBundleEncoder ├──► message
                          └─────────────────────┘

    - one vector input per signal, named as the signal.
    - message: abstract, the bytes, stamped as MessageEncoder's, with the
      context's time in `time`.

    Args:
        sizes: dict signal name -> size.
    """

    def __init__(self, sizes):
        super().__init__()
        self.sizes = dict(sizes)
        self._inputs = {name: self.DeclareVectorInputPort(name, size)
                        for name, size in self.sizes.items()}
        self._offset = self.DeclareNumericParameter(BasicVector([0.0]))
        self.DeclareAbstractOutputPort(
            "message", lambda: AbstractValue.Make(b""), self._encode)

    def set_time_offset(self, context, offset):
        """See MessageEncoder.set_time_offset."""
        set_time_offset(self, context, offset)

    def _encode(self, context, output):
        signals = {name: port.Eval(context)
                   for name, port in self._inputs.items()}
        output.set_value(messages.encode_signal_bundle(
            _utime(self, context), context.get_time(), signals))


def set_time_offset(system, context, offset):
    """Sets the `time_offset` parameter of an encoder in `context` (the
    system's own or a root context holding it)."""
    context = system.GetMyMutableContextFromRoot(context)
    context.get_mutable_numeric_parameter(0).SetAtIndex(0, float(offset))


def _utime(system, context):
    offset = context.get_numeric_parameter(0).GetAtIndex(0)
    return int(round(1e6 * (context.get_time() + offset)))
