"""Drake systems between LCM bytes and the station's ports.

A `MessageDecoder` subscribes to one channel and offers the values of
its last good message on vector ports named like the station's; a
`CommandReceiver` is the robot's side of the two command channels, which
obey one sender at a time; a `MessageEncoder` turns vector ports into
bytes for an `LcmPublisherSystem` (or a `FlaggedPublisher`, which sends
at once when told). `SignalBundleEncoder` packs named signals for the
logs. The pure part decides what a new message changes: `receive` and
`take` (the time stamps' sequence, judged by the receiver's clock,
`ClockRules`) and `admit` (the sender lock). drake_wbc/hardware/README.md
states these rules as the protocol.

These are plain double LeafSystems, as the station's sensors are: they
compare bytes and time stamps, carry abstract values, and are no part of
what the controller linearises.
"""

import functools
import logging
import math
from collections import Counter, deque
from typing import NamedTuple

import lcm as lcm_module
import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_wbc.hardware import messages
from drake_wbc.math.base_state import BASE_STATE_SIZE
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


def message_formats(num_joints, max_points=None):
    """The message kinds of the protocol, by name, for an arm of
    `num_joints` joints (an arm message of another size is refused) and
    obstacle point messages of at most `max_points` points (None: any
    number)."""
    n = int(num_joints)
    if n < 1:
        raise ValueError(f"num_joints = {num_joints!r} is not allowed: must "
                         "be a positive whole number")
    return {f.name: f for f in (
        MessageFormat("base_command", messages.encode_base_command,
                      messages.decode_base_command, (("velocity", 3),)),
        MessageFormat("arm_command", messages.encode_arm_command,
                      functools.partial(messages.decode_arm_command,
                                        num_joints=n), (("positions", n),)),
        MessageFormat("base_state", messages.encode_base_state,
                      messages.decode_base_state,
                      (("state", BASE_STATE_SIZE),)),
        MessageFormat("arm_status", messages.encode_arm_status,
                      functools.partial(messages.decode_arm_status,
                                        num_joints=n),
                      (("positions", n), ("velocities", n))),
        MessageFormat("wrist_wrench", messages.encode_wrench,
                      messages.decode_wrench, (("wrench", 6),)),
        MessageFormat("obstacle_points", messages.encode_obstacle_points,
                      functools.partial(messages.decode_obstacle_points,
                                        max_points=max_points),
                      (("points", None),)),
    )}


MESSAGE_KINDS = tuple(message_formats(1))
"""The names of the protocol's message kinds."""


def _format(message_format, num_joints, max_points=None):
    """`message_format`, or the one of `message_formats(num_joints,
    max_points)` it names."""
    if isinstance(message_format, MessageFormat):
        return message_format
    if message_format not in MESSAGE_KINDS:
        raise ValueError(f"message_format = {message_format!r} is not "
                         f"allowed: must be a MessageFormat or one of "
                         f"{', '.join(MESSAGE_KINDS)}")
    if num_joints is None and message_format.startswith("arm_"):
        raise ValueError(f"num_joints = None is not allowed for "
                         f"{message_format!r}: give the arm's joint count")
    return message_formats(num_joints or 1, max_points)[message_format]


class ClockRules(NamedTuple):
    """How a receiver judges its sender's time stamps (drake_wbc/hardware/
    README.md, "Time stamps").

    Attributes:
        tolerance: s: how far a stamp may run ahead of the receiver's
            clock since the last good message (HardwareOptions.
            clock_tolerance).
        resync_messages: how many consecutive out-of-sequence messages,
            each in sequence with the one before, establish a sender's
            clock that jumped (HardwareOptions.clock_resync_messages).
    """

    tolerance: float = 0.1
    resync_messages: int = 3

    @classmethod
    def of(cls, options):
        """The rules of a HardwareOptions."""
        return cls(options.clock_tolerance, options.clock_resync_messages)


