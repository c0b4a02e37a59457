"""The scripted scene of the simulated station: static obstacles, people
walking scheduled paths, a person's hand on the tool. In a scenario file
(loaded with `yaml_load_typed`, then drake_wbc.math.validation.validate)::

    cylinders: [{name: pillar, position: [2.0, 1.0], radius: 0.15,
                 height: 2.5}]
    boxes: [{name: wall, center: [1.2, 0.0, 1.0], size: [0.1, 3.0, 2.0]}]
    people: [{name: alice, times: [0, 10], waypoints: [[3, -2], [3, 2]]}]
    hand: {times: [1, 1.5, 3, 3.5],
           forces: [[0, 0, 0], [0, 15, 0], [0, 15, 0], [0, 0, 0]],
           impedance: {stiffness: 300, damping: 8, mass: 0.2}}

In a diagram, `add_static_obstacles` puts the obstacles into the plant
(drawn, touched); drake_wbc.station.scene_sources adds the people (drawn,
never touched; the LIDARs take their positions) and the hand.
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    Cylinder,
    GeometryInstance,
    MakePhongIllustrationProperties,
    ProximityProperties,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import (
    CoulombFriction,
)

from drake_wbc.math.kernels import body_for
from drake_wbc.math.movement import interpolated_row
from drake_wbc.math.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    checked_instance,
    non_negative,
    positive,
    within_site,
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
        self.position = within_site("position", as_vector(
            "position", self.position, 2).tolist())
        within_site("radius", positive("radius", self.radius))
        within_site("height", positive("height", self.height))


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
        self.center = within_site("center", as_vector(
            "center", self.center, 3).tolist())
        self.size = [within_site(f"size[{i}]", positive(f"size[{i}]", s))
                     for i, s in enumerate(as_vector("size", self.size, 3))]
        as_scalar("yaw", self.yaw)


@dataclass
class WalkingPerson:
    """A person, an upright cylinder, walking a piecewise-linear path.

    The person stands at the first waypoint until times[0], is at
    waypoints[i] at times[i], and stands at the last one afterwards.

    Attributes:
        name: non-empty, unique in the scene.
        radius, height: m, > 0; a LIDAR sees the person as a circle of
            the radius if its scan plane is at most `height` high.
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
        within_site("radius", positive("radius", self.radius))
        within_site("height", positive("height", self.height))
        self.times = _times("times", self.times)
        self.waypoints = within_site("waypoints", as_matrix(
            "waypoints", self.waypoints, (len(self.times), 2)).tolist())
        span = self.times[-1] - self.times[0]
        if non_negative("repeat", self.repeat) and self.repeat < span:
            raise ValueError(
                f"repeat = {self.repeat!r} is not allowed: must be 0 (no "
                f"repeat) or at least the schedule's length {span!r} s "
                "(times[-1] - times[0])")


HAND_STIFFNESS = 300.0
"""N/m, a relaxed grip's hand stiffness: measured human hand stiffness
in a maintained posture is 100 to 1000 N/m, larger with co-contraction
(Mussa-Ivaldi, Hogan, Bizzi 1985, J. Neurosci. 5(10):2732; Tsuji,
Morasso, Goto, Ito 1995, Biol. Cybern. 72:475)."""

HAND_DAMPING = 8.0
"""N s/m, a relaxed grip's hand viscosity: 3 to 30 N s/m in the same
measurements (Tsuji et al. 1995; Dolan, Friedman, Ebner 1993, IEEE
Trans. SMC 23(3):698), the upper end for a stiff, co-contracted grip."""

HAND_MASS = 0.2
"""kg, the mass that moves rigidly with the tool in a grip: the palm and
fingers; the forearm's share (0.5 to 2 kg of endpoint inertia, Tsuji et
al. 1995) moves behind the soft tissue of the grip and is left out."""

MAX_HAND_FORCE = 1000.0
"""N, the largest push of a hand a schedule may give, per component: a
person's strongest push, braced and with both hands, is about 0.5 kN;
the wrist sensor saturates at 300 N. Drake's contact solver fails on a
force of 1e20 N in the middle of a run, which this check refuses when
the scene is made."""

MAX_HAND_TORQUE = 100.0
"""N m, the largest twist of a hand a schedule may give, per component:
a person's strongest wrist twist is about 10 to 20 N m; the wrist sensor
saturates at 30 N m."""

HAND_REACTION_TIME = 0.3
"""s, how fast the hand's intention follows the tool it guides: a
person's voluntary reaction, 0.15 to 0.3 s; slower changes of the tool's
motion are what the person wants, faster ones meet the arm's impedance."""


@dataclass
class HandImpedance:
    """The impedance of a person's hand that holds the tool.

    The hand grips the tool centre point through a spring and a damper
    (the same in x, y and z) towards where the person means the hand to
    be: the point the hand has been following (the tool's motion slower
    than `reaction_time`) plus the schedule's force divided by the
    stiffness, so at rest the hand pushes with the scheduled force. A
    light touch is a low stiffness and damping, a stiff grip a high one.
    The twist (the schedule's torques) stays a scripted torque.

    Attributes:
        stiffness: N/m, > 0 (HAND_STIFFNESS).
        damping: N s/m, >= 0 (HAND_DAMPING).
        mass: kg, > 0, what moves with the tool (HAND_MASS); the person
            carries its weight.
        reaction_time: s, > 0 (HAND_REACTION_TIME).
    """

    stiffness: float = HAND_STIFFNESS
    damping: float = HAND_DAMPING
    mass: float = HAND_MASS
    reaction_time: float = HAND_REACTION_TIME

    def __post_init__(self):
        self.stiffness = positive("stiffness", self.stiffness)
        self.damping = non_negative("damping", self.damping)
        self.mass = positive("mass", self.mass)
        self.reaction_time = positive("reaction_time", self.reaction_time)


