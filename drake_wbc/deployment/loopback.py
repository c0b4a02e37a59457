"""The controller over LCM against the simulated robot, in one Diagram.

The robot side (drake_wbc.deployment.robot_side) and the controller side
(drake_wbc.deployment.deploy.add_controller_side) talk over one LCM
object, usually `DrakeLcm("memq://")`, inside one Diagram run on
simulated time: every message really goes through LCM (encoded, sent,
received, checked, decoded) yet the run is deterministic and needs no
network. It checks the deployment's whole path against the in-process
simulation (drake_wbc.experiments.runner), and lets a user rehearse a
deployment::

    loop = build_loopback(scenario, scenario.variants[0])
    log = simulate_loopback(loop)
    log["truth.end_effector_pose"]     # as runner.simulate's log

The log has run_log.SIGNALS: the station's outputs and ground truth as the
robot side had them, the commands as the hardware interface sent them,
the controller's diagnostics; and `hardware.diagnostics` (interface.
DIAGNOSTICS).
"""

import time as wall_clock
from dataclasses import dataclass

from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_wbc.controller.run_log import SIGNALS, SignalLogger
from drake_wbc.deployment.deploy import (
    COMMANDS,
    ControllerSide,
    add_controller_side,
)
from drake_wbc.deployment.robot_side import RobotSide
from drake_wbc.experiments.runner import fault_message
from drake_wbc.experiments.scenario import Scenario
from drake_wbc.hardware.interface import DIAGNOSTICS
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.math.validation import checked_instance

SENT = {"base.velocity_command": "hardware.base_velocity_command",
        "arm.position_command": "hardware.arm_position_command"}
"""The hardware interface's output logged for each command (what it
sent)."""


@dataclass
class Loopback:
    """One run over LCM, built.

    Attributes:
        diagram: robot side, controller side and the logger.
        robot: the RobotSide.
        side: the ControllerSide.
        logger: the run_log.SignalLogger of SIGNALS and
            hardware.diagnostics.
        lcm: the LCM object both sides talk over.
        scenario, variant: what it was built from.
    """

    diagram: object
    robot: RobotSide
    side: ControllerSide
    logger: SignalLogger
    lcm: object
    scenario: Scenario
    variant: object


def build_loopback(scenario, variant=None, options=None, lcm=None):
    """Wires one run of `scenario` over LCM (see the module's docstring).

    Args:
        scenario: a Scenario.
        variant: one of scenario.variants (the first if None).
        options: HardwareOptions (the scenario's, or the defaults); its
            lcm_url is not used (both sides talk over `lcm`).
        lcm: the LCM object (a new DrakeLcm("memq://") if None).

    Returns:
        Loopback.
    """
    scenario = checked_instance("scenario", scenario, Scenario, Scenario)
    variant = variant or scenario.variants[0]
    options = checked_instance("options", options or scenario.hardware,
                               HardwareOptions, HardwareOptions)
    lcm = lcm or DrakeLcm("memq://")
    builder = DiagramBuilder()
    side = add_controller_side(builder, scenario, variant, options, lcm)
    robot = RobotSide(scenario, options, lcm, add_pump=False)
    builder.AddNamedSystem("robot", robot.diagram)
    hardware, controller = side.hardware.diagram, side.controller.diagram
    ports = {}
    for name in SIGNALS:
        if name in COMMANDS:
            port = hardware.GetOutputPort(SENT[name])
        elif robot.diagram.HasOutputPort(name):
            port = robot.diagram.GetOutputPort(name)
        elif controller.HasOutputPort(name):
            port = controller.GetOutputPort(name)
        elif name == "reference_velocity":
            port = side.sources[name].get_output_port()
        else:
            continue
        ports[name] = port
    ports["hardware.diagnostics"] = hardware.GetOutputPort(
        "hardware.diagnostics")
    logger = SignalLogger(builder, ports, scenario.outputs.log_period,
                          columns={"hardware.diagnostics": DIAGNOSTICS})
    diagram = builder.Build()
    diagram.set_name(f"loopback_{variant.name}")
    return Loopback(diagram, robot, side, logger, lcm, scenario, variant)


def make_simulator(loop):
    """A Simulator of `loop` at the scenario's initial state (the robot
    at rest, the controller started from its arm positions), not yet
    initialized."""
    simulator = Simulator(loop.diagram)
    root = simulator.get_mutable_context()
    loop.robot.set_initial_state(root)
    loop.side.initialize(root,
                         loop.robot.station.options.initial_arm_positions)
    return simulator


def simulate_loopback(loop, duration=None, simulator=None):
    """Runs a Loopback from the scenario's initial state for `duration` s
    (the scenario's if None) on simulated time.

    Args:
        loop: a Loopback.
        duration: s.
        simulator: the loop's Simulator from `make_simulator` (a new one
            if None).

    Returns:
        RunLog (run_log.SIGNALS and hardware.diagnostics).
    """
    duration = loop.scenario.duration if duration is None else duration
    simulator = simulator or make_simulator(loop)
    root = simulator.get_mutable_context()
    simulator.Initialize()
    started = wall_clock.perf_counter()
    simulator.AdvanceTo(duration)
    elapsed = wall_clock.perf_counter() - started
    # Deliver what was sent at the last instant to the in-process
    # subscribers (the Diagram's own would take it at the next step).
    loop.lcm.HandleSubscriptions(0)
    return loop.logger.run_log(root, duration / max(elapsed, 1e-9),
                               fault_message(loop.robot.station, root))

