"""Linearisation of a multi-rate discrete diagram over one period.

Drake's `Linearize` takes a system with one periodic discrete group. The
controller runs at the control period h and the station's drivers at the
plant's step, so a chain that crosses them (e.g. eq. (filtering)'s
BaseVelocityFilter feeding the base's velocity loop) has two groups. Its
state sampled every h still evolves time-invariantly; the map over one
period is simulated here in AutoDiffXd and its Jacobians are the
discrete-time A, B, C, D at period h (the design notes' "Jacobian of the
discrete update with AutoDiff").

A MultibodyPlant inside the diagram is stepped in AutoDiffXd too. Drake's
scalar conversion of a plant leaves out its joint actuators' PD gains (the
in-plant servos); `to_autodiff` puts them back.
"""

import numpy as np
from pydrake.autodiffutils import (
    AutoDiffXd,
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointActuatorIndex
from pydrake.systems.analysis import Simulator_
from pydrake.systems.framework import Diagram, PortDataType
from pydrake.systems.primitives import LinearSystem

from drake_wbc.math.validation import positive, whole_multiple

EQUILIBRIUM_TOLERANCE = 1e-9
"""How far a state entry x_i may move over the period at an operating
point, relative to 1 + |x_i|: further, and it is not an equilibrium."""


def _discrete_groups(context):
    state = context.get_discrete_state()
    return [state.get_vector(i).CopyToVector()
            for i in range(state.num_groups())]


def _restore_servo_gains(system, converted):
    """Copies the PD gains of every joint actuator of each MultibodyPlant
    in `system` (a Diagram's, recursively, by name) to its counterpart in
    the scalar-converted `converted`."""
    if isinstance(system, MultibodyPlant):
        for i in range(system.num_actuators()):
            actuator = system.get_joint_actuator(JointActuatorIndex(i))
            if actuator.has_controller():
                converted.get_mutable_joint_actuator(
                    JointActuatorIndex(i)).set_controller_gains(
                        actuator.get_controller_gains())
    elif isinstance(system, Diagram):
        for child in system.GetSystems():
            _restore_servo_gains(
                child, converted.GetSubsystemByName(child.get_name()))


def to_autodiff(system):
    """`system`.ToAutoDiffXd(), with the PD gains of the in-plant servos of
    every MultibodyPlant inside it kept (Drake's conversion of a plant
    drops them, so that its PD-controlled joints would go limp)."""
    converted = system.ToAutoDiffXd()
    _restore_servo_gains(system, converted)
    return converted


def update_periods(system):
    """{name: period in s} of the periodic discrete update of every leaf
    system inside `system` (a Diagram's, recursively; `system` itself if
    it is a leaf) that has one."""
    if isinstance(system, Diagram):
        periods = {}
        for child in system.GetSystems():
            periods.update(update_periods(child))
        return periods
    attribute = system.GetUniquePeriodicDiscreteUpdateAttribute()
    if attribute is None:
        return {}
    return {system.get_name(): attribute.period_sec()}


def check_map_period(system, period):
    """`period` (s) as a float after checking that it is > 0 and a whole
    multiple of every periodic discrete update's period in `system`
    (update_periods): over another span the map would take a whole
    number of updates all the same and be labelled with a period they
    do not fill.

    Raises:
        ValueError: naming period, its value and the update it does not
            fit.
    """
    h = positive("period", period)
    for name, step in update_periods(system).items():
        whole_multiple("period", h, f"the update period of {name!r}", step)
    return h


def linearize_period_map(system, context, period, input_port, output_port,
                         drop_clocks=False):
    """Linearises a discrete multi-rate `system` over one `period`, by
    AutoDiff through Drake's Simulator.

    Drake's `Linearize` takes one periodic discrete group; a diagram
    whose groups run at rates that divide 1 / `period` (e.g. the control
    period and the plant's step) is time invariant when sampled every
    `period`. Its period map x_k -> x_(k+1), with the input held at u_k
    over the period, is simulated here in AutoDiffXd from `context`
    (time 0, all updates aligned), seeded with derivatives w.r.t. x_k
    and u_k, so that

        x_(k+1) = A x_k + B u_k,   y_k = C x_k + D u_k

    are the exact Jacobians (x: the discrete groups stacked; y sampled
    just before the updates at t_k, like the state).

    Args:
        system: a scalar-convertible System with discrete state only (a
            MultibodyPlant inside without sampled output ports, whose
            samples are abstract state).
        context: its Context at the operating point, time 0; its other
            inputs fixed (an abstract one, such as obstacle points,
            passes to the AutoDiffXd system as it is).
        period: the map's period in s, a whole multiple of every
            group's period (checked: check_map_period).
        input_port, output_port: the vector ports of u and y.
        drop_clocks: whether state entries that count time (e.g. the
            InputGuard's valid_time) may move over the period: an entry
            that moves is then dropped from the map if it is a clock
            (its own row of A the identity's, or zero for a clock kept
            in floats, nothing else depending on it: its column of A and
            C zero elsewhere, its row of B zero); any other moving entry
            is still an error. Each entry is compared with its own size
            (EQUILIBRIUM_TOLERANCE).

    Returns:
        LinearSystem(A, B, C, D, period).
    """
    h = check_map_period(system, period)
    if context.num_continuous_states() or context.num_abstract_states():
        raise ValueError(
            f"system = {system.get_name()!r} is not allowed: must have "
            "discrete state only (no continuous or abstract state)")
    groups = _discrete_groups(context)
    sizes = [len(g) for g in groups]
    x0 = np.concatenate(groups) if groups else np.zeros(0)
    u0 = input_port.Eval(context)
    n, m = len(x0), len(u0)
    seeded = InitializeAutoDiff(np.concatenate([x0, u0]), n + m)[:, 0]
    ad_system = to_autodiff(system)

    def ad_context():
        new = ad_system.CreateDefaultContext()
        new.SetTime(0.0)
        offset = 0
        state = new.get_mutable_discrete_state()
        for i, size in enumerate(sizes):
            state.get_mutable_vector(i).SetFromVector(
                seeded[offset:offset + size])
            offset += size
        for i in range(system.num_input_ports()):
            port = system.get_input_port(i)
            ad_port = ad_system.get_input_port(i)
            if i == input_port.get_index():
                ad_port.FixValue(new, seeded[n:])
            elif not port.HasValue(context):
                continue
            elif port.get_data_type() == PortDataType.kVectorValued:
                ad_port.FixValue(new, np.array(
                    [AutoDiffXd(v) for v in port.Eval(context)]))
            else:  # e.g. obstacle points: the same value in both
                ad_port.FixValue(new, port.EvalAbstract(context).Clone())
        return new

    start = ad_context()
    y = ad_system.get_output_port(output_port.get_index()).Eval(start)
    simulator = Simulator_[AutoDiffXd](ad_system, ad_context())
    simulator.AdvanceTo(h)
    after = simulator.get_context().get_discrete_state()
    x1 = np.concatenate([after.get_vector(i).CopyToVector()
                         for i in range(len(sizes))])
    dx, dy = ExtractGradient(x1), ExtractGradient(y)
    value = ExtractValue(x1).ravel()
    A, B, C, D = dx[:, :n], dx[:, n:], dy[:, :n], dy[:, n:]
    # Each entry against its own size: a state that holds a large
    # sentinel (a time that never was, -1e9 s) must not hide another
    # entry's motion.
    changed = ~np.isclose(value, x0, rtol=EQUILIBRIUM_TOLERANCE,
                          atol=EQUILIBRIUM_TOLERANCE)
    moving = changed.copy()
    if drop_clocks:
        for i in np.nonzero(moving)[0]:
            others = np.delete(A[:, i], i)
            if (A[i, i] in (0.0, 1.0) and not np.delete(A[i], i).any()
                    and not others.any() and not C[:, i].any()
                    and not B[i].any()):
                moving[i] = False
        clocks = changed & ~moving
        keep = ~clocks
        A, B, C = A[np.ix_(keep, keep)], B[keep], C[:, keep]
    if moving.any():
        raise ValueError(
            "the operating point is not an equilibrium over one period "
            f"(state moves by {np.abs(value - x0)[moving].max():.3g}), "
            "which linearize_period_map does not allow")
    return LinearSystem(A, B, C, D, h)
