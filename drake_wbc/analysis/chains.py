"""The controller's filter chain, linearised with Drake.

Each chain is built from the project's own scalar-convertible systems and
linearised around the operating point of a scenario (the arm at its
initial configuration, the robot at rest):

- the base filter alone, eq. (filtering): BaseVelocityFilter, V_b' to
  V_b^flt, with Drake's `Linearize`;
- the split of the end-effector command (`build_split_diagram`):
  MotionDistributor (eq. (wbccm)) -> BaseVelocityFilter -> RobustCompensator
  (eqs. (wb_error), (compensation)) at a fixed arm configuration, from V_ee
  to the base's share J_b V_b^flt, the arm's share R_ba V_a^ref and their
  sum, the end effector's velocity J_wb [V_a^ref; V_b^flt] with ideal
  actuators (one periodic discrete group: `Linearize`);
- the same split with the base's real velocity loop, the station's
  BaseVelocityDriver (eq. (filtering)'s output as its command, the base's
  share J_b v_base): two rates, the control period and the plant's step,
  so the period map over one control period is linearised with AutoDiff
  (`linearize_period_map`);
- the same split through the station's plant (`station=`): the driver
  commands the base of a copy of the SimulatedStation's MultibodyPlant
  (SAP, the in-plant velocity servo, the flexible mount, the arm held by
  its servo) at the station's static equilibrium; the base's actual
  velocity and the end effector's through the plant are read off its
  state (`plant_outputs`), and `linearize_base_plant` gives the driver
  and plant alone;
- the loop of the tracking-error elimination (`deviation_loop`): the
  deviation the robust compensation leaves out, through WholeBodyCdmp,
  the split and (with the "measured" or "predicted" source of the base's
  motion) the base's real velocity loop, back to the deviation.

The force responses of the coupled DMPs are in
drake_wbc.analysis.dmp_force_response.
"""
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Linearize,
    LinearSystem,
    MatrixGain,
    Multiplexer,
)

from drake_wbc.analysis.frequency import frequency_response
from drake_wbc.analysis.period_map import linearize_period_map
from drake_wbc.analysis.plant_chain import (
    add_station_plant,
    plant_outputs,
    station_equilibrium,
)
from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.math import kinematics
from drake_wbc.math.filtering import BaseFilterParameters
from drake_wbc.math.safety import MEASURED_POSITION_MARGIN
from drake_wbc.math.validation import as_vector, checked_instance
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import (
    BaseVelocityFilter,
    MotionDistributor,
    RobustCompensator,
    WholeBodyCdmp,
)
from drake_wbc.station.drivers import (
    BaseDriverParameters,
    BaseVelocityDriver,
    check_base_time_step,
)

SPLIT_OUTPUTS = ("base_share", "arm_share", "end_effector_velocity")
"""The split diagram's outputs, each a twist (6) of the end effector in
T_b, stacked in this order on its `shares` port."""

@dataclass
class OperatingPoint:
    """Where the chains are linearised: the arm's configuration and what
    the controller's ArmCapability and WorkspaceAdapter make of it.

    Attributes:
        arm: the controller's ArmKinematics (its robot's arm).
        arm_positions: q_a (n), rad.
        end_effector_position: p_ee (3) in T_b, m.
        capability: C_m; capability_gradient: grad_x C_m (6, T_a).
        alpha: alpha of eq. (transition).
        sigma_xy, sigma_phi: the weighting factors of eq.
            (weight-factors) at rest (V_ee = 0), in the intuitive pHRI
            mode one tick from the WorkspaceAdapter's start state
            (workspace.WEIGHTING_START: f itself inside the workspace,
            at most max_rate * time_step below 1 outside it).
    """

    arm: ArmKinematics
    arm_positions: np.ndarray
    end_effector_position: np.ndarray
    capability: float
    capability_gradient: np.ndarray
    alpha: float
    sigma_xy: float
    sigma_phi: float


