"""The controller against the robot over LCM, in real time.

`add_controller_side` puts into a DiagramBuilder what runs on the
controller's computer: the controller Diagram of drake_wbc.controller.diagram
(the very one a simulation uses), the task's sources of the scenario, the
HardwareInterface in place of the simulated station, and a publisher of
the controller's diagnostics for the logs. `deploy` runs it against the
robot: it waits for the robot's first status, starts the controller from
the measured arm positions on the arrival of a base state (so that its
ticks follow the robot's status; none within its watchdog limit, and it
starts nothing: TimeoutError), paces the Simulator to the wall clock
for the scenario's duration, and stops cleanly (zero base velocity, and
the arm braked within its limits and held, sent before returning) at the
end, on a stop request (Ctrl-C in `drake-wbc deploy`) or on an error.
"""

import time
from dataclasses import dataclass

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_wbc.controller.diagram import HARDWARE_INPUTS
from drake_wbc.controller.run_log import SIGNALS, advance_times
from drake_wbc.controller.task import add_controller
from drake_wbc.experiments.scenario import (
    Scenario,
    controller_arm,
    controller_for,
)
from drake_wbc.hardware import messages
from drake_wbc.hardware.codecs import SignalBundleEncoder, message_formats
from drake_wbc.hardware.interface import (
    DIAGNOSTICS,
    HardwareInterface,
    add_publisher,
)
from drake_wbc.hardware.options import STATUS_CHANNELS, HardwareOptions
from drake_wbc.hardware.safety import WallClock, stop_arm
from drake_wbc.math.validation import (
    checked_instance,
    positive,
    positive_duration,
)

COMMANDS = ("base.velocity_command", "arm.position_command")
"""The controller's outputs that go to the robot."""

LONGEST_DEPLOYMENT = 24 * 3600.0
"""s: the longest deployment `deploy` accepts (a day). A deployment keeps
no log of its own, unlike a simulated run (its diagnostics go out over
LCM, for an lcm-logger beside it to write to disk;
drake_wbc.math.validation.LONGEST_RUN bounds a simulated run's logs),
and its memory does not grow with its length: against `drake-wbc
robot-sim` over UDP, from 30 to 240 s of run, its Python heap stayed
flat and its resident memory within 0.2 MB (the same to the kB on a
quiet machine; on a loaded one, a single step of 164 kB). The bound
catches a duration that is no length of a robot's work (a typo of
1e300 s)."""

STOP_REPEATS = 3
"""How many times the stop commands are sent (UDP may drop one)."""


@dataclass
class ControllerSide:
    """The controller side, added to a builder.

    Attributes:
        hardware: the HardwareInterface.
        controller: the drake_wbc.controller.diagram.Controller.
        sources: dict task input name -> its source system.
        bundle: the SignalBundleEncoder of the diagnostics.
        scenario, variant, options: what it was built from.
    """

    hardware: HardwareInterface
    controller: object
    sources: dict
    bundle: SignalBundleEncoder
    scenario: Scenario
    variant: object
    options: HardwareOptions

    def initialize(self, root_context, arm_positions,
                   base_velocity=(0.0, 0.0, 0.0)):
        """Starts the controller from the robot's measured state and holds
        the arm there until the controller's first command."""
        self.controller.initialize(root_context, arm_position=arm_positions,
                                   base_velocity=base_velocity)
        self.hardware.set_arm_command(root_context, arm_positions)

    def set_time_offset(self, root_context, offset):
        """Stamps the messages sent with 1e6 (t + offset) microseconds."""
        self.hardware.set_time_offset(root_context, offset)
        self.bundle.set_time_offset(root_context, offset)


