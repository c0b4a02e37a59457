"""The pHRI admittance loop, linearised: the controller's admittance
against the tool, the person's hand and the wrist sensor.

In the intuitive pHRI mode (S_hri = 1) the whole body's velocity command
is the admittance of eq. (cdmp-wb), V = k_hri F_ext (behind the lag of
`whole_body_cdmp.hri_time_constant` T, math.cdmp.admittance_filter_model,
when T > 0). The wrist sensor that measures F_ext also weighs what the
command does to the tool: its inertia, the hand's mass that moves with it
and the hand's spring and damper. So the admittance closes a loop::

    wrist.wrench_measured ─► controller ─► arm.position_command
            ▲                (estimator, admittance filter,        │
            │                 whole-body CDMP, split, arm CDMP,    │
            │                 the arm's velocity controller)       ▼
    wrist sensor (sampled) ◄─ weld reaction ◄─ plant ◄─ arm driver
                              (tool, hand mass, hand spring to the world)

This module linearises both halves at the start of the `phri` scenario's
stage A (S_hri = 1, the arm alone, sigma = 1, the base at rest) and
combines them at the control period h:

- the controller part (`linearize_controller_part`): the real controller
  Diagram (drake_wbc.controller.diagram.build_controller with the
  scenario's parameters, experiments.scenario.controller_for), its period
  map over one control period (analysis.period_map.linearize_period_map)
  from `wrist.wrench_measured` to `arm.position_command`, the other inputs
  at their rest values (S_hri = 1, zero reference velocity, the station's
  rest measurements, the tool's weight as the reading,
  stages.wrench.tool_weight_reading);
- the plant part (`linearize_plant_part`): the station's robot alone
  (analysis.plant_chain: no scene graph, the station's servo gains, the
  base's velocity servo held at rest) driven through the station's arm
  driver, read by the wrist sensor (the plant's reaction at the sensor's
  weld, WeldWrench, sampled at the sensor's rate like
  WristForceTorqueSensor, without its noise and quantisation), with the
  hand as linear parts: a point mass of hand.mass welded at the tool
  centre point (for a point mass the same as the station's ball
  constraint; the person carries its weight) and a spring-damper
  (LinearBushingRollPitchYaw, the hand's K and D in translation, nothing
  in rotation) to a world point at the tool centre point's rest position.
  The person's intention (station.hand.HandIntention) is held: it follows
  the tool with a reaction time of 0.3 s (0.5 Hz), slower than the loop's
  gain crossover (2 to 5 Hz) and far slower than the modes that go
  unstable (the mount's rocking at 4 to 6 Hz, the tool's inertial
  reaction at the 50 Hz Nyquist rate), so over the band that decides
  stability the hand is its spring and damper to a fixed point (below
  0.5 Hz the real hand follows the tool, which the model does not);
- the arm's measured positions are fed back too (the estimator removes
  the tool's weight at the measured configuration): the loop is opened
  at the wrist's reading alone (`reading_loop`);
- the loop (`admittance_loop`): the two in series, L = P C from the
  reading back to the reading (6 by 6, the sensor's frame turned into
  T_b for the per-axis responses), the closed loop's eigenvalues, the
  largest stable k_hri (bisection on k_hri, the controller relinearised;
  stable while the closed loop's spectral radius is below 1) and the
  gain and phase margins per translational axis at the scenario's k_hri,
  where the open loop is stable. An open loop with a pole outside the
  unit circle has no margins (the Nyquist criterion would need its
  unstable poles counted), only its largest stable k_hri: at the
  paper's T = 0 with the inertia compensation (|z| = 1.102 at 38.6 Hz,
  1.093 at 38.8 Hz with the stiff hand) the loop that stays closed, the
  estimator's removal of the tool's inertial reaction from the arm's
  measured positions through the admittance to the arm's command, is
  unstable by itself at k_hri = 0.05 (controller and plant apart are
  stable, and so is that loop at k_hri = 0.005 or without the
  compensation).

Checked against the simulated station (tests/test_admittance_loop.py):
the `phri` scenario's stage A oscillates at 1.3 times the largest stable
k_hri and is calm at 0.7 times it, for the relaxed hand with and without
the admittance's lag and for the stiff hand with it.

The scalar loop of one axis is L_i = -(R P C R^T)_ii (negative feedback,
as frequency.stability_margins takes it; the other axes open), so its
margins are those of one axis; the largest stable k_hri is the whole
loop's (all six axes closed), the number that the simulation checks.
"""