def operating_point(params=None, arm_positions=None, arm=None):
    """The OperatingPoint of a controller with `params` (the paper's if
    None) on `arm` (an ArmKinematics; the shipped robot's if None) with
    the arm at `arm_positions` (its home if None), from the controller's
    own stages.

    Raises:
        ValueError: naming the first joint of `arm_positions` further
            than MEASURED_POSITION_MARGIN outside its limits (the
            controller's input guard would not take it as a
            measurement, and its stages would see the last valid one).
    """
    arm = checked_instance("arm", arm, ArmKinematics, ArmKinematics)
    q_a = as_vector("arm_positions", arm.home
                    if arm_positions is None else arm_positions,
                    arm.num_joints)
    beyond = np.maximum(arm.lower - q_a, q_a - arm.upper)
    if np.any(beyond > MEASURED_POSITION_MARGIN):
        i = int(np.flatnonzero(beyond > MEASURED_POSITION_MARGIN)[0])
        raise ValueError(
            f"arm_positions[{i}] = {float(q_a[i])!r} is not allowed: must "
            f"lie within the joint's limits [{float(arm.lower[i])!r}, "
            f"{float(arm.upper[i])!r}] rad give or take "
            f"{MEASURED_POSITION_MARGIN!r}")
    controller = build_controller(checked_instance(
        "params", params, ControllerParameters, ControllerParameters),
        robot=arm)
    context = controller.diagram.CreateDefaultContext()
    diagram = controller.diagram
    diagram.GetInputPort("arm.position_measured").FixValue(context, q_a)
    for name in ("reference_velocity", "wrist.wrench_measured"):
        diagram.GetInputPort(name).FixValue(context, np.zeros(6))
    diagram.GetInputPort("base.state_estimated").FixValue(context,
                                                          np.zeros(6))

    def value(stage, port):
        system = controller.stages[stage]
        return system.GetOutputPort(port).Eval(
            system.GetMyContextFromRoot(context))

    return OperatingPoint(
        arm=arm,
        arm_positions=q_a,
        end_effector_position=value("capability", "end_effector_position"),
        capability=float(value("capability", "capability")[0]),
        capability_gradient=value("capability", "capability_gradient"),
        alpha=float(value("capability", "alpha")[0]),
        sigma_xy=float(value("workspace", "sigma_xy")[0]),
        sigma_phi=float(value("workspace", "sigma_phi")[0]))


def linearize_base_filter(params=None, time_step=0.01):
    """Drake's linearisation of BaseVelocityFilter, eq. (filtering): a
    LinearSystem from V_b' (3) to V_b^flt (3) of the filter `params`
    (BaseFilterParameters; the paper's if None), continuous (time_step =
    0) or discrete at the control period `time_step` (s; 0.01 if not
    given)."""
    system = BaseVelocityFilter(checked_instance(
        "params", params, BaseFilterParameters, BaseFilterParameters),
        time_step=time_step)
    context = system.CreateDefaultContext()
    system.get_input_port().FixValue(context, np.zeros(3))
    return Linearize(system, context)


def linearize_base_driver(params=None, time_step=None):
    """Drake's linearisation of the station's BaseVelocityDriver at rest
    (the base's velocity loop of BaseDriverParameters `params`, inside
    its saturations): a LinearSystem from the velocity command (3) to the
    loop's velocity (3), discrete at `time_step` (s, required: the
    plant's step, StationOptions.time_step)."""
    system = BaseVelocityDriver(checked_instance(
        "params", params, BaseDriverParameters, BaseDriverParameters),
        time_step)
    context = system.CreateDefaultContext()
    system.GetInputPort("base_pose").FixValue(context, np.zeros(3))
    command = system.GetInputPort("velocity_command")
    command.FixValue(context, np.zeros(3))
    return Linearize(system, context, command.get_index(),
                     system.GetOutputPort("velocity").get_index())