class Reception(NamedTuple):
    """What a receiver knows of one channel.

    Attributes:
        utime: the time stamp of the last good message (None: none yet,
            or the sender changed).
        values: the last good message's values (the defaults before).
        received: when the last good message was taken in, s of the
            receiver's clock (-inf: never).
        rejected: how many messages were rejected.
        reason: why the last one was rejected ("" if none was).
        run_utime, run_received, run_length: the newest message of the
            run of consecutive out-of-sequence messages that are in
            sequence among themselves (a sender's clock that may have
            jumped), and how many there were (0: no run).
        clock_jumps: how many times the sender's clock was taken to have
            jumped (a run reached ClockRules.resync_messages).
    """

    utime: int | None
    values: tuple
    received: float
    rejected: int = 0
    reason: str = ""
    run_utime: int = 0
    run_received: float = -np.inf
    run_length: int = 0
    clock_jumps: int = 0

    def __deepcopy__(self, memo):
        # Never changed in place (only replaced), so the copies that Drake
        # makes of an abstract state at each update may share it.
        return self

    def age(self, now):
        """s of the receiver's clock since the last good message was taken
        in, at `now` (inf: never). A message taken in after `now` (the
        receiver's clock was set back since) has no age the clock can
        tell: inf, a stale stream, not a fresh one until the clock
        catches up with it."""
        age = now - self.received
        return age if age >= 0.0 else math.inf


DEFAULT_RULES = ClockRules()
"""The ClockRules of HardwareOptions' defaults."""


def in_sequence(utime, last_utime, last_received, now, tolerance):
    """True when a stamp `utime` (microseconds) may follow `last_utime`,
    received at `last_received` (s of the receiver's clock), at `now`:
    later than it, and not ahead of it by more than the receiver's clock
    has advanced since, plus `tolerance` s."""
    return (last_utime < utime
            <= last_utime + 1e6 * (now - last_received + tolerance))


def receive(reception, data, now, decode, rules=DEFAULT_RULES):
    """The Reception after the message `data` (bytes) arrived at `now`.

    Bytes that `decode` rejects (MessageError: not the message, wrong
    size, NaN) are counted and change nothing else; so does a message
    out of sequence (`take`).
    """
    try:
        decoded = decode(data)
    except messages.MessageError as error:
        return reject(reception, str(error))
    return take(reception, decoded, now, rules)


def reject(reception, reason):
    """`reception` with one more message rejected for `reason`."""
    return reception._replace(rejected=reception.rejected + 1, reason=reason)


def take(reception, decoded, now, rules=DEFAULT_RULES):
    """The Reception after a decoded message arrived at `now`.

    Freshness is the receiver's clock (`received` = `now`); the sender's
    stamps only order the messages. The first message is taken; a repeat
    of the last good stamp is ignored (not counted, not fresh); a message
    in sequence (`in_sequence` with the last good one) is the new last
    good message. Any other (its stamp behind the last good one, or ahead
    of the receiver's clock by more than the tolerance) is rejected, but
    counted in a run: when `rules.resync_messages` consecutive such
    messages are each in sequence with the one before, the sender's clock
    has jumped (a restart, a clock step) and the last of them is taken.
    So no single message, however stamped, locks the genuine ones out for
    more than that many messages.
    """
    if reception.utime is None:
        return _accepted(reception, decoded, now)
    if decoded.utime == reception.utime:
        return reception
    if in_sequence(decoded.utime, reception.utime, reception.received, now,
                   rules.tolerance):
        return _accepted(reception, decoded, now)
    length = 1
    if reception.run_length and in_sequence(
            decoded.utime, reception.run_utime, reception.run_received, now,
            rules.tolerance):
        length = reception.run_length + 1
    if length >= rules.resync_messages:
        return _accepted(reception, decoded, now)._replace(
            clock_jumps=reception.clock_jumps + 1,
            reason=f"the sender's clock jumped from utime = "
                   f"{reception.utime} to {decoded.utime}: taken after "
                   f"{length} consistent messages")
    seconds = (decoded.utime - reception.utime) * 1e-6
    how = (f"{-seconds:.6g} s behind it" if seconds <= 0 else
           f"{seconds - (now - reception.received):.6g} s ahead of the "
           "receiver's clock")
    return reject(reception, (
        f"utime = {decoded.utime} is out of sequence with the last good "
        f"message's {reception.utime} ({how}); a jumped clock is taken "
        f"after {rules.resync_messages} consistent messages"))._replace(
            run_utime=decoded.utime, run_received=float(now),
            run_length=length)