from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    LinearBushingRollPitchYaw,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Demultiplexer,
    LinearSystem,
    MatrixGain,
    Multiplexer,
    ZeroOrderHold,
)

from drake_wbc.analysis.frequency import response_function, stability_margins
from drake_wbc.analysis.period_map import linearize_period_map
from drake_wbc.analysis.plant_chain import (
    add_robot_plant,
    station_at_rest,
    station_equilibrium,
)
from drake_wbc.controller import build_controller
from drake_wbc.experiments.scenario import (
    controller_arm,
    controller_for,
    scenario_station,
)
from drake_wbc.math.kinematics import twist_rotation
from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.stages.arm_control import (
    TWIST_SIZE,
    ArmCartesianVelocityController,
)
from drake_wbc.stages.support import define_stage
from drake_wbc.stages.wrench import sensor_rotation_in_base, tool_weight_reading
from drake_wbc.station.driver_dynamics import interpolated_command
from drake_wbc.station.force_torque import WeldWrench
from drake_wbc.station.scene import HandImpedance
from drake_wbc.station.simulation import add_desired_states, arm_state_output

STIFF_HAND = HandImpedance(stiffness=1000.0, damping=30.0, mass=0.2)
"""A stiff grip: the top of the range of a person's hand impedance in a
maintained posture (README, pHRI)."""

AXES = ("x", "y", "z")
"""The translational axes of T_b of the per-axis loops."""


@define_stage("PeriodicArmDriver_")
def PeriodicArmDriver_(T):
    class Impl(LeafSystem_[T]):
        """The station's arm driver (station.drivers.ArmPositionDriver:
        sample the command every command period, interpolate linearly
        towards it, driver_dynamics.interpolated_command) with a state
        that is periodic in time, for the period map.

        ::

                                   ┌───────────────────┐
            arm.position_command ─►│ PeriodicArmDriver ├──► desired_state
                                   └───────────────────┘

        The station's driver keeps the sample's time t_k in its state,
        which grows from period to period; here t_k is the last multiple
        of the command period at or before the context's time (the
        driver's samples run at offset 0 from t = 0, so it is the same
        number), and the state is [q_from; q_to] alone.

        Args:
            params: ArmDriverParameters (its command_period is used).
            size: n, the arm's joints.
        """

        def _construct(self, params, size, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params, self.size = params, int(size)
            self._command = self.DeclareVectorInputPort(
                "arm.position_command", self.size)
            self.DeclareDiscreteState(2 * self.size)
            period = positive("params.command_period",
                              params.command_period)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0,
                                                    self._update)
            self.DeclareVectorOutputPort(
                "desired_state", 2 * self.size, self._desired_state)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other.size,
                            converter=converter)

        def _sample_time(self, context):
            # The sample the state holds: the last one strictly before
            # the context's time. At a sample instant the plant's and
            # this driver's updates read the state before the update,
            # the previous sample's (where the station's driver, which
            # keeps t_k in its state, is at the end of its ramp); after
            # the update this rule gives the end of the new ramp, which
            # no update reads before the next step.
            t = context.get_time()
            value = t.value() if hasattr(t, "value") else float(t)
            period = self.params.command_period
            return period * (np.ceil(value / period - 1e-9) - 1.0)

        def _interpolated(self, context):
            state = context.get_discrete_state_vector().CopyToVector()
            return interpolated_command(
                np.concatenate([state, [self._sample_time(context)]]),
                context.get_time(), self.params.command_period)

        def _update(self, context, discrete_state):
            reached = self._interpolated(context)[0]
            discrete_state.set_value(np.concatenate(
                [reached, self._command.Eval(context)]))

        def _desired_state(self, context, output):
            q_d, v_d = self._interpolated(context)
            output.SetFromVector(np.concatenate([q_d, v_d]))

    return Impl


