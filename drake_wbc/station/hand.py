"""A person's hand that holds the tool: a hand with impedance, in the plant.

The hand (scene.HandImpedance) is a body of the hand's mass on three
prismatic joints from the world (x, y, z), tied to the tool centre point
by a ball constraint (SAP's, so the grip is rigid in translation and free
in rotation). Each joint is driven by the plant's PD actuator with the
hand's stiffness and damping towards where the person means the hand to
be; SAP treats those PD terms implicitly, so a stiff grip steps as stably
as a light touch. The hand's weight is the person's to carry (gravity is
off for the hand's model instance). So the push on the tool is what the
arm's motion and the person's intention produce together::

    f_hand = K (p_d - p) + D (v_d - v)

with p, v the tool centre point's position and velocity, and the
person's intention (`HandIntention`, sampled every `period` s)::

    p_d = a + f_s / K,    v_d = w

where f_s is the schedule's force and a, w follow the tool's position
and velocity with the person's reaction time T (a critically damped
filter with zero error at a constant velocity: w' = (v - w) / T,
a' = w + (p - a) / T). Slower than T the person guides the tool and the
push is the scheduled force (at rest, p_d - p = f_s / K exactly); faster
than T the tool meets the hand's spring and damper (and its mass, which
the wrist sensor weighs with the tool's).
"""

import numpy as np
from pydrake.multibody.tree import (
    PdControllerGains,
    PrismaticJoint,
    SpatialInertia,
)
from pydrake.systems.framework import LeafSystem

from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.station.scene import HandForce, HandImpedance, HandSchedule

HAND_AXES = ("x", "y", "z")


class HandBody:
    """The hand's parts in the plant (from `add_hand_body`).

    Attributes:
        instance: the hand's ModelInstanceIndex ("hand").
        body: the hand's body, at the tool centre point.
        joints: its prismatic joints along the world's x, y and z.
        impedance: the HandImpedance it was made with.
    """

    def __init__(self, instance, body, joints, impedance):
        self.instance, self.body = instance, body
        self.joints, self.impedance = joints, impedance

    def position_indices(self):
        """The hand's x, y, z in the plant's positions."""
        return [j.position_start() for j in self.joints]


def add_hand_body(plant, model, impedance):
    """Adds the hand of `impedance` (a HandImpedance) gripping the tool
    centre point of the robot `model` to `plant`, which must not be
    finalized yet, and must be discrete with SAP (the ball constraint and
    the implicit PD terms are SAP's); returns its HandBody."""
    impedance = checked_instance("impedance", impedance, HandImpedance,
                                 HandImpedance)
    if plant.is_finalized():
        raise ValueError("plant is finalized, which is not allowed: add "
                         "the hand before plant.Finalize()")
    instance = plant.AddModelInstance("hand")
    parent = plant.world_frame()
    joints = []
    for i, axis in enumerate(HAND_AXES):
        last = i == len(HAND_AXES) - 1
        body = plant.AddRigidBody(
            "hand" if last else f"hand_{axis}", instance,
            SpatialInertia.SolidSphereWithMass(impedance.mass, 0.04) if last
            else SpatialInertia.Zero())
        joint = plant.AddJoint(PrismaticJoint(
            f"hand_{axis}", parent, body.body_frame(), np.eye(3)[i]))
        actuator = plant.AddJointActuator(f"hand_{axis}", joint)
        actuator.set_controller_gains(PdControllerGains(
            p=impedance.stiffness, d=impedance.damping))
        joints.append(joint)
        parent = body.body_frame()
    plant.set_gravity_enabled(instance, False)
    tool = model.tcp_frame.body()
    plant.AddBallConstraint(
        body, np.zeros(3), tool,
        model.tcp_frame.GetFixedPoseInBodyFrame().translation())
    return HandBody(instance, body, joints, impedance)