def _accepted(reception, decoded, now):
    return Reception(decoded.utime, decoded.values, float(now),
                     reception.rejected, reception.reason,
                     clock_jumps=reception.clock_jumps)


class SenderLock(NamedTuple):
    """Which sender the robot obeys on its command channels.

    Attributes:
        sender: its identity (None: nobody yet).
        heard: when it was last heard, s of the receiver's clock.
        refused: how many messages of other senders were refused.
        changes: how many times the lock passed to a new sender.
    """

    sender: int | None = None
    heard: float = -np.inf
    refused: int = 0
    changes: int = 0

    def __deepcopy__(self, memo):
        # Never changed in place (only replaced), so the copies that Drake
        # makes of an abstract state at each update may share it.
        return self


def admit(lock, sender, now, quiet_time):
    """(the SenderLock after a command of `sender` at `now`, whether it is
    obeyed, whether the lock passed to it now).

    The first sender heard is locked in; a command of another sender is
    refused while the locked one has been heard within `quiet_time` s
    (the robot's command timeout), and takes the lock after that.
    """
    if sender == lock.sender:
        return lock._replace(heard=float(now)), True, False
    if lock.sender is None or now - lock.heard > quiet_time:
        return SenderLock(sender, float(now), lock.refused,
                          lock.changes + (lock.sender is not None)), True, True
    return lock._replace(refused=lock.refused + 1), False, False


def _points_value(points=None):
    return AbstractValue.Make(np.zeros((0, 2)) if points is None
                              else np.asarray(points, dtype=float))


class _Mailbox:
    """The messages an LCM subscription delivered and a receiver has not
    taken in yet, oldest first, at most QUEUE_LIMIT of them (the oldest
    are dropped, and counted, beyond that).

    Args:
        kind: of a message, the key under which its drop is counted (its
            channel's, for a receiver of several); one for all if None.
    """

    def __init__(self, kind=None):
        self.items = deque()
        self.dropped = Counter()
        self._kind = kind or (lambda item: None)

    def put(self, item):
        if len(self.items) >= QUEUE_LIMIT:
            self.dropped[self._kind(self.items.popleft())] += 1
        self.items.append(item)

    def take(self):
        """(the messages, oldest first; a Counter of the drops by kind)."""
        items, dropped = list(self.items), self.dropped
        self.items.clear()
        self.dropped = Counter()
        return items, dropped

    def keep_newest(self):
        """Drops all but the newest message (and forgets the drops)."""
        while len(self.items) > 1:
            self.items.popleft()
        self.dropped = Counter()


def _dropped(reception, count):
    """`reception` with `count` messages dropped from a full mailbox."""
    return reception._replace(
        rejected=reception.rejected + count,
        reason=f"{count} dropped: more than {QUEUE_LIMIT} messages in one "
               "step")


QUEUE_LIMIT = 1000
"""Messages a receiver holds between two simulator steps (10 s of a
100 Hz stream; a flood beyond that drops the oldest)."""

LOG_INTERVAL = 1.0
"""s of the receiver's clock between two warnings of one receiver about
rejected or refused messages (the first is said at once), so that a
flood of bad messages cannot flood the log as well."""