PeriodicArmDriver = PeriodicArmDriver_[None]


def _add_welded_hand(plant, model, hand, X_WT):
    """The hand as a point mass welded at the tool centre point, without
    weight (the person carries it), and its spring-damper to the world
    pose X_WT where it rests."""
    instance = plant.AddModelInstance("hand")
    body = plant.AddRigidBody("hand", instance, SpatialInertia(
        hand.mass, np.zeros(3), UnitInertia(0.0, 0.0, 0.0)))
    plant.WeldFrames(model.tcp_frame, body.body_frame(), RigidTransform())
    plant.set_gravity_enabled(instance, False)
    anchor = plant.AddFrame(FixedOffsetFrame(
        "hand_rest", plant.world_frame(), X_WT))
    plant.AddForceElement(LinearBushingRollPitchYaw(
        anchor, body.body_frame(), np.zeros(3), np.zeros(3),
        np.full(3, hand.stiffness), np.full(3, hand.damping)))


def build_plant_part(station, hand):
    """The plant part as a Diagram (module docstring): input
    arm.position_command (n), output wrench_measured (6, the sensor's
    frame, like the station's wrist.wrench_measured without noise).

    Args:
        station: the SimulatedStation whose robot, servo gains, arm driver
            and sensor rate are used.
        hand: HandImpedance of the hand on the tool (its reaction time is
            not used: the person's intention is held).

    Returns:
        (diagram, plant, model): the Diagram, its MultibodyPlant and the
        robot's RobotModel in it.
    """
    hand = checked_instance("hand", hand, HandImpedance, None)
    builder = DiagramBuilder()
    add = builder.AddNamedSystem
    plant, model = add_robot_plant(builder, station)
    options = station.options
    _, settled = station_at_rest(station)
    X_WT = station.model.tcp_frame.CalcPoseInWorld(settled)
    _add_welded_hand(plant, model, hand, X_WT)
    plant.Finalize()
    driver = add("arm_driver", PeriodicArmDriver(
        options.arm, model.num_arm_joints))
    base_hold = add("base_hold", ConstantVectorSource(np.zeros(6)))
    weld = add("weld_wrench", WeldWrench(
        plant, model.ft_sensor_joint, model.ft_measurement_frame))
    sensor = add("wrist", ZeroOrderHold(1.0 / options.wrist.rate, 6))
    connect = builder.Connect
    add_desired_states(builder, plant, model, base_hold.get_output_port(),
                       driver.get_output_port())
    connect(plant.get_reaction_forces_output_port(),
            weld.GetInputPort("reaction_forces"))
    connect(weld.GetOutputPort("wrench"), sensor.get_input_port())
    builder.ExportInput(driver.get_input_port(), "arm.position_command")
    n = model.num_arm_joints
    arm_state, _ = arm_state_output(builder, plant, model)
    positions = add("arm_positions", MatrixGain(np.eye(n, 2 * n)))
    connect(arm_state, positions.get_input_port())
    both = add("measured", Multiplexer([6, n]))
    connect(sensor.get_output_port(), both.get_input_port(0))
    connect(positions.get_output_port(), both.get_input_port(1))
    builder.ExportOutput(sensor.get_output_port(), "wrench_measured")
    builder.ExportOutput(positions.get_output_port(), "arm.position_measured")
    builder.ExportOutput(both.get_output_port(), "measured")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    diagram = builder.Build()
    diagram.set_name("admittance_plant")
    return diagram, plant, model