def build_split_diagram(params=None, point=None, base_driver=None,
                        alpha=None, station=None, base_step=None):
    """The split of the end-effector command as a Diagram.

    ::

                              ┌──────────────────────┐
                              │ MotionDistributor    ├─► shares
        end_effector_velocity►│ → BaseVelocityFilter │   [base_share;
                              │ (→ BaseVelocityDriver)   arm_share;
                              │ → RobustCompensator  │   end_effector_
                              └──────────────────────┘   velocity]

    - end_effector_velocity: V_ee (6), the commanded twist in T_b.
    - shares (18): the base's share J_b V_b^flt (J_b v_base with the
      driver; the compensator's "measured" source reads v_base), the
      arm's share R6_ba V_a^ref, and their sum, the end effector's twist
      J_wb [V_a^ref; V_b] with an ideal arm; each 6, T_b.
      Also exported alone under their names, with filtered_base_velocity
      (3) and arm_reference_velocity (6).

    The distributor's other inputs (p_ee, C_m, grad_x C_m, sigma_xy,
    sigma_phi, k_n) and the compensator's (p_ee, grad_x C_m, alpha, s_c)
    are constants at the operating point, J_b is taken at its p_ee. The
    BaseCdmp between distributor and filter is left out: without obstacles
    it only passes V_b on (V_b' = V_b, a DMP with C_dot = V_b and g + C =
    y).

    Args:
        params: ControllerParameters (the paper's if None); the filter
            runs at params.time_step.
        point: OperatingPoint (`operating_point(params)` if None).
        base_driver: BaseDriverParameters of the base's velocity loop
            between the filter and the base, or None for an ideal base.
        alpha: alpha in [0, 1] in place of the operating point's (the
            split sums to one while alpha = 0).
        station: a SimulatedStation, or None. If given (base_driver must
            be None), its base driver drives a copy of its plant
            (`add_station_plant`), whose state [q; v] is exported as
            plant_state and after the shares on shares_and_plant_state.
        base_step: the step of `base_driver`'s loop in s (the plant's,
            StationOptions.time_step), required with it, at most its
            lag / 10.
    """
    return _build_split(params, point, base_driver, alpha, station,
                        base_step)[0]


def _add_split_stages(add, params, point):
    """Adds the split's stages with `add` (a builder's AddNamedSystem):
    the distributor, the base filter and the compensator of `params` on
    the operating point's arm. Returns the three."""
    return (add("distributor", MotionDistributor(
                params.distributor, point.arm, band=params.capability_band)),
            add("base_filter", BaseVelocityFilter(
                params.base_filter, time_step=params.time_step)),
            add("compensator", RobustCompensator(
                params.compensator, point.arm, time_step=params.time_step)))


def _base_driver(params, time_step):
    """The BaseVelocityDriver of a chain's `base_driver` (`params`) at
    its `base_step` (`time_step`)."""
    params = checked_instance("base_driver", params, BaseDriverParameters,
                              None)
    return BaseVelocityDriver(params, check_base_time_step(
        params, "base_step", time_step, prefix="base_driver."))


def _connect_split(builder, distributor, base_filter, compensator):
    """Wires the split in `builder`: V_b from the distributor into the
    filter and the compensator, V_a into the compensator, V_b^flt into the
    compensator. Returns the filter's output port."""
    connect = builder.Connect
    base_velocity = distributor.GetOutputPort("base_velocity")
    connect(base_velocity, base_filter.get_input_port())
    connect(base_velocity, compensator.GetInputPort("base_velocity"))
    connect(distributor.GetOutputPort("arm_velocity"),
            compensator.GetInputPort("arm_velocity"))
    filtered = base_filter.get_output_port()
    connect(filtered, compensator.GetInputPort("filtered_base_velocity"))
    return filtered