def add_controller_side(builder, scenario, variant=None, options=None,
                        lcm=None, wall_clock=None):
    """Adds the controller, the task sources, the hardware interface and
    the diagnostics publisher to `builder` (see the module's docstring).

    Args:
        builder: a DiagramBuilder.
        scenario: the Scenario (its controller parameters and task).
        variant: one of scenario.variants (the first if None).
        options: HardwareOptions (the scenario's, or the defaults, if
            None).
        lcm: the DrakeLcmInterface to talk over.
        wall_clock: the WallClock of a run in real time (`deploy`), which
            the hardware interface's guard reads at every check; None on
            simulated time.

    Returns:
        ControllerSide.
    """
    scenario = checked_instance("scenario", scenario, Scenario, Scenario)
    variant = variant or scenario.variants[0]
    options = checked_instance("options", options or scenario.hardware,
                               HardwareOptions, HardwareOptions)
    h = scenario.controller.time_step
    if abs(options.publish_period - h) > 1e-12:
        raise ValueError(
            f"hardware.publish_period = {options.publish_period!r} s is not "
            f"allowed with controller.time_step = {h!r} s: the commands go "
            "out once a control period, so they must be equal")
    arm = controller_arm(scenario)
    params = controller_for(scenario, variant)
    # Until the robot's first status: the shipped robot's scenario start,
    # or another robot's home.
    hardware = HardwareInterface(
        options, lcm, None if scenario.robot
        else scenario.station.initial_arm_positions, robot=arm,
        wall_clock=wall_clock,
        arm_follow_tolerance=params.safety.arm_follow_tolerance)
    builder.AddNamedSystem("hardware", hardware.diagram)
    controller, sources = add_controller(
        builder, params, scenario.task,
        hardware.diagram, arm=hardware.arm)
    # The watchdog's stop stops the controller too (HARDWARE_INPUTS).
    for name in HARDWARE_INPUTS:
        builder.Connect(hardware.diagram.GetOutputPort(name),
                        controller.diagram.GetInputPort(name))
    ports = {name: controller.diagram.GetOutputPort(name)
             for name in SIGNALS
             if name not in COMMANDS
             and controller.diagram.HasOutputPort(name)}
    ports["reference_velocity"] = sources["reference_velocity"] \
        .get_output_port()
    ports["hardware.diagnostics"] = hardware.diagram.GetOutputPort(
        "hardware.diagnostics")
    bundle = builder.AddNamedSystem("encoder.controller", SignalBundleEncoder(
        {name: port.size() for name, port in ports.items()}))
    for name, port in ports.items():
        builder.Connect(port, bundle.GetInputPort(name))
    # At offset 0, as the runner's loggers sample: the values of the
    # control period that ends.
    publisher = add_publisher(builder, options.channels.controller, lcm,
                              "publisher.controller", options.truth_period)
    builder.Connect(bundle.GetOutputPort("message"),
                    publisher.get_input_port())
    return ControllerSide(hardware, controller, sources, bundle, scenario,
                          variant, options)


def wait_for_status(lcm, options, num_joints, timeout=None, stop=None):
    """Waits for a good message on every status channel on `lcm` (base
    state, arm status, wrist wrench, obstacle points: the controller
    depends on each).

    Args:
        lcm: a DrakeLcmInterface.
        options: HardwareOptions (channels; startup_timeout if `timeout`
            is None).
        num_joints: the arm's joint count (an arm status of another size
            is not good).
        timeout: s of wall clock.
        stop: a callable; waiting ends early when it returns True.

    Returns:
        the first value of each channel's message, in the order of
        STATUS_CHANNELS (base state (6,), arm positions (n,), wrench
        (6,), points (M, 2)), or None if stopped.

    Raises:
        TimeoutError: naming the channels still without a good message,
            the URL, and for each channel whose messages were refused
            how many and why (the last refusal's MessageError).
    """
    timeout = options.startup_timeout if timeout is None else positive(
        "timeout", timeout)
    formats = message_formats(num_joints, options.max_obstacle_points)
    decoders = {getattr(options.channels, name): formats[name].decode
                for name in STATUS_CHANNELS}
    received, waiting = {}, [True]
    rejected = {}  # channel -> (count, the last MessageError)

    def handler_for(channel):
        def handle(data):
            if not waiting[0]:
                return
            try:
                received[channel] = decoders[channel](data).values[0]
            except messages.MessageError as error:
                count = rejected.get(channel, (0, None))[0]
                rejected[channel] = (count + 1, error)
        return handle

    # (pydrake's Subscribe offers no unsubscribe: the handlers stay, idle.)
    for channel in decoders:
        lcm.Subscribe(channel, handler_for(channel))
    deadline = time.monotonic() + timeout
    while len(received) < len(decoders):
        if stop is not None and stop():
            return None
        if time.monotonic() > deadline:
            silent = sorted(set(decoders) - set(received))
            url = getattr(lcm, 'get_lcm_url', lambda: '?')()
            reasons = [f"{channel}: {rejected[channel][0]} messages "
                       f"rejected: {rejected[channel][1]}"
                       for channel in silent if channel in rejected]
            if set(silent) - set(rejected):
                reasons.append("is the robot (or `drake-wbc robot-sim`) "
                               "running on this LCM URL?")
            raise TimeoutError(
                f"no status on {', '.join(silent)} within "
                f"{timeout:g} s on {url}: {'; '.join(reasons)}")
        lcm.HandleSubscriptions(50)
    waiting[0] = False
    return tuple(received[channel] for channel in decoders)