def plant_part_context(station, diagram, plant, model):
    """The plant part's Context at the station's static equilibrium: the
    robot's positions the station's (set_initial_state), at rest, the arm
    driver holding the arm's command, the sensor's reading taken, the
    command input fixed at the initial arm positions."""
    options = station.options
    context = diagram.CreateDefaultContext()
    station_equilibrium(station, plant, model, context)
    q_cmd = np.asarray(options.initial_arm_positions, dtype=float)
    driver = diagram.GetSubsystemByName("arm_driver")
    driver.GetMyMutableContextFromRoot(context).SetDiscreteState(
        np.concatenate([q_cmd, q_cmd]))
    diagram.GetInputPort("arm.position_command").FixValue(context, q_cmd)
    weld = diagram.GetSubsystemByName("weld_wrench")
    sensor = diagram.GetSubsystemByName("wrist")
    reading = weld.GetOutputPort("wrench").Eval(
        weld.GetMyContextFromRoot(context))
    sensor.GetMyMutableContextFromRoot(context).SetDiscreteState(reading)
    return context


def linearize_plant_part(station, hand, period):
    """The plant part's LinearSystem from the arm's position command (n)
    to what the controller measures, [the sensor's reading (6, sensor
    frame); the arm's joint positions (n)], the AutoDiff period map
    over `period` (the control period) around the station's static
    equilibrium. Returns (linear, rest_reading)."""
    diagram, plant, model = build_plant_part(station, hand)
    context = plant_part_context(station, diagram, plant, model)
    linear = linearize_period_map(
        diagram, context, period, diagram.GetInputPort(
            "arm.position_command"), diagram.GetOutputPort("measured"))
    return linear, diagram.GetOutputPort("wrench_measured").Eval(context)


def rest_measurements(station):
    """What the station reports at its static equilibrium: (base.
    state_estimated (6), arm.position_measured (n))."""
    root, _ = station_at_rest(station)
    return tuple(station.diagram.GetOutputPort(name).Eval(root).copy()
                 for name in ("base.state_estimated",
                              "arm.position_measured"))


def linearize_controller_part(params, arm, base_state, arm_positions,
                              command_start):
    """The controller part: the LinearSystem of the controller built from
    `params` (ControllerParameters) on `arm` (ArmKinematics) from what it
    measures, [wrist.wrench_measured (6); arm.position_measured (n)], to
    arm.position_command (n), its period map
    over params.time_step, at the rest of stage A of pHRI: S_hri = 1, zero
    reference velocity, the station's rest measurements `base_state` (6)
    and `arm_positions` (n), and the tool's weight as the wrist's reading
    (so that F_ext = 0); the controller started as the runner starts it
    (its arm command at `command_start` (n), the scenario's initial arm
    positions), its estimator's memory at the measured positions.
    Returns (linear, controller)."""
    controller = build_controller(params, arm)
    n = controller.arm.num_joints
    builder = DiagramBuilder()
    builder.AddNamedSystem("controller", controller.diagram)
    split = builder.AddNamedSystem("measured", Demultiplexer([6, n]))
    builder.ExportInput(split.get_input_port(), "measured")
    for i, name in enumerate(("wrist.wrench_measured",
                              "arm.position_measured")):
        builder.Connect(split.get_output_port(i),
                        controller.diagram.GetInputPort(name))
    for i in range(controller.diagram.num_input_ports()):
        port = controller.diagram.get_input_port(i)
        if port.get_name() not in ("wrist.wrench_measured",
                                   "arm.position_measured"):
            builder.ExportInput(port, port.get_name())
    builder.ExportOutput(controller.diagram.GetOutputPort(
        "arm.position_command"), "arm.position_command")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    controller.initialize(context, arm_position=command_start)
    controller.stages["wrench"].set_arm_position(
        controller.stages["wrench"].GetMyMutableContextFromRoot(context),
        arm_positions)
    fix = {"base.state_estimated": base_state,
           "measured": np.concatenate([tool_weight_reading(
               controller.arm, arm_positions), arm_positions]),
           "reference_velocity": np.zeros(6),
           "phri_switch": np.ones(1)}
    for name, value in fix.items():
        diagram.GetInputPort(name).FixValue(context, value)
    # A few ticks at rest, so that the input guard holds these inputs as
    # its last valid samples; then back to t = 0 (every stage's updates
    # are at offset 0, so only the guard's clock of valid time has moved).
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(3 * params.time_step)
    context.SetTime(0.0)
    return (linearize_period_map(
        diagram, context, params.time_step,
        diagram.GetInputPort("measured"),
        diagram.GetOutputPort("arm.position_command"), drop_clocks=True),
        controller)


