"""The scripted scene of the simulated station: static obstacles, people
walking scheduled paths, a person's hand on the tool. In a scenario file
(loaded with `yaml_load_typed`, then drake_wbc.validation.validate)::

    cylinders: [{name: pillar, position: [2.0, 1.0], radius: 0.15,
                 height: 2.5}]
    boxes: [{name: wall, center: [1.2, 0.0, 1.0], size: [0.1, 3.0, 2.0]}]
    people: [{name: alice, times: [0, 10], waypoints: [[3, -2], [3, 2]]}]
    hand: {times: [1, 1.5, 3, 3.5],
           forces: [[0, 0, 0], [0, 15, 0], [0, 15, 0], [0, 0, 0]]}

In a diagram, `add_static_obstacles` puts the obstacles into the plant
(drawn, touched), `add_people` the people (drawn, never touched; the LIDARs
take their positions) and `add_hand` the hand.
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    Cylinder,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    MakePhongIllustrationProperties,
    ProximityProperties,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import (
    CoulombFriction,
    ExternallyAppliedSpatialForce,
)
from pydrake.systems.framework import LeafSystem

from drake_wbc.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    checked_instance,
    non_negative,
    positive,
    validated_copy,
)

OBSTACLE_FRICTION = CoulombFriction(0.6, 0.5)  # static, dynamic
OBSTACLE_DISSIPATION = 10.0  # s/m, Hunt-Crossley (Lagged, Similar), the pad's
OBSTACLE_RELAXATION_TIME = 0.01  # s, the Kelvin-Voigt dissipation of SAP
OBSTACLE_RESOLUTION_HINT = 0.05  # m, a rigid cylinder's largest mesh edge
CYLINDER_COLOR = [0.55, 0.57, 0.62, 1.0]  # RGBA, grey
BOX_COLOR = [0.78, 0.74, 0.66, 1.0]  # beige
PERSON_COLOR = [0.25, 0.38, 0.62, 1.0]  # blue clothes


def _empty(value):
    return isinstance(value, (list, tuple)) and not value


def _times(name, value, allow_empty=False):
    """`value` as a list of strictly increasing times (s)."""
    if allow_empty and _empty(value):
        return []
    times = as_vector(name, value)
    if times.size == 0:
        raise ValueError(f"{name} = [] is not allowed: must hold at least "
                         "one time")
    if np.any(np.diff(times) <= 0.0):
        raise ValueError(f"{name} = {times.tolist()} is not allowed: must "
                         "be strictly increasing")
    return times.tolist()


@dataclass
class CylinderObstacle:
    """An upright cylinder standing on the floor (z = 0), e.g. a pillar.

    Attributes:
        name: non-empty, unique in the scene.
        position: [x, y] of its axis in the world, m.
        radius, height: m, > 0.
    """

    name: str = "cylinder"
    position: list[float] = field(default_factory=lambda: [0.0, 0.0])
    radius: float = 0.1
    height: float = 1.0

    def __post_init__(self):
        self.position = as_vector("position", self.position, 2).tolist()
        positive("radius", self.radius)
        positive("height", self.height)


@dataclass
class BoxObstacle:
    """A box turned about the vertical by `yaw`: a wall, a table, a crate.

    Attributes:
        name: non-empty, unique in the scene.
        center: [x, y, z] of its centre in the world, m.
        size: [sx, sy, sz] its side lengths along its own axes, m, > 0.
        yaw: rad, its rotation about the world's z axis.
    """

    name: str = "box"
    center: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.5])
    size: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    yaw: float = 0.0

    def __post_init__(self):
        self.center = as_vector("center", self.center, 3).tolist()
        self.size = [positive(f"size[{i}]", s)
                     for i, s in enumerate(as_vector("size", self.size, 3))]
        as_scalar("yaw", self.yaw)


@dataclass
class WalkingPerson:
    """A person, an upright cylinder, walking a piecewise-linear path.

    The person stands at the first waypoint until times[0], is at
    waypoints[i] at times[i], and stands at the last one afterwards.

    Attributes:
        name: non-empty, unique in the scene.
        radius, height: m, > 0.
        times: [t0, t1, ...] s, strictly increasing.
        waypoints: [[x, y], ...] in the world, m, one per time.
        repeat: s; 0 walks the schedule once, a period of at least
            times[-1] - times[0] starts it again every `repeat` s after
            times[0] (end at the first waypoint for a loop).
    """

    name: str = "person"
    radius: float = 0.25
    height: float = 1.75
    times: list[float] = field(default_factory=lambda: [0.0])
    waypoints: list[list[float]] = field(
        default_factory=lambda: [[0.0, 0.0]])
    repeat: float = 0.0

    def __post_init__(self):
        positive("radius", self.radius)
        positive("height", self.height)
        self.times = _times("times", self.times)
        self.waypoints = as_matrix("waypoints", self.waypoints,
                                   (len(self.times), 2)).tolist()
        span = self.times[-1] - self.times[0]
        if non_negative("repeat", self.repeat) and self.repeat < span:
            raise ValueError(
                f"repeat = {self.repeat!r} is not allowed: must be 0 (no "
                f"repeat) or at least the schedule's length {span!r} s "
                "(times[-1] - times[0])")


@dataclass
class HandForce:
    """A person's hand on the tool: a force at the tool centre point, and
    optionally a twist of the tool (a torque about that point).

    Piecewise-linear in time, zero before the first and after the last
    time (so a smooth schedule starts and ends with a zero wrench).

    Attributes:
        times: [t0, t1, ...] s, strictly increasing; empty for no hand.
        forces: [[fx, fy, fz], ...] N in the world frame, one per time.
        torques: [[tx, ty, tz], ...] N m in the world frame about the tool
            centre point, one per time; empty (the default) for none.
    """

    times: list[float] = field(default_factory=list)
    forces: list[list[float]] = field(default_factory=list)
    torques: list[list[float]] = field(default_factory=list)

    def __post_init__(self):
        self.times = _times("times", self.times, allow_empty=True)
        rows = (len(self.times), 3)
        self.forces = ([] if not self.times and _empty(self.forces) else
                       as_matrix("forces", self.forces, rows).tolist())
        self.torques = ([] if _empty(self.torques) else
                        as_matrix("torques", self.torques, rows).tolist())


@dataclass
class Scene:
    """Everything scripted around the robot (see the module's example).

    Attributes:
        cylinders: upright cylinders on the floor.
        boxes: boxes (walls, tables, crates).
        people: walking people.
        hand: the hand on the tool (an empty schedule or None: no hand).

    The names of all obstacles and people must differ.
    """

    cylinders: list[CylinderObstacle] = field(default_factory=list)
    boxes: list[BoxObstacle] = field(default_factory=list)
    people: list[WalkingPerson] = field(default_factory=list)
    hand: HandForce = field(default_factory=HandForce)

    def __post_init__(self):
        seen = {}
        for key, kind in (("cylinders", CylinderObstacle),
                          ("boxes", BoxObstacle), ("people", WalkingPerson)):
            for i, item in enumerate(getattr(self, key)):
                where = f"{key}[{i}]"
                if not isinstance(item, kind):
                    raise ValueError(f"{where} = {item!r} is not allowed: "
                                     f"must be a {kind.__name__}")
                if not isinstance(item.name, str) or not item.name:
                    raise ValueError(f"{where}.name = {item.name!r} is not "
                                     "allowed: must be a non-empty string")
                if item.name in seen:
                    raise ValueError(
                        f"{where}.name = {item.name!r} is not allowed: "
                        f"{seen[item.name]} has that name already, and "
                        "names must be unique in the scene")
                seen[item.name] = f"{where}.name"
        self.hand = checked_instance("hand", self.hand, HandForce,
                                     HandForce)


def person_positions(people, t):
    """Returns the [x, y] (N, 2) of the validated WalkingPerson list
    `people` in the world at time `t` (s)."""
    t = as_scalar("t", t)
    positions = np.zeros((len(people), 2))
    for i, person in enumerate(people):
        s, t0 = t, person.times[0]
        if person.repeat > 0.0 and t > t0:
            s = t0 + (t - t0) % person.repeat
        path = np.asarray(person.waypoints)
        positions[i] = [np.interp(s, person.times, path[:, k])
                        for k in range(2)]
    return positions


def hand_wrench(hand, t):
    """Returns the wrench (6,) [f; tau] of the validated HandForce `hand`
    on the tool at time `t` (s): N and N m about the tool centre point, in
    the world; zero outside its times."""
    t = as_scalar("t", t)
    if not hand.times:
        return np.zeros(6)
    columns = np.asarray(hand.forces)
    if hand.torques:
        columns = np.hstack([columns, hand.torques])
    wrench = np.zeros(6)
    for k in range(columns.shape[1]):
        wrench[k] = np.interp(t, hand.times, columns[:, k], left=0.0,
                              right=0.0)
    return wrench


def planar_shapes(scene, height):
    """The static obstacles of the validated `scene` cut by a horizontal
    plane, as a 2-D LIDAR at `height` (m above the floor) sees them.

    An obstacle appears only if its vertical extent spans `height` (bounds
    included); people move and are not included (see `person_positions`).

    Returns:
        (circles, boxes): circles (K, 3), rows [cx, cy, r], and boxes
        (L, 5), rows [cx, cy, half_x, half_y, yaw], in the world, m, rad.
    """
    z = as_scalar("height", height)
    circles = [[*c.position, c.radius] for c in scene.cylinders
               if 0.0 <= z <= c.height]
    boxes = [[b.center[0], b.center[1], b.size[0] / 2, b.size[1] / 2, b.yaw]
             for b in scene.boxes if abs(z - b.center[2]) <= b.size[2] / 2]
    return (np.array(circles, dtype=float).reshape(-1, 3),
            np.array(boxes, dtype=float).reshape(-1, 5))


def add_static_obstacles(plant, scene):
    """Adds the scene's cylinders and boxes to `plant`, fixed to the world.

    Each gets an illustration geometry "<name>_visual" (no perception
    role: the robot has no camera) and a rigid hydroelastic collision
    geometry "<name>": the compliant pad presses on a wall over a patch
    whose stiffness is the pad's alone (a wall is far stiffer than foam),
    with friction and the dissipation of each discrete approximation
    (OBSTACLE_*). Against the robot's non-hydroelastic geometry the plant
    falls back to point contact.

    Args:
        plant: a MultibodyPlant with a SceneGraph, not yet finalized.
        scene: a Scene (validated here).

    Returns:
        dict[str, GeometryId]: each obstacle's collision geometry by name,
        e.g. to find its contacts in the plant's contact results.
    """
    if plant.is_finalized():
        raise ValueError("plant is finalized, which is not allowed: add "
                         "the obstacles before plant.Finalize()")
    if not plant.geometry_source_is_registered():
        raise ValueError("plant has no SceneGraph, which is not allowed: "
                         "make it with AddMultibodyPlantSceneGraph")
    scene = validated_copy(scene)
    shapes = [(c.name, RigidTransform([*c.position, c.height / 2]),
               Cylinder(c.radius, c.height), CYLINDER_COLOR,
               min(OBSTACLE_RESOLUTION_HINT, c.radius / 2))
              for c in scene.cylinders]
    shapes += [(b.name, RigidTransform(RollPitchYaw(0.0, 0.0, b.yaw),
                                       b.center),
                Box(*b.size), BOX_COLOR, OBSTACLE_RESOLUTION_HINT)
               for b in scene.boxes]
    world = plant.world_body()
    ids = {}
    for name, X, shape, color, hint in shapes:
        visual = GeometryInstance(X, shape, f"{name}_visual")
        visual.set_illustration_properties(
            MakePhongIllustrationProperties(color))
        plant.RegisterVisualGeometry(world, visual)
        properties = ProximityProperties()
        AddRigidHydroelasticProperties(hint, properties)
        AddContactMaterial(OBSTACLE_DISSIPATION, None, OBSTACLE_FRICTION,
                           properties)
        properties.AddProperty("material", "relaxation_time",
                               OBSTACLE_RELAXATION_TIME)
        ids[name] = plant.RegisterCollisionGeometry(world, X, shape, name,
                                                    properties)
    return ids


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
      below the person; to scene_graph.get_source_pose_port(source_id).

    The bodies are illustration cylinders: drawn (in Meshcat at
    /drake/visualizer/people/<name>, also in recordings), never touched.

    Args:
        people: list of WalkingPerson (validated; names must differ).
    """

    def __init__(self, people):
        super().__init__()
        self.people = validated_copy(Scene(people=list(people))).people
        self.source_id = None
        self._frame_ids = []
        self.DeclareVectorOutputPort(
            "positions", 2 * len(self.people), self._calc_positions,
            prerequisites_of_calc={self.time_ticket()})

    def _calc_positions(self, context, output):
        output.SetFromVector(
            person_positions(self.people, context.get_time()).ravel())

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
            self._calc_poses, prerequisites_of_calc={self.time_ticket()})
        return self.source_id

    def _calc_poses(self, context, output):
        poses = output.get_mutable_value()
        poses.clear()
        xy = person_positions(self.people, context.get_time())
        for frame_id, (x, y) in zip(self._frame_ids, xy, strict=True):
            poses.set_value(frame_id, RigidTransform([x, y, 0.0]))