def wait_for_next(lcm, channel, timeout):
    """Blocks until the next message on `channel` (or `timeout` s of
    wall clock); returns True if one came.

    Its handler stays subscribed to `lcm` (pydrake's Subscribe offers no
    unsubscribe), which a deployment then pumps for as long as it runs:
    it sets a flag, and keeps nothing of the messages.
    """
    arrived = [False]

    def handle(data):
        arrived[0] = True

    lcm.Subscribe(channel, handle)
    lcm.HandleSubscriptions(0)
    arrived[0] = False
    deadline = time.monotonic() + timeout
    while not arrived[0] and time.monotonic() < deadline:
        lcm.HandleSubscriptions(5)
    return arrived[0]


def send_stop(lcm, options, arm_positions, sender, utime,
              arm_velocity=None, limits=None):
    """Sends zero base velocity and `arm_positions` (the arm held) on the
    command channels, from `sender`, STOP_REPEATS times, stamped utime,
    utime + 1, ...: `utime` later than the run's last command on the
    run's time base (HardwareInterface.command_utime), so that the robot
    takes each in sequence (a stamp of the wall clock is ahead of the
    run's by as much as the controller fell behind, and beyond the
    protocol's clock_tolerance the robot rejects it).

    An arm still moving is not held at once (that would ask its servo for
    an unbounded deceleration): given `arm_velocity`, the rate of
    `arm_positions` (the command guard's), and `limits` (its Limits), the
    arm first slows down from it within its acceleration limit
    (drake_wbc.hardware.safety.stop_arm), one command a publish period of
    the wall clock, each with zero base velocity and stamped a period
    after the one before, and is held where it comes to rest.

    Returns:
        (n,) the arm positions held.
    """
    utime = int(utime)
    held = np.array(arm_positions, dtype=float)
    ramp = []
    if arm_velocity is not None:
        # A rate not known (not finite) cannot be braked from: held at
        # once (braking from NaN never came to rest, and the stop hung).
        velocity = np.array(arm_velocity, dtype=float)
        velocity[~np.isfinite(velocity)] = 0.0
        while np.any(velocity != 0.0):
            held, velocity = stop_arm(held, velocity,
                                      options.publish_period, limits)
            ramp.append(held)
    step = int(round(1e6 * options.publish_period))
    for i, positions in enumerate(ramp):
        if i:
            time.sleep(options.publish_period)
        _publish_stop(lcm, options, positions, sender, utime + i * step)
    utime += len(ramp) * step
    for i in range(STOP_REPEATS):
        _publish_stop(lcm, options, held, sender, utime + i)
        time.sleep(0.002)
    return held


def _publish_stop(lcm, options, arm_positions, sender, utime):
    """Sends zero base velocity and `arm_positions`, stamped `utime`."""
    lcm.Publish(options.channels.base_command,
                messages.encode_base_command(utime, np.zeros(3), sender))
    lcm.Publish(options.channels.arm_command,
                messages.encode_arm_command(utime, arm_positions, sender))


@dataclass
class DeployResult:
    """How a deployment ended.

    Attributes:
        time: the controller's clock at the end, s.
        stopped: True if a stop request ended it early.
        real_time_factor: controller time over wall-clock time.
        diagnostics: dict DIAGNOSTICS entry -> its value at the end.
        held_arm_positions: the arm command sent with the stop.
    """

    time: float
    stopped: bool
    real_time_factor: float
    diagnostics: dict
    held_arm_positions: np.ndarray