class QueuedLcm:
    """Receiving over UDP multicast without losing messages.

    DrakeLcm keeps one message a subscription between two of its polls,
    the oldest: after a moment without a poll (a busy processor) the
    receivers would see an old message and miss the newer ones, and a
    flood of garbage on a channel would hide its genuine messages. This is
    the lcm package's own LCM on the same URL, each subscription holding
    up to QUEUE_LIMIT messages; it offers the two methods of DrakeLcm that
    the receivers use, and an LcmPump in the Diagram polls it.

    Args:
        url: the LCM URL (udpm://...).
    """

    def __init__(self, url):
        self.url = url
        self._lcm = lcm_module.LCM(url)

    def get_lcm_url(self):
        return self.url

    def Subscribe(self, channel, handler):  # noqa: N802 (DrakeLcm's name)
        subscription = self._lcm.subscribe(
            channel, lambda _, data: handler(data))
        subscription.set_queue_capacity(QUEUE_LIMIT)

    def HandleSubscriptions(self, timeout_millis):  # noqa: N802
        """Delivers the messages received, at most QUEUE_LIMIT (the rest
        at the next poll: a flood that never pauses must not hold the
        program here); returns how many."""
        count = 0
        while count < QUEUE_LIMIT and self._handle(
                timeout_millis if not count else 0) > 0:
            count += 1
        return count

    def _handle(self, timeout_millis):
        """One message, if one comes within `timeout_millis`: 1, or 0.

        A signal that lands while the wait runs (Ctrl-C, which the
        programs turn into a stop) makes lcm give up with -1, as a
        failure of its socket does: the wait is made once more, where a
        failure raises again and an interruption is over.
        """
        try:
            return self._lcm.handle_timeout(timeout_millis)
        except OSError:
            return self._lcm.handle_timeout(timeout_millis)


def receiving_bus(lcm):
    """What the receivers of an LCM connection `lcm` subscribe on: a
    QueuedLcm of its URL for UDP multicast, `lcm` itself otherwise
    (DrakeLcm's memq:// delivers every message)."""
    url = lcm.get_lcm_url() if hasattr(lcm, "get_lcm_url") else ""
    return QueuedLcm(url) if url.startswith("udpm://") else lcm


class LcmPump(LeafSystem):
    """Delivers the messages received on `bus` to the receivers' Python
    handlers (their mailboxes) at the start of every simulator step,
    before the receivers take them in: a per-step unrestricted update
    that changes no state, so it must come before the receivers in the
    Diagram (the Diagram updates its systems in the order they were
    added; HardwareInterface and RobotSide add it before their
    receivers).

    `bus` is what `receiving_bus` gives: a QueuedLcm over UDP, the
    DrakeLcm itself over memq://. Drake's LcmInterfaceSystem is not used
    to pump: it calls the handlers from Simulator.AdvanceTo, which has
    released the GIL, and pydrake's Subscribe makes each message's bytes
    object before it takes the GIL back (Python 3.12 and later crash
    there; tests/test_hardware_loop.py checks on Python's debug
    allocator). Here the handlers run on the Python thread that holds
    the GIL, over UDP and over memq:// alike, so the in-process runs
    deliver as the deployment does."""

    def __init__(self, bus):
        super().__init__()
        self._bus = bus
        self.DeclarePerStepUnrestrictedUpdateEvent(self._poll)

    def _poll(self, context, state):
        self._bus.HandleSubscriptions(0)


class _Warnings:
    """A receiver's rate-limited warnings on the drake_wbc.hardware
    logger: the first of each kind at once, then at most one a
    LOG_INTERVAL, with the count since."""

    def __init__(self, name):
        self.name = name
        self.last = {}
        self.pending = {}

    def say(self, now, kind, count, reason):
        if not count:
            return
        self.pending[kind] = self.pending.get(kind, 0) + count
        last = self.last.get(kind)
        if last is None or now - last >= LOG_INTERVAL:
            LOG.warning("%s: %d message(s) %s%s: %s", self.name,
                        self.pending[kind], kind, "" if last is None
                        else f" in the last {now - last:.3g} s", reason)
            self.last[kind], self.pending[kind] = now, 0