class HandIntention(LeafSystem):
    """Where the person means the hand to be (module docstring).

    ::

                     ┌───────────────┐
        hand_state ─►│ HandIntention ├──► desired_state
                     │               ├──► force
                     └───────────────┘

    - hand_state: (6) [p; v] of the hand, which is the tool centre point
      (the plant's state output of the hand's model instance).
    - desired_state: (6) [p_d; v_d] for the plant's desired state input
      of the hand: a + w (t - t_k) + f_s / K and w, from the last sample
      t_k (so p_d moves on between samples and never steps by the tool's
      motion).
    - force: (6) [f_hand; tau] in the world, N and N m: the spring's and
      damper's force on the hand (the grip's force on the tool less the
      hand's small inertial force) and the schedule's torque, for logs.

    Args:
        hand: a HandForce with an impedance (validated).
        period: s, > 0, how often the intention and the schedule are
            sampled.
    """

    def __init__(self, hand, period=0.01):
        super().__init__()
        self.hand = checked_instance("hand", hand, HandForce, HandForce)
        if self.hand.impedance is None:
            raise ValueError("hand.impedance = None is not allowed here: "
                             "a HandIntention needs the hand's impedance")
        self.period = positive("period", period)
        self._k = self.hand.impedance.stiffness
        self._d = self.hand.impedance.damping
        self._tau = self.hand.impedance.reaction_time
        self._wrench_at = HandSchedule(self.hand)
        self._input = self.DeclareVectorInputPort("hand_state", 6)
        # [a (3), w (3), f_s (3), torque (3), t_k]
        self._state = self.DeclareDiscreteState(13)
        self.DeclarePeriodicDiscreteUpdateEvent(self.period, 0.0,
                                                self._sample)
        held = {self.discrete_state_ticket(self._state), self.time_ticket()}
        self._desired_state = self.DeclareVectorOutputPort(
            "desired_state", 6, self._calc_desired,
            prerequisites_of_calc=held)
        self.DeclareVectorOutputPort(
            "force", 6, self._calc_force,
            prerequisites_of_calc=held | {self.all_input_ports_ticket()})

    def initial_state(self, position, t=0.0):
        """The state of a hand at rest at `position` (3) at time `t`."""
        state = np.zeros(13)
        state[:3] = position
        state[6:12] = self._wrench_at(float(t))
        state[12] = t
        return state

    def _sample(self, context, discrete_state):
        x = context.get_discrete_state(self._state).CopyToVector()
        pv = self._input.Eval(context)
        t = context.get_time()
        h = t - x[12]
        a, w = x[:3] + h * x[3:6], x[3:6]
        gain = min(1.0, h / self._tau)
        new = np.empty(13)
        new[:3] = a + gain * (pv[:3] - a)
        new[3:6] = w + gain * (pv[3:] - w)
        new[6:12] = self._wrench_at(t)
        new[12] = t
        discrete_state.set_value(self._state, new)

    def _desired(self, context):
        x = context.get_discrete_state(self._state).CopyToVector()
        h = context.get_time() - x[12]
        return np.concatenate([x[:3] + h * x[3:6] + x[6:9] / self._k,
                               x[3:6]])

    def _calc_desired(self, context, output):
        output.SetFromVector(self._desired(context))

    def _calc_force(self, context, output):
        # The desired state the plant reads at this time: computed once.
        desired = self._desired_state.Eval(context)
        pv = self._input.Eval(context)
        x = context.get_discrete_state(self._state).CopyToVector()
        f = self._k * (desired[:3] - pv[:3]) + self._d * (desired[3:]
                                                          - pv[3:])
        output.SetFromVector(np.concatenate([f, x[9:12]]))


def torque_only(hand):
    """The HandForce of `hand`'s torques alone (its forces zero, no
    impedance): the twist that a hand with impedance still applies as a
    scripted torque; an empty HandForce if it has none."""
    if not hand.torques:
        return HandForce()
    return HandForce(times=list(hand.times),
                     forces=[[0.0, 0.0, 0.0] for _ in hand.times],
                     torques=[list(r) for r in hand.torques])


def add_hand_intention(builder, plant, hand_body, hand, period=0.01):
    """Adds the HandIntention "hand_intention" of `hand` (sampled every
    `period` s) to `builder` and connects it to the finalized `plant`'s
    hand of `hand_body`; returns it."""
    if not plant.is_finalized():
        raise ValueError("plant is not finalized, which is not allowed: "
                         "call plant.Finalize() before add_hand_intention")
    intention = builder.AddNamedSystem("hand_intention",
                                       HandIntention(hand, period))
    builder.Connect(plant.get_state_output_port(hand_body.instance),
                    intention.GetInputPort("hand_state"))
    builder.Connect(intention.GetOutputPort("desired_state"),
                    plant.get_desired_state_input_port(hand_body.instance))
    return intention