def series(controller, plant):
    """The loop broken at the reading: the LinearSystem (at their common
    period) of `controller` (reading -> command) followed by `plant`
    (command -> reading), state [x_c; x_p]."""
    h = controller.time_period()
    if abs(plant.time_period() - h) > 1e-12:
        raise ValueError(f"plant.time_period() = {plant.time_period()!r} is "
                         f"not allowed: must equal the controller's {h!r}")
    Ac, Bc, Cc, Dc = controller.A(), controller.B(), controller.C(), \
        controller.D()
    Ap, Bp, Cp, Dp = plant.A(), plant.B(), plant.C(), plant.D()
    nc, n_p = Ac.shape[0], Ap.shape[0]
    A = np.block([[Ac, np.zeros((nc, n_p))], [Bp @ Cc, Ap]])
    B = np.vstack([Bc, Bp @ Dc])
    C = np.hstack([Dp @ Cc, Cp])
    D = Dp @ Dc
    return LinearSystem(A, B, C, D, h)


def close_channels(loop, channels):
    """`loop` (a square LinearSystem, inputs and outputs the same signals)
    with the inputs `channels` fed back as their outputs, u_i = y_i: the
    LinearSystem of the other channels."""
    A, B, C, D = loop.A(), loop.B(), loop.C(), loop.D()
    m = B.shape[1]
    closed = np.zeros(m, dtype=bool)
    closed[list(channels)] = True
    open_ = ~closed
    B1, B2 = B[:, open_], B[:, closed]
    C1, C2 = C[open_], C[closed]
    D11, D12 = D[np.ix_(open_, open_)], D[np.ix_(open_, closed)]
    D21, D22 = D[np.ix_(closed, open_)], D[np.ix_(closed, closed)]
    M = np.linalg.inv(np.eye(D22.shape[0]) - D22)
    return LinearSystem(A + B2 @ M @ C2, B1 + B2 @ M @ D21,
                        C1 + D12 @ M @ C2, D11 + D12 @ M @ D21,
                        loop.time_period())


def reading_loop(loop):
    """`loop` (measured -> measured: the wrist's reading (6), then the
    arm's positions) broken at the wrist's reading alone, the arm's
    positions fed back (`close_channels`): reading -> reading, 6 by 6,
    the sensor's frame."""
    return close_channels(loop, range(6, loop.B().shape[1]))


def closed_loop_matrix(loop):
    """The closed loop's A of `loop` (series: reading -> reading) with the
    reading fed back as measured, u = y (the real loop's sign)."""
    A, B, C, D = loop.A(), loop.B(), loop.C(), loop.D()
    feedthrough = np.linalg.solve(np.eye(D.shape[0]) - D, C)
    return A + B @ feedthrough