def _build_split(params, point, base_driver, alpha, station, base_step):
    """build_split_diagram's diagram, and the RobotModel of its plant (or
    None)."""
    params = checked_instance("params", params, ControllerParameters,
                              ControllerParameters)
    point = point if point is not None else operating_point(params)
    if not isinstance(point, OperatingPoint):
        raise ValueError(f"point = {point!r} is not allowed: must be an "
                         "OperatingPoint or None")
    builder = DiagramBuilder()
    add = builder.AddNamedSystem
    distributor, base_filter, compensator = _add_split_stages(
        add, params, point)
    alpha = point.alpha if alpha is None else alpha

    def constant(name, value, destination, port):
        source = add(f"{name}_{destination.get_name()}", ConstantVectorSource(
            np.atleast_1d(np.asarray(value, dtype=float))))
        builder.Connect(source.get_output_port(),
                        destination.GetInputPort(port))

    p_ee = point.end_effector_position
    for name, value in (
            ("end_effector_position", p_ee), ("capability", point.capability),
            ("capability_gradient", point.capability_gradient),
            ("sigma_xy", point.sigma_xy), ("sigma_phi", point.sigma_phi),
            ("null_space_gain", params.distributor.null_space_gain)):
        constant(name, value, distributor, name)
    for name, value in (
            ("end_effector_position", p_ee),
            ("capability_gradient", point.capability_gradient),
            ("alpha", alpha),
            ("compensation_switch",
             params.compensator.compensation_switch)):
        constant(name, value, compensator, name)
    connect = builder.Connect
    filtered = _connect_split(builder, distributor, base_filter, compensator)
    base_motion, model = filtered, None
    if station is not None:
        if base_driver is not None:
            raise ValueError(f"base_driver = {base_driver!r} is not allowed "
                             "with a station: must be None (the station's "
                             "own driver is used)")
        driver, plant, model = add_station_plant(builder, station)
        connect(filtered, driver.GetInputPort("velocity_command"))
        base_motion = driver.GetOutputPort("velocity")
    elif base_driver is not None:
        driver = add("base_driver", _base_driver(base_driver, base_step))
        connect(filtered, driver.GetInputPort("velocity_command"))
        constant("base_pose", np.zeros(3), driver, "base_pose")
        base_motion = driver.GetOutputPort("velocity")
    if params.compensator.base_source == "measured":
        # The odometry as the station's reports it: the base's own
        # velocity (the driver's loop, or the command of an ideal base).
        odometry = add("odometry", MatrixGain(np.vstack([np.zeros((3, 3)),
                                                         np.eye(3)])))
        connect(base_motion, odometry.get_input_port())
        connect(odometry.get_output_port(),
                compensator.GetInputPort("base_state"))
    J_b = kinematics.base_jacobian(p_ee)
    R6 = kinematics.twist_rotation(distributor.R_ba)
    base_share = add("base_share", MatrixGain(J_b))
    arm_share = add("arm_share", MatrixGain(R6))
    total = add("end_effector", MatrixGain(np.hstack([R6, J_b])))
    stack = add("shares", Multiplexer([6, 6, 6]))
    both = add("arm_and_base", Multiplexer([6, 3]))
    arm_reference = compensator.GetOutputPort("arm_reference_velocity")
    connect(base_motion, base_share.get_input_port())
    connect(arm_reference, arm_share.get_input_port())
    connect(arm_reference, both.get_input_port(0))
    connect(base_motion, both.get_input_port(1))
    connect(both.get_output_port(), total.get_input_port())
    for i, system in enumerate((base_share, arm_share, total)):
        connect(system.get_output_port(), stack.get_input_port(i))
    builder.ExportInput(distributor.GetInputPort("end_effector_velocity"),
                        "end_effector_velocity")
    builder.ExportOutput(stack.get_output_port(), "shares")
    for name, system in zip(SPLIT_OUTPUTS, (base_share, arm_share, total),
                            strict=True):
        builder.ExportOutput(system.get_output_port(), name)
    builder.ExportOutput(filtered, "filtered_base_velocity")
    builder.ExportOutput(arm_reference, "arm_reference_velocity")
    if model is not None:
        state = plant.get_state_output_port()
        both = add("shares_and_plant_state", Multiplexer([18, state.size()]))
        connect(stack.get_output_port(), both.get_input_port(0))
        connect(state, both.get_input_port(1))
        builder.ExportOutput(state, "plant_state")
        builder.ExportOutput(both.get_output_port(), "shares_and_plant_state")
    diagram = builder.Build()
    diagram.set_name("split_with_plant" if model is not None else "split"
                     if base_driver is None else "split_with_base")
    return diagram, model