class MessageDecoder(LeafSystem):
    """The values of the last good message on an LCM channel.

    ::

                        ┌────────────────┐
                        │                ├──► <value ports of the format>
                        │ MessageDecoder ├──► age
                        │                ├──► rejected
                        │                ├──► clock_jumps
                        └────────────────┘

    - value ports: as the format names them (e.g. `positions`,
      `velocities` of an arm status), the last good message's values;
      zeros (no points) until one arrives.
    - age: (1) s since the last good message was taken in (inf before
      the first, and while the receiver's clock is set back before it:
      `Reception.age`), on the receiver's clock (the context's time).
    - rejected: (1) how many messages were rejected (see `receive`).
    - clock_jumps: (1) how many times the sender's clock was taken to
      have jumped (Reception.clock_jumps).

    It subscribes to `channel` itself and takes in every message
    delivered, in order, at the start of each simulator step (an
    LcmPump before it in the Diagram delivers them): not only the last
    one of a step, so that a flood
    of garbage on the channel cannot hide the genuine messages. The
    outputs are of the state alone. Rejections are logged on the
    `drake_wbc.hardware` logger, at most once a LOG_INTERVAL.

    Args:
        message_format: a MessageFormat or the name of one of
            MESSAGE_KINDS (an arm's with `num_joints`).
        lcm: the DrakeLcmInterface to subscribe on (it must outlive the
            system).
        channel: the channel's name.
        rules: the ClockRules of the sender's time stamps.
        num_joints: the arm's joint count, for the arm's kinds by name.
        max_points: the most points an obstacle points message may hold,
            for that kind by name (None: any number).
    """

    def __init__(self, message_format, lcm, channel, rules=DEFAULT_RULES,
                 num_joints=None, max_points=None):
        super().__init__()
        self.format = message_format = _format(message_format, num_joints,
                                               max_points)
        ports = message_format.ports
        self.rules = rules
        self._mailbox = _Mailbox()
        self._warnings = _Warnings(f"{message_format.name} on {channel}")
        lcm.Subscribe(channel, self._mailbox.put)
        self._state = self.DeclareAbstractState(AbstractValue.Make(
            Reception(None, tuple(
                np.zeros((0, 2)) if size is None else np.zeros(size)
                for _, size in ports), -np.inf)))
        for i, (name, size) in enumerate(ports):
            if size is None:
                self.DeclareAbstractOutputPort(
                    name, _points_value, lambda c, o, i=i: o.set_value(
                        self.reception(c).values[i]))
            else:
                self.DeclareVectorOutputPort(
                    name, size, lambda c, o, i=i: o.SetFromVector(
                        self.reception(c).values[i]))
        self.DeclareVectorOutputPort("age", 1, self._age)
        self.DeclareVectorOutputPort("rejected", 1, self._rejected)
        self.DeclareVectorOutputPort(
            "clock_jumps", 1, lambda c, o: o.SetAtIndex(
                0, self.reception(c).clock_jumps))
        self.DeclarePerStepUnrestrictedUpdateEvent(self._update)

    def reception(self, context):
        """The Reception at `context`."""
        return context.get_abstract_state(0).get_value()

    def discard_pending(self):
        """Forgets the messages delivered and not yet taken in but the
        newest: those that came before a run starts (while its program
        waited for the robot), which the receiver's clock did not see
        arrive."""
        self._mailbox.keep_newest()

    def _age(self, context, output):
        output.SetAtIndex(0, self.reception(context).age(context.get_time()))

    def _rejected(self, context, output):
        output.SetAtIndex(0, self.reception(context).rejected)

    def _update(self, context, state):
        items, dropped = self._mailbox.take()
        if not items and not dropped:
            return
        now = context.get_time()
        before = reception = self.reception(context)
        if dropped:
            reception = _dropped(reception, dropped.total())
        for data in items:
            reception = receive(reception, data, now, self.format.decode,
                                self.rules)
        if reception.clock_jumps > before.clock_jumps:
            LOG.warning("%s at t = %.3f s: %s", self._warnings.name, now,
                        reception.reason)
        self._warnings.say(now, "rejected",
                           reception.rejected - before.rejected,
                           reception.reason)
        state.get_mutable_abstract_state(0).set_value(reception)