@dataclass
class LoopResult:
    """One case of the admittance loop.

    Attributes:
        label: the case's name.
        hand: the HandImpedance.
        inertia_compensation: the estimator's setting.
        time_constant: hri_time_constant T, s.
        k_hri: the scenario's gain.
        loop: the loop broken at the wrist's reading at k_hri (reading
            -> reading, 6, the sensor's frame; `reading_loop`).
        rotation: R6 (6, 6) from the sensor's frame to T_b.
        spectral_radius: of the closed loop at k_hri.
        limit: the largest stable k_hri in K_HRI_SEARCH (nan if the
            loop is unstable at its lowest, its highest if stable there).
        limit_frequency: Hz, of the closed loop's least stable
            eigenvalue just above the limit (nan where there is none).
        open_loop_pole: the least stable pole of `loop` (drifts aside,
            `least_stable`; 0 if it has none).
        margins: per axis of T_b (AXES), StabilityMargins of
            L_i = -(R P C R^T)_ii at k_hri; empty where the open loop is
            unstable (`margins_unavailable`).
    """

    label: str
    hand: HandImpedance
    inertia_compensation: bool
    time_constant: float
    k_hri: float
    loop: LinearSystem
    rotation: np.ndarray
    spectral_radius: float
    limit: float
    limit_frequency: float
    open_loop_pole: complex
    margins: dict

    @property
    def margins_unavailable(self):
        """Why the loop has no gain and phase margins: "open loop
        unstable: |z| = ... at ... Hz" if `open_loop_pole` lies on or
        outside the unit circle, else "" (it has them)."""
        pole = self.open_loop_pole
        if abs(pole) < 1.0:
            return ""
        hertz = abs(np.angle(pole)) / (2 * np.pi * self.loop.time_period())
        return f"open loop unstable: |z| = {abs(pole):.3f} at {hertz:.3g} Hz"

    def axis_loop(self, axis):
        """omega (rad/s, a float or an array) -> L_axis (complex, one per
        omega), `axis` in AXES: -(R (C (zI - A)^-1 B + D) R^T)_axis,axis
        of the loop, z = e^(j omega h)."""
        i = AXES.index(axis)
        R, lin = self.rotation, self.loop
        response = response_function(
            lin.A(), lin.B() @ R.T[:, i:i + 1], (R @ lin.C())[i:i + 1],
            (R @ lin.D() @ R.T)[i:i + 1, i:i + 1], lin.time_period())
        return lambda omega: -response(omega)[:, 0, 0]

    def axis_margins(self, axis, omega):
        """The StabilityMargins of `axis_loop(axis)` on the grid `omega`
        (rad/s), read below the loop's Nyquist frequency (the loop is
        sampled: frequency.stability_margins with its period, so that a
        grid beyond pi / h does not count the crossovers' aliases)."""
        return stability_margins(self.axis_loop(axis), omega,
                                 self.loop.time_period())


DRIFT_TOLERANCE = 1e-4
"""|z - 1| below which a closed-loop eigenvalue counts as a drift, not an
oscillation or a divergence: the base's position on its velocity servo
and the like, integrators that the loop leaves (all but) free, with
time constants above h / 1e-4 = 100 s. `spectral_radius` leaves them
out."""


K_HRI_SEARCH = (1e-4, 1.0)
"""m/(N s): the range in which `AdmittanceCase.limit` looks for the
largest stable k_hri."""


def limit_sentence(result, frequency=True):
    """What a LoopResult says of its largest stable k_hri, in words (with
    the frequency of the oscillation above it if `frequency`)."""
    low, high = K_HRI_SEARCH
    if np.isnan(result.limit):
        return (f"unstable at every k_hri down to {low:g} (the search's "
                "lowest)")
    if result.limit >= high:
        return f"stable up to k_hri = {high:g} at least (the search's highest)"
    sentence = f"largest stable k_hri {result.limit:.4g}"
    if frequency:
        sentence += (f", oscillating at {result.limit_frequency:.3g} Hz "
                     "above it")
    return sentence


def spectral_radius(A, drift_tolerance=DRIFT_TOLERANCE):
    """max |z| over the eigenvalues z of A that are not drifts (|z - 1| >=
    `drift_tolerance`); 0 if none."""
    eig = np.linalg.eigvals(A)
    eig = eig[np.abs(eig - 1.0) >= drift_tolerance]
    return float(np.abs(eig).max(initial=0.0))


def least_stable(A, drift_tolerance=DRIFT_TOLERANCE):
    """The eigenvalue of A (not a drift) of the largest modulus; 0 if
    there is none."""
    eig = np.linalg.eigvals(A)
    eig = eig[np.abs(eig - 1.0) >= drift_tolerance]
    return complex(eig[np.argmax(np.abs(eig))]) if len(eig) else 0j