def linearize_split(params=None, point=None, base_driver=None, alpha=None,
                    station=None, base_step=None):
    """The split's LinearSystem from V_ee (6) to the stacked shares (18,
    SPLIT_OUTPUTS), discrete at params.time_step: Drake's `Linearize`
    for ideal actuators, `linearize_period_map` with the base driver
    (two rates). Arguments as for `build_split_diagram`.

    With a `station`, around its static equilibrium, 27 outputs: the
    shares (the base's J_b v of the driver's loop), then PLANT_OUTPUTS
    of the plant: the base's actual velocity (3) and the end effector's
    twist (6), the arm's share R6_ba V_a^ref (an ideal arm) plus the
    tool centre point's twist in the plant with the arm held (the base's
    motion and the mount's rocking).
    """
    params = checked_instance("params", params, ControllerParameters,
                              ControllerParameters)
    diagram, model = _build_split(params, point, base_driver, alpha, station,
                                  base_step)
    context = diagram.CreateDefaultContext()
    source = diagram.GetInputPort("end_effector_velocity")
    source.FixValue(context, np.zeros(6))
    if model is not None:
        plant = diagram.GetSubsystemByName("plant")
        S = plant_outputs(plant, model, station_equilibrium(
            station, plant, model, context))
        linear = linearize_period_map(
            diagram, context, params.time_step, source,
            diagram.GetOutputPort("shares_and_plant_state"))
        select = np.zeros((27, 18 + S.shape[1]))
        select[:18, :18] = np.eye(18)
        select[18:, 18:] = S
        select[21:, 6:12] = np.eye(6)  # the arm's share
        return LinearSystem(linear.A(), linear.B(), select @ linear.C(),
                            select @ linear.D(), linear.time_period())
    output = diagram.GetOutputPort("shares")
    if base_driver is None:
        return Linearize(diagram, context, source.get_index(),
                         output.get_index())
    return linearize_period_map(diagram, context, params.time_step, source,
                                output)