def deploy(scenario, variant=None, options=None, duration=None, lcm=None,
           stop=None, realtime_rate=1.0, chunk=0.05, on_start=None,
           on_progress=None):
    """Runs the controller against the robot over LCM (see the module).

    Args:
        scenario: a Scenario.
        variant: one of its variants (the first if None).
        options: HardwareOptions (the scenario's, or the defaults).
        duration: controller time to run, s, at most LONGEST_DEPLOYMENT
            (the scenario's if None).
        lcm: a DrakeLcmInterface (a DrakeLcm of options.lcm_url if None).
        stop: a callable polled every `chunk` s of controller time; True
            ends the run there (the stop commands are then sent at once).
        realtime_rate: the Simulator's target real-time rate, > 0 and
            finite.
        chunk: s of controller time between polls of `stop`.
        on_start: called with the measured arm positions when the
            controller starts.
        on_progress: called with the controller's time every `chunk` s
            of it.

    Returns:
        DeployResult, or None if stopped before the robot answered.
    """
    options = checked_instance("options", options or scenario.hardware,
                               HardwareOptions, HardwareOptions)
    duration = scenario.duration if duration is None else positive_duration(
        "duration", duration, longest=LONGEST_DEPLOYMENT)
    realtime_rate = positive("realtime_rate", realtime_rate)
    lcm = lcm or DrakeLcm(options.lcm_url)
    wall_clock = WallClock(realtime_rate)
    builder = DiagramBuilder()
    side = add_controller_side(builder, scenario, variant, options, lcm,
                               wall_clock)
    diagram = builder.Build()
    diagram.set_name("deployment")
    # The waits listen where the receivers do, on the bus that the
    # diagram's LcmPump polls from Python: a handler left on `lcm` itself
    # would be called by the Simulator without the GIL (see LcmPump).
    bus = side.hardware.receiving
    status = wait_for_status(bus, options, side.hardware.arm.num_joints,
                             stop=stop)
    if status is None:
        return None
    state, arm = status[:2]
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    side.initialize(root, arm, base_velocity=state[3:])
    side.set_time_offset(root, time.time())
    guard = side.hardware.systems["guard"]
    held = np.asarray(arm, dtype=float)
    stopped = False
    simulator.set_target_realtime_rate(realtime_rate)
    # Start the clock just after a base state arrives, so that each tick
    # follows the robot's status by a fraction of a period and the
    # commands reach the robot well before it samples them.
    limit = options.watchdog_limits.base_state
    if not wait_for_next(bus, options.channels.base_state, limit):
        # Started anyway, the controller took the last state heard for a
        # fresh one and sent commands until the watchdog tripped.
        raise TimeoutError(
            f"no status on {options.channels.base_state} for {limit:g} s "
            "(its watchdog limit) after the first: the robot stopped "
            "sending its base state before the start; nothing was sent")
    side.hardware.discard_pending()
    started = time.perf_counter()
    try:
        simulator.Initialize()
        if on_start is not None:
            on_start(held)
        for t in advance_times(duration, chunk):
            if stop is not None and stop():
                stopped = True
                break
            simulator.AdvanceTo(t)
            if on_progress is not None:
                on_progress(t)
    finally:
        # Stamped after the run's last command, on its time base; the
        # arm brakes from the rate it was last sent.
        sent = guard.stored(guard.GetMyContextFromRoot(root))
        held = send_stop(lcm, options, sent.arm, side.hardware.sender,
                         utime=side.hardware.command_utime(root) + 1,
                         arm_velocity=sent.arm_velocity,
                         limits=guard.limits)
    elapsed = time.perf_counter() - started
    values = side.hardware.diagram.GetOutputPort(
        "hardware.diagnostics").Eval(
            side.hardware.diagram.GetMyContextFromRoot(root))
    return DeployResult(root.get_time(), stopped,
                        root.get_time() / max(elapsed, 1e-9),
                        dict(zip(DIAGNOSTICS, values.tolist(), strict=True)),
                        np.array(held))