SETTLED_SPEED = 1e-8
"""rad/s: the arm controller's joint speed below which a redundant arm's
self-motion has come to rest (`settled_arm_positions`); over a control
period it moves the command less than the period map's equilibrium
tolerance (analysis.period_map.EQUILIBRIUM_TOLERANCE)."""


def settled_arm_positions(params, arm, start, longest=1000.0):
    """Where the arm comes to rest from `start` (n, rad) with no twist
    asked of it: `start` itself for an arm of six joints, or one at rest
    there; for an arm of more, the end of its self-motion (the joint
    centring of drake_wbc.math.arm_control.centring_velocity, which moves
    the joints without moving the end effector, to first order), found
    by running the controller's ArmCartesianVelocityController
    (params.arm_controller of the ControllerParameters `params`, on the
    ArmKinematics `arm`) with a zero twist until its joint speeds are
    below SETTLED_SPEED.

    The admittance loop is linearised there: at `start` a redundant arm
    is still moving (not an equilibrium), and the self-motion's change of
    direction with the configuration turns the tool's free directions
    (the hand holds no torque) from drifts into slowly growing modes.

    Raises:
        ValueError: if the self-motion has not come to rest within
            `longest` simulated seconds.
    """
    start = np.asarray(start, dtype=float)
    if (arm.num_joints <= TWIST_SIZE
            or params.arm_controller.self_motion_gain == 0.0):
        return start
    stage = ArmCartesianVelocityController(params.arm_controller, arm,
                                           params.time_step)
    context = stage.CreateDefaultContext()
    stage.GetInputPort("arm_velocity").FixValue(context, np.zeros(TWIST_SIZE))
    stage.set_arm_position(context, start)
    simulator = Simulator(stage, context)
    speeds = stage.GetOutputPort("arm_velocity_command")
    chunk = params.time_step
    while context.get_time() < longest:
        simulator.AdvanceTo(context.get_time() + chunk)
        speed = np.abs(speeds.Eval(context)).max()
        if speed < SETTLED_SPEED:
            # At rest from the first tick: `start` itself (so that a
            # settled start settles to itself).
            return start if chunk == params.time_step else (
                stage.GetOutputPort("arm_position_command").Eval(context))
        chunk = 10.0
    raise ValueError(
        f"the arm's self-motion from {start.tolist()} has not come to rest "
        f"within {longest:g} s (joint speeds up to {speed:.3g} rad/s): the "
        "admittance loop has no operating point there; start the arm "
        "nearer the middle of its joints' ranges or raise "
        "arm_controller.self_motion_gain")


def operating_scenario(scenario):
    """`scenario` with its arm starting where the admittance loop is
    linearised, `settled_arm_positions` of its initial arm positions (the
    very scenario if the arm starts at rest)."""
    start = scenario.station.initial_arm_positions
    settled = settled_arm_positions(controller_for(scenario),
                                    controller_arm(scenario), start)
    if np.array_equal(settled, np.asarray(start, dtype=float)):
        return scenario
    return replace(scenario, station=replace(
        scenario.station, initial_arm_positions=settled.tolist()))


