"""The scripted scene's moving parts as Drake systems: the walking people
(`PeopleSource`, `add_people`) and the person's hand on the tool
(`HandForceSource`, `add_hand`), from the scene's descriptions
(drake_wbc.station.scene)."""

from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Cylinder,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    MakePhongIllustrationProperties,
)
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.station.scene import (
    PERSON_COLOR,
    HandForce,
    HandSchedule,
    Scene,
    Walks,
)


class PeopleSource(LeafSystem):
    """The walking people: their positions, and their bodies in SceneGraph.

    ::

            ┌──────────────┐
            │ PeopleSource ├──► positions
            │              ├──► geometry_pose  (after register_geometry)
            └──────────────┘

    - positions: (2N) [x0, y0, x1, y1, ...] in the world, m, at the
      context's time (`person_positions`).
    - geometry_pose: FramePoseVector of each person's frame, on the floor
      below the person, as last sampled (every `period` s, from t = 0);
      to scene_graph.get_source_pose_port(source_id).

    The bodies are illustration cylinders: drawn (in Meshcat at
    /drake/visualizer/people/<name>, also in recordings), never touched.
    SceneGraph reads their poses whenever the plant asks for geometry (at
    every plant step), so they are sampled, not computed at each read: a
    person walking 1 m/s is drawn at most `period` m behind.

    Args:
        people: list of WalkingPerson (validated; names must differ).
        period: s, > 0, how often the drawn poses are sampled.
    """

    def __init__(self, people, period=0.01):
        super().__init__()
        self.people = Scene(people=list(people)).people
        self.period = positive("period", period)
        self._positions_at = Walks(self.people)
        self.source_id = None
        self._frame_ids = []
        self.DeclareVectorOutputPort(
            "positions", 2 * len(self.people), self._calc_positions,
            prerequisites_of_calc={self.time_ticket()})
        self._drawn = self.DeclareDiscreteState(
            self._positions_at(0.0).ravel())
        if self.people:
            self.DeclarePeriodicDiscreteUpdateEvent(self.period, 0.0,
                                                    self._sample)

    def _calc_positions(self, context, output):
        output.SetFromVector(self._positions_at(context.get_time()).ravel())

    def _sample(self, context, discrete_state):
        discrete_state.set_value(
            self._drawn, self._positions_at(context.get_time()).ravel())

    def register_geometry(self, scene_graph):
        """Registers the people with `scene_graph` as the geometry source
        "people" (a frame "people::<name>" and a cylinder each) and
        declares the `geometry_pose` output; returns the SourceId.

        Call it once, before the diagram is built.
        """
        if self.source_id is not None:
            raise ValueError("register_geometry was called already, which "
                             "is not allowed: register the people once")
        self.source_id = scene_graph.RegisterSource("people")
        for person in self.people:
            frame_id = scene_graph.RegisterFrame(
                self.source_id, GeometryFrame(f"people::{person.name}"))
            body = GeometryInstance(
                RigidTransform([0.0, 0.0, person.height / 2]),
                Cylinder(person.radius, person.height), "body")
            body.set_illustration_properties(
                MakePhongIllustrationProperties(PERSON_COLOR))
            scene_graph.RegisterGeometry(self.source_id, frame_id, body)
            self._frame_ids.append(frame_id)
        self.DeclareAbstractOutputPort(
            "geometry_pose", lambda: AbstractValue.Make(FramePoseVector()),
            self._calc_poses,
            prerequisites_of_calc={self.discrete_state_ticket(self._drawn)})
        return self.source_id

    def _calc_poses(self, context, output):
        poses = output.get_mutable_value()
        poses.clear()
        xy = context.get_discrete_state(self._drawn).CopyToVector()
        for frame_id, (x, y) in zip(self._frame_ids, xy.reshape(-1, 2),
                                    strict=True):
            # By keyword: pybind11 tries the other constructors first.
            poses.set_value(frame_id, RigidTransform(p=[x, y, 0.0]))


