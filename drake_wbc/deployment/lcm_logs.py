"""A log of LCM messages (lcm-logger's, or any lcm.EventLog) as the signals
of a run.

`read_lcm_log` decodes every channel of the protocol (channel names of
HardwareOptions) and samples the signals on one time grid, as a
drake_wbc.controller.run_log.RunLog with the signal names of run_log.SIGNALS
where
they exist, so that the experiments' metrics and figures
(drake_wbc.experiments) apply to a run on the robot as to a simulated
one:

- base.state_estimated: WBC_BASE_STATE;
- arm.position_measured, arm.velocity_estimated: WBC_ARM_STATUS;
- wrist.wrench_measured: WBC_WRIST_WRENCH;
- base.velocity_command, arm.position_command: WBC_BASE_COMMAND,
  WBC_ARM_COMMAND (the commands as sent, of the sender the robot obeyed:
  the first heard, until it was quiet for sender_release_time, as the
  robot's rule, drake_wbc.hardware.codecs.admit; another sender's,
  which the robot refused, are skipped);
- truth.*: WBC_TRUTH (from a simulated robot only);
- capability, alpha, ..., reference_velocity, hardware.diagnostics:
  WBC_CONTROLLER.

Time is the controller's clock (0 when `drake-wbc deploy` started, so
the scenario's task schedule applies): WBC_CONTROLLER carries it; every
other message is placed by its reception time in the log, mapped to the
controller's clock by the reception times of WBC_CONTROLLER's messages
(`clock_time`). Without
WBC_CONTROLLER, time is the robot's (WBC_TRUTH's), or reception time
from the first message. Each signal is sampled by holding its latest
message (the first one before it starts) on the grid of the clock's
messages. A log of several runs (each restart of the controller) gives
one run at a time. A message that does not decode, and an arm message of
another joint count than the robot's (`arm_joint_count`), is skipped.
"""

import functools
from collections import Counter, defaultdict

import lcm
import numpy as np

from drake_wbc.controller.run_log import RunLog, column_names
from drake_wbc.hardware import messages
from drake_wbc.hardware.codecs import SenderLock, admit
from drake_wbc.hardware.interface import DIAGNOSTICS
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.math.validation import checked_instance

LATE = 1e-4
"""s: a message stamped up to this after a grid time counts for it (the
senders' clocks tick together, their stamps up to rounding)."""

CHANNEL_SIGNALS = (
    ("base_state", messages.decode_base_state, ("base.state_estimated",)),
    ("arm_status", messages.decode_arm_status,
     ("arm.position_measured", "arm.velocity_estimated")),
    ("wrist_wrench", messages.decode_wrench, ("wrist.wrench_measured",)),
    ("base_command", messages.decode_base_command,
     ("base.velocity_command",)),
    ("arm_command", messages.decode_arm_command, ("arm.position_command",)),
)
"""(channel field, decoder, signal names of its values)."""

ARM_CHANNELS = ("arm_status", "arm_command")
"""The channels whose decoders take the arm's joint count."""

COMMAND_CHANNELS = ("base_command", "arm_command")
"""The channels of one sender at a time (`obeyed`)."""

EXTRA_COLUMNS = {
    "arm.velocity_estimated": "v",  # v1, ..., vn: one a joint
    "hardware.diagnostics": DIAGNOSTICS,
}
"""Column names of the signals that run_log.SIGNALS does not list (as
there: a tuple, or a prefix numbered from 1; run_log.column_names)."""


def read_events(path):
    """Every event of an LCM log file: a dict channel -> list of
    (reception time in s, data bytes), in the log's order."""
    events = defaultdict(list)
    log = lcm.EventLog(str(path), "r")
    try:
        for event in log:
            events[event.channel].append((event.timestamp * 1e-6,
                                          bytes(event.data)))
    finally:
        log.close()
    return events


def _decoded(events, decode):
    """[(reception time, Decoded)] of a channel's good messages, in the
    log's order; bad ones are skipped."""
    good = []
    for stamp, data in events:
        try:
            good.append((stamp, decode(data)))
        except messages.MessageError:
            continue
    return good


def arm_joint_count(events, channels):
    """The robot's arm joint count in a log (`events` of `read_events`):
    that of most of its arm status messages (of its arm commands, without
    any), so that a stray message of another count is skipped, not
    taken for the robot's; None without either."""
    decoders = {name: decode for name, decode, _ in CHANNEL_SIGNALS}
    for name in ARM_CHANNELS:
        counts = Counter(
            decoded.values[0].size for _, decoded in _decoded(
                events.get(getattr(channels, name), []), decoders[name]))
        if counts:
            return counts.most_common(1)[0][0]
    return None


def obeyed(commands, release_time):
    """The commands the robot obeyed of `commands` (a dict channel field
    -> [(reception time, Decoded)] of COMMAND_CHANNELS): on both
    channels, in order of reception, those of one sender at a time, the
    robot's rule (drake_wbc.hardware.codecs.admit, with its
    `release_time`). The same dict with the others left out."""
    merged = sorted((stamp, order, name, decoded)
                    for name, good in commands.items()
                    for order, (stamp, decoded) in enumerate(good))
    lock, kept = SenderLock(), {name: [] for name in commands}
    for stamp, _, name, decoded in merged:
        lock, taken, _ = admit(lock, decoded.sender, stamp, release_time)
        if taken:
            kept[name].append((stamp, decoded))
    return kept