class AdmittanceCase:
    """The linear admittance loop of one scenario, hand and estimator
    setting, relinearising only the controller part for each k_hri.

    Args:
        scenario: an experiments.scenario.Scenario (its controller with
            S_hri = 1, its station); the loop is linearised at its
            `operating_scenario` (`scenario` itself unless the arm is
            redundant).
        hand: HandImpedance (the scenario's scene.hand.impedance if None,
            or HandImpedance() if it has none).
        inertia_compensation: the estimator's setting (the scenario's if
            None).
        time_constant: hri_time_constant T in s (the scenario's if None).
        station: a SimulatedStation of `operating_scenario(scenario)` to
            share (built if None).
        plant: (LinearSystem, rest reading) of the plant part to share
            (linearised if None).
    """

    def __init__(self, scenario, hand=None, inertia_compensation=None,
                 time_constant=None, station=None, plant=None):
        self.scenario = scenario = operating_scenario(scenario)
        params = controller_for(scenario)
        # Through `replace`, so that the parameters' own checks see them.
        if inertia_compensation is not None:
            params = replace(params, wrench=replace(
                params.wrench,
                inertia_compensation=bool(inertia_compensation)))
        if time_constant is not None:
            params = replace(params, whole_body_cdmp=replace(
                params.whole_body_cdmp, hri_time_constant=time_constant))
        self.params = params
        self.hand = hand if hand is not None else (
            scenario.scene.hand.impedance or HandImpedance())
        if station is None:
            station = scenario_station(scenario)
        elif not np.array_equal(station.options.initial_arm_positions,
                                scenario.station.initial_arm_positions):
            raise ValueError(
                "station is not allowed: its arm starts at "
                f"{list(station.options.initial_arm_positions)}, not where "
                "the loop is linearised, "
                f"{scenario.station.initial_arm_positions}: give a station "
                "of operating_scenario(scenario), or None")
        self.station = station
        self.arm = controller_arm(scenario)
        h = self.params.time_step
        self.plant, self.rest_reading = plant if plant is not None else (
            linearize_plant_part(self.station, self.hand, h))
        self.base_state, self.arm_positions = rest_measurements(self.station)
        self._rotation = None

    def controller_part(self, k_hri):
        """The controller part's LinearSystem at `k_hri`."""
        params = replace(self.params, whole_body_cdmp=replace(
            self.params.whole_body_cdmp, k_hri=positive("k_hri", k_hri)))
        linear, controller = linearize_controller_part(
            params, self.arm, self.base_state, self.arm_positions,
            self.scenario.station.initial_arm_positions)
        if self._rotation is None:
            self._rotation = twist_rotation(sensor_rotation_in_base(
                controller.arm, self.arm_positions))
        return linear

    def loop(self, k_hri):
        """The series LinearSystem (measured -> measured: the wrist's
        reading and the arm's positions) at `k_hri`."""
        return series(self.controller_part(k_hri), self.plant)

    def radius(self, k_hri):
        """The closed loop's spectral radius at `k_hri`."""
        return spectral_radius(closed_loop_matrix(self.loop(k_hri)))

    def limit(self, low=K_HRI_SEARCH[0], high=K_HRI_SEARCH[1],
              tolerance=0.01):
        """The largest stable k_hri by bisection on [low, high] (relative
        `tolerance`), or nan if `low` is unstable; `high` if it is
        stable."""
        if self.radius(low) >= 1.0:
            return float("nan")
        if self.radius(high) < 1.0:
            return float(high)
        while high / low > 1.0 + tolerance:
            middle = np.sqrt(low * high)
            if self.radius(middle) < 1.0:
                low = middle
            else:
                high = middle
        return float(low)

    def result(self, label, omega, k_hri=None, limit=None):
        """The LoopResult at `k_hri` (the scenario's if None), margins on
        the grid `omega` (rad/s) if the open loop is stable; `limit` the
        largest stable k_hri if it is known (`limit()` searches it if
        None)."""
        k = self.params.whole_body_cdmp.k_hri if k_hri is None else k_hri
        loop = self.loop(k)
        wrench = reading_loop(loop)
        radius = spectral_radius(closed_loop_matrix(loop))
        limit = self.limit() if limit is None else float(limit)
        frequency = float("nan")
        if np.isfinite(limit) and limit < K_HRI_SEARCH[1]:
            worst = least_stable(closed_loop_matrix(self.loop(limit * 1.01)))
            frequency = abs(np.angle(worst)) / (2 * np.pi
                                                * loop.time_period())
        result = LoopResult(
            label=label, hand=self.hand,
            inertia_compensation=self.params.wrench.inertia_compensation,
            time_constant=self.params.whole_body_cdmp.hri_time_constant,
            k_hri=k, loop=wrench, rotation=self._rotation,
            spectral_radius=radius, limit=limit,
            limit_frequency=frequency,
            open_loop_pole=least_stable(wrench.A()), margins={})
        if not result.margins_unavailable:
            for axis in AXES:
                result.margins[axis] = result.axis_margins(axis, omega)
        return result