def add_people(builder, scene_graph, people, period=0.01):
    """Adds a PeopleSource "people" of `people` (drawn poses sampled every
    `period` s) to `builder`, registers their bodies with `scene_graph`
    and connects their poses; returns it."""
    source = PeopleSource(people, period)
    source_id = source.register_geometry(scene_graph)
    builder.AddSystem(source)
    source.set_name("people")
    builder.Connect(source.GetOutputPort("geometry_pose"),
                    scene_graph.get_source_pose_port(source_id))
    return source


class HandForceSource(LeafSystem):
    """A person's hand pushing (and twisting) the tool at its centre point.

    ::

            ┌─────────────────┐
            │ HandForceSource ├──► spatial_forces
            │                 ├──► force
            └─────────────────┘

    - spatial_forces: list[ExternallyAppliedSpatialForce], one force on
      the tool body at the tool centre point, for the plant's
      applied_spatial_force input (empty with no hand).
    - force: (6) [f; tau] in the world, N and N m: that wrench, the
      torque about the tool centre point, for logs.

    The wrench is sampled every `period` s from t = 0 and held (a zero
    order hold of `hand_wrench`; the default state holds the wrench at
    t = 0): the plant reads it at every step, and a hand's push changes
    far slower than the plant steps. Both outputs come from the held
    wrench alone. With no hand there is no event and both outputs are
    constant.

    The tool centre point is fixed in the tool body and the force is in
    the world frame, as ExternallyAppliedSpatialForce takes it: no body
    poses are needed.

    Args:
        plant: the MultibodyPlant that holds the robot.
        model: the RobotModel that add_robot returned for `plant`.
        hand: a HandForce (validated); None for no hand.
        period: s, > 0, how often the wrench is sampled.
    """

    def __init__(self, plant, model, hand, period=0.01):
        super().__init__()
        self.hand = checked_instance("hand", hand, HandForce, HandForce)
        self.period = positive("period", period)
        self._body_index = model.tcp_frame.body().index()
        self._p_BoBq_B = (model.tcp_frame.GetFixedPoseInBodyFrame()
                          .translation())
        self._wrench_at = HandSchedule(self.hand)
        self._wrench = self.DeclareDiscreteState(self._wrench_at(0.0))
        if self.hand.times:
            self.DeclarePeriodicDiscreteUpdateEvent(self.period, 0.0,
                                                    self._sample)
        held = {self.discrete_state_ticket(self._wrench)}
        self.DeclareAbstractOutputPort(
            "spatial_forces",
            lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc_spatial_forces, prerequisites_of_calc=held)
        self.DeclareVectorOutputPort(
            "force", 6, self._calc_force, prerequisites_of_calc=held)

    def _sample(self, context, discrete_state):
        discrete_state.set_value(
            self._wrench, self._wrench_at(context.get_time()))

    def _calc_spatial_forces(self, context, output):
        if not self.hand.times:
            output.set_value([])
            return
        wrench = context.get_discrete_state(self._wrench).CopyToVector()
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = self._body_index
        applied.p_BoBq_B = self._p_BoBq_B
        applied.F_Bq_W = SpatialForce(tau=wrench[3:], f=wrench[:3])
        output.set_value([applied])

    def _calc_force(self, context, output):
        output.SetFromVector(
            context.get_discrete_state(self._wrench).CopyToVector())


def add_hand(builder, plant, model, hand, period=0.01):
    """Adds a HandForceSource "hand" (the wrench sampled every `period`
    s) to `builder` and connects it to the finalized `plant`'s
    applied_spatial_force input, which must be free; returns it."""
    if not plant.is_finalized():
        raise ValueError("plant is not finalized, which is not allowed: "
                         "call plant.Finalize() before add_hand")
    source = builder.AddSystem(HandForceSource(plant, model, hand,
                                                period))
    source.set_name("hand")
    builder.Connect(source.GetOutputPort("spatial_forces"),
                    plant.get_applied_spatial_force_input_port())
    return source