class Commands(NamedTuple):
    """What a CommandReceiver keeps: its SenderLock and the Reception of
    each command channel."""

    lock: SenderLock
    base: Reception
    arm: Reception

    def __deepcopy__(self, memo):
        # Never changed in place (only replaced), so the copies that Drake
        # makes of an abstract state at each update may share it.
        return self


COMMAND_STATUS = ("base_command_rejected", "arm_command_rejected",
                  "refused", "sender_changes")
"""The entries of CommandReceiver's `status` output."""


class CommandReceiver(LeafSystem):
    """The robot's side of the command channels: the base's and the arm's
    commands of one sender at a time (drake_wbc/hardware/README.md).

    ::

                         ┌─────────────────┐
                         │                 ├──► velocity
                         │ CommandReceiver ├──► positions
                         │                 ├──► status
                         └─────────────────┘

    - velocity: (3) the base command of the last good base_command
      message; zero before the first and once it is older than
      `timeout` (the robot's own command timeout).
    - positions: (n) the arm command of the last good arm_command
      message (`initial_positions` before the first): the arm holds it.
    - status: (4) COMMAND_STATUS: messages rejected on each channel (not
      decodable, out of sequence; see `receive`), messages refused
      (another sender's), and how many times the lock passed to a new
      sender.

    Both channels obey one sender (`admit`): the first one heard, until
    it has been quiet on both for `release_time`; its time stamps are judged
    by `rules` (a new sender starts a new sequence). It subscribes to
    both channels itself and takes in every message delivered, in order
    of arrival, at the start of each simulator step, as MessageDecoder
    does (an LcmPump before it in the Diagram delivers them).

    Args:
        lcm: the DrakeLcmInterface to subscribe on.
        channels: (base command channel, arm command channel).
        initial_positions: (n,) the arm command before the first (n the
            arm's joints: commands of another size are refused).
        timeout: s, the robot's command timeout.
        release_time: s, the sender lock's quiet time (at least
            `timeout`).
        rules: the ClockRules.
    """

    def __init__(self, lcm, channels, initial_positions, timeout,
                 release_time, rules=DEFAULT_RULES):
        super().__init__()
        self.timeout = positive("timeout", timeout)
        self.release_time = positive("release_time", release_time)
        self.rules = rules
        self.initial = as_vector("initial_positions", initial_positions)
        n = self.initial.size
        formats = message_formats(n)
        self._formats = (formats["base_command"], formats["arm_command"])
        self._mailbox = _Mailbox(kind=lambda item: item[0])
        self._warnings = _Warnings(f"commands on {', '.join(channels)}")
        self._rejections = tuple(
            _Warnings(f"{message_format.name} on {channel}")
            for message_format, channel in zip(self._formats, channels,
                                               strict=True))
        for kind, channel in enumerate(channels):
            lcm.Subscribe(channel, lambda data, kind=kind: self._mailbox.put(
                (kind, data)))
        self._state = self.DeclareAbstractState(AbstractValue.Make(Commands(
            SenderLock(),
            Reception(None, (np.zeros(3),), -np.inf),
            Reception(None, (self.initial.copy(),), -np.inf))))
        self.DeclareVectorOutputPort("velocity", 3, self._velocity)
        self.DeclareVectorOutputPort("positions", n, self._positions)
        self.DeclareVectorOutputPort("status", len(COMMAND_STATUS),
                                     self._status)
        self.DeclarePerStepUnrestrictedUpdateEvent(self._update)

    def stored(self, context):
        """The Commands at `context`."""
        return context.get_abstract_state(0).get_value()

    def _velocity(self, context, output):
        base = self.stored(context)[1]
        stale = base.age(context.get_time()) > self.timeout
        output.SetFromVector(np.zeros(3) if stale else base.values[0])

    def _positions(self, context, output):
        output.SetFromVector(self.stored(context)[2].values[0])

    def _status(self, context, output):
        lock, base, arm = self.stored(context)
        output.SetFromVector([base.rejected, arm.rejected, lock.refused,
                              lock.changes])

    def _update(self, context, state):
        items, dropped = self._mailbox.take()
        if not items and not dropped:
            return
        now = context.get_time()
        lock, *receptions = self.stored(context)
        before = (lock, *receptions)
        for kind, data in items:
            try:
                decoded = self._formats[kind].decode(data)
            except messages.MessageError as error:
                receptions[kind] = reject(receptions[kind], str(error))
                continue
            lock, obeyed, new = admit(lock, decoded.sender, now,
                                      self.release_time)
            if not obeyed:
                continue
            if new:
                receptions = [r._replace(utime=None) for r in receptions]
                LOG.warning("commands at t = %.3f s: obeying sender %d%s",
                            now, decoded.sender,
                            "" if before[0].sender is None else
                            f" (sender {before[0].sender} fell quiet)")
            receptions[kind] = take(receptions[kind], decoded, now,
                                    self.rules)
        for kind, count in dropped.items():
            receptions[kind] = _dropped(receptions[kind], count)
        # Each channel's rejections with its own reason: that of its last
        # message rejected (since its last warning), not another channel's
        # of long ago.
        for kind, reception in enumerate(receptions):
            self._rejections[kind].say(
                now, "rejected", reception.rejected - before[1 + kind].rejected,
                reception.reason)
        self._warnings.say(now, "refused", lock.refused - before[0].refused,
                           f"another sender than {lock.sender}, which has "
                           "the command channels")
        state.get_mutable_abstract_state(0).set_value(
            Commands(lock, *receptions))