def _within(name, rows, limit, unit, what):
    """Checks that every entry of `rows` (a list of lists) lies within
    +-`limit`; a ValueError naming the first entry that does not."""
    if not rows:
        return
    values = np.asarray(rows, dtype=float)
    bad = np.argwhere(np.abs(values) > limit)
    if bad.size:
        i, j = (int(k) for k in bad[0])
        raise ValueError(
            f"{name}[{i}][{j}] = {float(values[i, j])!r} {unit} is not "
            f"allowed: must lie within +-{limit:g} {unit} ({what})")


@dataclass
class HandForce:
    """A person's hand on the tool: a force at the tool centre point, and
    optionally a twist of the tool (a torque about that point).

    Piecewise-linear in time, zero before the first and after the last
    time (so a smooth schedule starts and ends with a zero wrench).

    Attributes:
        times: [t0, t1, ...] s, strictly increasing; empty for no hand.
        forces: [[fx, fy, fz], ...] N in the world frame, one per time,
            each within +-MAX_HAND_FORCE.
        torques: [[tx, ty, tz], ...] N m in the world frame about the tool
            centre point, one per time, each within +-MAX_HAND_TORQUE;
            empty (the default) for none.
        impedance: None (the default) for a pure force source, the
            scheduled forces applied whatever the tool does; a
            HandImpedance for a hand that holds the tool (throughout the
            run) and pushes it with those forces at rest.
    """

    times: list[float] = field(default_factory=list)
    forces: list[list[float]] = field(default_factory=list)
    torques: list[list[float]] = field(default_factory=list)
    impedance: HandImpedance | None = None

    def __post_init__(self):
        self.times = _times("times", self.times, allow_empty=True)
        rows = (len(self.times), 3)
        self.forces = ([] if not self.times and _empty(self.forces) else
                       as_matrix("forces", self.forces, rows).tolist())
        self.torques = ([] if _empty(self.torques) else
                        as_matrix("torques", self.torques, rows).tolist())
        _within("forces", self.forces, MAX_HAND_FORCE, "N",
                "MAX_HAND_FORCE, more than any person's push")
        _within("torques", self.torques, MAX_HAND_TORQUE, "N m",
                "MAX_HAND_TORQUE, more than any person's twist")
        if self.impedance is not None:
            self.impedance = checked_instance(
                "impedance", self.impedance, HandImpedance, HandImpedance)
            if not self.times:
                raise ValueError(
                    "impedance is not allowed without times: a hand that "
                    "holds the tool needs a schedule (times and forces)")


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
    return Walks(people)(as_scalar("t", t))


class Walks:
    """`person_positions` of a fixed validated list of people, with their
    schedules as float lists once: a call takes a float time as it is."""

    def __init__(self, people):
        self._walks = [
            ([float(x) for x in p.times],
             np.asarray(p.waypoints, dtype=float).tolist(),
             float(p.times[0]), float(p.repeat)) for p in people]
        self._interpolated = body_for(interpolated_row, float)

    def __call__(self, t):
        rows = []
        for times, path, t0, repeat in self._walks:
            s = t0 + (t - t0) % repeat if repeat > 0.0 and t > t0 else t
            rows.append(self._interpolated(s, times, path))
        return np.array(rows, dtype=float).reshape(len(rows), 2)


def hand_wrench(hand, t):
    """Returns the wrench (6,) [f; tau] of the validated HandForce `hand`
    on the tool at time `t` (s): N and N m about the tool centre point, in
    the world; zero outside its times."""
    return HandSchedule(hand)(as_scalar("t", t))


class HandSchedule:
    """`hand_wrench` of a fixed validated HandForce, with its schedule as
    float lists once: a call takes a float time as it is."""

    def __init__(self, hand):
        self._times = [float(x) for x in hand.times]
        columns = np.zeros((len(hand.times), 6))
        if hand.times:
            columns[:, :3] = hand.forces
            if hand.torques:
                columns[:, 3:] = hand.torques
        self._rows = columns.tolist()
        self._interpolated = body_for(interpolated_row, float)

    def __call__(self, t):
        if not self._times:
            return np.zeros(6)
        return np.array(self._interpolated(t, self._times, self._rows, 0.0,
                                           0.0), dtype=float)


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


def people_at_height(scene, height):
    """The indices (in `scene.people`) of the people of the validated
    `scene` whom a horizontal plane at `height` (m above the floor) cuts,
    as `planar_shapes` cuts the cylinders: those whose height reaches it
    (bounds included). A 2-D LIDAR at `height` sees them, as circles of
    their radius; it scans over the heads of the others."""
    z = as_scalar("height", height)
    return [i for i, person in enumerate(scene.people)
            if 0.0 <= z <= person.height]


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
        scene: a Scene.

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
    scene = checked_instance("scene", scene, Scene, Scene)
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