def build_deviation_loop(params=None, point=None, base_driver=None,
                         alpha=1.0, base_step=None):
    """The loop of the tracking-error elimination, eq. (cdmp-wb-error),
    broken at WholeBodyCdmp's deviation input, as a Diagram.

    ::

        deviation_in ─► WholeBodyCdmp ─► MotionDistributor ─► BaseVelocity-
        (delta_V_ee)     (V_ee)            │ V_a, V_b          Filter
                                           ▼                    │ V_b^flt
        deviation_out ◄─ RobustCompensator ◄─ (BaseVelocityDriver) ◄┘

    The deviation of eq. (deviation), -alpha R_ba P_Cm delta_V_a^req, is
    what the robust compensation leaves out; WholeBodyCdmp integrates it
    into its tracking error and commands it back, through the base: a
    loop that closes through the base's real velocity loop when the
    compensator's source (params.compensator.base_source) is "measured"
    (its odometry: the driver's velocity) or "predicted" (its model of
    that loop), and through the command alone with "command". The
    reference, wrench and yaw are zero, S_hri = 0, k_n = 0; p_ee, C_m,
    grad_x C_m and sigma are the operating point's, alpha is `alpha`
    (1: the most the compensation leaves out) and s_c 1.

    Args:
        params: ControllerParameters (the paper's if None).
        point: OperatingPoint (`operating_point(params)` if None).
        base_driver: BaseDriverParameters of the base's velocity loop, or
            None for an ideal base (its velocity the filter's output).
        alpha: alpha in [0, 1].
        base_step: the step of `base_driver`'s loop in s (the plant's,
            StationOptions.time_step), required with it.
    """
    params = checked_instance("params", params, ControllerParameters,
                              ControllerParameters)
    point = point if point is not None else operating_point(params)
    builder = DiagramBuilder()
    add = builder.AddNamedSystem
    connect = builder.Connect
    whole_body = add("whole_body_cdmp", WholeBodyCdmp(
        params.whole_body_cdmp, time_step=params.time_step))
    distributor, base_filter, compensator = _add_split_stages(
        add, params, point)

    def constant(value, port):
        source = add(f"{port.get_name()}_{port.get_system().get_name()}",
                     ConstantVectorSource(np.atleast_1d(
                         np.asarray(value, dtype=float))))
        connect(source.get_output_port(), port)

    for name, value in (("reference_velocity", np.zeros(6)),
                        ("wrench", np.zeros(6)), ("base_yaw", 0.0),
                        ("phri_switch", 0.0)):
        constant(value, whole_body.GetInputPort(name))
    p_ee = point.end_effector_position
    for name, value in (
            ("end_effector_position", p_ee), ("capability", point.capability),
            ("capability_gradient", point.capability_gradient),
            ("sigma_xy", point.sigma_xy), ("sigma_phi", point.sigma_phi),
            ("null_space_gain", 0.0)):
        constant(value, distributor.GetInputPort(name))
    for name, value in (
            ("end_effector_position", p_ee),
            ("capability_gradient", point.capability_gradient),
            ("alpha", alpha), ("compensation_switch", 1.0)):
        constant(value, compensator.GetInputPort(name))
    connect(whole_body.GetOutputPort("end_effector_velocity"),
            distributor.GetInputPort("end_effector_velocity"))
    filtered = _connect_split(builder, distributor, base_filter, compensator)
    base_motion = filtered
    if base_driver is not None:
        driver = add("base_driver", _base_driver(base_driver, base_step))
        connect(filtered, driver.GetInputPort("velocity_command"))
        constant(np.zeros(3), driver.GetInputPort("base_pose"))
        base_motion = driver.GetOutputPort("velocity")
    odometry = add("odometry", MatrixGain(np.vstack([np.zeros((3, 3)),
                                                     np.eye(3)])))
    connect(base_motion, odometry.get_input_port())
    connect(odometry.get_output_port(),
            compensator.GetInputPort("base_state"))
    builder.ExportInput(whole_body.GetInputPort("end_effector_deviation"),
                        "deviation_in")
    builder.ExportOutput(compensator.GetOutputPort("end_effector_deviation"),
                         "deviation_out")
    diagram = builder.Build()
    diagram.set_name("deviation_loop")
    return diagram


def deviation_loop(params=None, point=None, base_driver=None, alpha=1.0,
                   base_step=None):
    """The loop transfer function L(omega) of `build_deviation_loop`
    (same arguments), for `frequency.stability_margins`: its deviation is
    always along d = R6_ba grad_x C_m / |.| (P_Cm has rank one), so the
    loop is the scalar L = -d^T H d, H the broken loop's response from
    deviation_in to deviation_out (the loop closes as deviation_in =
    deviation_out; L's sign is that of a negative feedback). Linearised
    with `linearize_period_map` over one control period (the driver runs
    at base_step).

    Returns:
        (L, linear): a callable omega (rad/s) -> complex, and the
        LinearSystem H (6 by 6, discrete at params.time_step).
    """
    params = checked_instance("params", params, ControllerParameters,
                              ControllerParameters)
    point = point if point is not None else operating_point(params)
    diagram = build_deviation_loop(params, point, base_driver, alpha,
                                   base_step)
    context = diagram.CreateDefaultContext()
    source = diagram.GetInputPort("deviation_in")
    source.FixValue(context, np.zeros(6))
    linear = linearize_period_map(diagram, context, params.time_step, source,
                                  diagram.GetOutputPort("deviation_out"))
    R_ba = diagram.GetSubsystemByName("distributor").R_ba
    direction = kinematics.twist_rotation(R_ba) @ point.capability_gradient
    direction = direction / np.linalg.norm(direction)

    def loop(omega):
        H = frequency_response(linear.A(), linear.B(), linear.C(),
                               linear.D(), [omega], linear.time_period())[0]
        return -(direction @ H @ direction)

    return loop, linear