class FlaggedPublisher(LeafSystem):
    """Publishes a message's bytes at once, between the periodic
    publications, when a flag says so (the command guard's stop).

    ::

                     ┌──────────────────┐
          message ──►│ FlaggedPublisher │
          flag ─────►│                  │
                     └──────────────────┘

    - message: abstract, the bytes (a MessageEncoder's).
    - flag: (1) >= 0.5: publish at this check.

    Args:
        lcm: the DrakeLcmInterface.
        channel: the channel's name.
        period, offset: when it checks the flag, s.
    """

    def __init__(self, lcm, channel, period, offset):
        super().__init__()
        self._lcm, self.channel = lcm, channel
        self._message = self.DeclareAbstractInputPort(
            "message", AbstractValue.Make(b""))
        self._flag = self.DeclareVectorInputPort("flag", 1)
        self.DeclarePeriodicPublishEvent(positive("period", period),
                                         non_negative("offset", offset),
                                         self._publish)

    def _publish(self, context):
        if self._flag.Eval(context)[0] >= 0.5:
            self._lcm.Publish(self.channel, self._message.Eval(context),
                              context.get_time())


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
        message_format: a MessageFormat or the name of one of
            MESSAGE_KINDS (an arm's with `num_joints`).
        sender: the sender's identity, for the command formats (which
            carry one); None for the others.
        num_joints: the arm's joint count, for the arm's kinds by name.
    """

    def __init__(self, message_format, sender=None, num_joints=None):
        super().__init__()
        self.format = message_format = _format(message_format, num_joints)
        self.sender = sender
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

    def utime(self, context):
        """The stamp of a message encoded at `context` (this system's or
        the root's), microseconds."""
        return _utime(self, self.GetMyContextFromRoot(context))

    def _encode(self, context, output):
        values = [port.Eval(context) for port in self._inputs]
        extra = {} if self.sender is None else {"sender": self.sender}
        output.set_value(self.format.encode(_utime(self, context), *values,
                                            **extra))


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