def add_people(builder, scene_graph, people):
    """Adds a PeopleSource "people" of `people` to `builder`, registers
    their bodies with `scene_graph` and connects their poses; returns it."""
    source = PeopleSource(people)
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
      applied_spatial_force input.
    - force: (6) [f; tau] in the world, N and N m: that wrench, the
      torque about the tool centre point, for logs.

    The tool centre point is fixed in the tool body and the force is in
    the world frame, as ExternallyAppliedSpatialForce takes it: no body
    poses are needed, the outputs depend on time alone.

    Args:
        plant: the MultibodyPlant that holds the robot.
        model: the McrModel that add_mcr returned for `plant`.
        hand: a HandForce (validated); None for no hand.
    """

    def __init__(self, plant, model, hand):
        super().__init__()
        self.hand = validated_copy(
            checked_instance("hand", hand, HandForce, HandForce))
        self._body_index = model.tcp_frame.body().index()
        self._p_BoBq_B = (model.tcp_frame.GetFixedPoseInBodyFrame()
                          .translation())
        self.DeclareAbstractOutputPort(
            "spatial_forces",
            lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc_spatial_forces,
            prerequisites_of_calc={self.time_ticket()})
        self.DeclareVectorOutputPort(
            "force", 6, self._calc_force,
            prerequisites_of_calc={self.time_ticket()})

    def _calc_spatial_forces(self, context, output):
        wrench = hand_wrench(self.hand, context.get_time())
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = self._body_index
        applied.p_BoBq_B = self._p_BoBq_B
        applied.F_Bq_W = SpatialForce(tau=wrench[3:], f=wrench[:3])
        output.set_value([applied])

    def _calc_force(self, context, output):
        output.SetFromVector(hand_wrench(self.hand, context.get_time()))


def add_hand(builder, plant, model, hand):
    """Adds a HandForceSource "hand" to `builder` and connects it to the
    finalized `plant`'s applied_spatial_force input, which must be free;
    returns it."""
    if not plant.is_finalized():
        raise ValueError("plant is not finalized, which is not allowed: "
                         "call plant.Finalize() before add_hand")
    source = builder.AddSystem(HandForceSource(plant, model, hand))
    source.set_name("hand")
    builder.Connect(source.GetOutputPort("spatial_forces"),
                    plant.get_applied_spatial_force_input_port())
    return source