def _bundles(events):
    """(reception times, sender times, dict name -> (n, k) array) of a
    channel of signal_bundle_t; bad messages and signals whose size
    changes are skipped."""
    stamps, times, rows = [], [], []
    for stamp, data in events:
        try:
            _, time, signals = messages.decode_signal_bundle(data)
        except messages.MessageError:
            continue
        stamps.append(stamp)
        times.append(time)
        rows.append(signals)
    signals = {}
    for name in (rows[0] if rows else {}):
        sizes = {len(row.get(name, ())) for row in rows}
        if len(sizes) == 1 and sizes != {0}:
            signals[name] = np.array([row[name] for row in rows])
    return np.asarray(stamps), np.asarray(times), signals


def hold(times, values, grid):
    """`values` (n, k) sampled at `times` (n,), held from each time to the
    next (the first value before the first time), on `grid` (m,)."""
    index = np.searchsorted(times, np.asarray(grid) + LATE, side="right") - 1
    return np.asarray(values)[np.clip(index, 0, len(times) - 1)]


def clock_time(stamps, clock_stamps, clock_times):
    """Reception times `stamps` on the clock whose messages were received
    at `clock_stamps` stamped `clock_times`: interpolated between them
    (a sender slower than real time is followed), extended beyond them
    at the clock's mean rate."""
    stamps = np.asarray(stamps, dtype=float)
    clock_stamps = np.asarray(clock_stamps, dtype=float)
    clock_times = np.asarray(clock_times, dtype=float)
    span = clock_stamps[-1] - clock_stamps[0]
    rate = ((clock_times[-1] - clock_times[0]) / span if span > 0.0
            else 1.0)
    result = np.interp(stamps, clock_stamps, clock_times)
    before, after = stamps < clock_stamps[0], stamps > clock_stamps[-1]
    result[before] = clock_times[0] + rate * (stamps[before]
                                              - clock_stamps[0])
    result[after] = clock_times[-1] + rate * (stamps[after]
                                              - clock_stamps[-1])
    return result


def deployments(times):
    """Slices of a sender clock's samples `times`, one per run of the
    sender: a new run starts where its clock goes back."""
    times = np.asarray(times, dtype=float)
    starts = [0, *(np.flatnonzero(np.diff(times) < 0.0) + 1).tolist()]
    ends = starts[1:] + [len(times)]
    return [slice(a, b) for a, b in zip(starts, ends, strict=True)]


def read_lcm_log(path, options=None, deployment=0):
    """The signals of the LCM log file `path` (see the module's docstring).

    Args:
        path: an LCM log file (lcm-logger's format).
        options: HardwareOptions whose channel names to read (the
            defaults if None).
        deployment: which run of the controller (or, without one, of the
            simulated robot) in the log, 0 for the first; each restart
            of its clock starts a new one (`deployments`).

    Returns:
        RunLog.

    Raises:
        ValueError: naming the file when it holds none of the channels;
            naming the signal when its size is not that of its column
            names (run_log.column_names).
    """
    options = checked_instance("options", options, HardwareOptions,
                               HardwareOptions)
    channels = options.channels
    events = read_events(path)
    bundles = {name: _bundles(events.get(getattr(channels, name), []))
               for name in ("controller", "truth")}
    clock = next((name for name in ("controller", "truth")
                  if len(bundles[name][0])), None)
    if clock is not None:
        runs = deployments(bundles[clock][1])
        if not -len(runs) <= deployment < len(runs):
            raise ValueError(
                f"deployment = {deployment!r} is not allowed: the log holds "
                f"{len(runs)} run(s) of the {clock} clock")
        run = runs[deployment]
        clock_stamps, grid, clock_signals = bundles[clock]
        clock_stamps, grid = clock_stamps[run], grid[run]
        bundles[clock] = (clock_stamps, grid, {
            k: v[run] for k, v in clock_signals.items()})

        def to_clock(stamps):
            return clock_time(stamps, clock_stamps, grid)
    else:
        stamps = [stamp for name, _, _ in CHANNEL_SIGNALS
                  for stamp, _ in events.get(getattr(channels, name), [])]
        if not stamps:
            names = ", ".join(vars(channels).values())
            raise ValueError(
                f"path = {str(path)!r} is not allowed: the log holds none of "
                f"the channels of the protocol ({names})")
        start, step = min(stamps), options.truth_period
        grid = np.arange(0.0, max(stamps) - start + 0.5 * step, step)

        def to_clock(stamps):
            return np.asarray(stamps) - start
    joints = arm_joint_count(events, channels)
    good = {name: _decoded(
        events.get(getattr(channels, name), []),
        functools.partial(decode, num_joints=joints)
        if name in ARM_CHANNELS else decode)
        for name, decode, _ in CHANNEL_SIGNALS}
    good.update(obeyed({name: good[name] for name in COMMAND_CHANNELS},
                       options.sender_release_time))
    signals = {}
    for name, _, names in CHANNEL_SIGNALS:
        if good[name]:
            times = np.array([stamp for stamp, _ in good[name]])
            for i, signal in enumerate(names):
                signals[signal] = hold(
                    to_clock(times),
                    [decoded.values[i] for _, decoded in good[name]], grid)
    for name, (bundle_stamps, bundle_times, bundle) in bundles.items():
        times = bundle_times if name == clock else to_clock(bundle_stamps)
        for signal, values in bundle.items():
            signals[signal] = hold(times, values, grid)
    columns = {name: column_names(name, values.shape[1], EXTRA_COLUMNS)
               for name, values in signals.items()}
    return RunLog(np.asarray(grid, dtype=float), signals, columns)
