"""The scripted scene: schedules against hand values, the YAML schema and
its errors, the LIDAR's cut of the obstacles, and the scene's systems in
simulations of the robot (a hand on the tool, the pad against a wall,
people drawn in Meshcat)."""

import re

import numpy as np
import pytest
from locked_robot import sensing_weld_reaction, sensor_reading
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.geometry import Meshcat, MeshcatVisualizer, Role, SceneGraph
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_wbc.math.validation import validate
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    add_robot,
    joint_position_indices,
    make_robot_plant,
)
from drake_wbc.station.scene import (
    BoxObstacle,
    CylinderObstacle,
    HandForce,
    Scene,
    WalkingPerson,
    add_static_obstacles,
    hand_wrench,
    person_positions,
    planar_shapes,
)
from drake_wbc.station.scene_sources import (
    HandForceSource,
    PeopleSource,
    add_hand,
    add_people,
)

FULL_SCENE = """
cylinders:
- {name: pillar, position: [2.0, 1.0], radius: 0.15, height: 2.5}
boxes:
- {name: wall, center: [1.2, 0.0, 1.0], size: [0.1, 3.0, 2.0]}
- {name: table, center: [-1.0, 2.0, 0.4], size: [1.2, 0.8, 0.8], yaw: 0.5}
people:
- {name: alice, times: [0, 10], waypoints: [[3, -2], [3, 2]]}
- {name: bob, radius: 0.3, height: 1.9, times: [2, 4, 6],
   waypoints: [[0, 4], [2, 4], [0, 4]], repeat: 5}
hand:
  times: [1, 1.5, 3, 3.5]
  forces: [[0, 0, 0], [0, 15, -5], [0, 15, -5], [0, 0, 0]]
"""


def load(text):
    return validate(yaml_load_typed(schema=Scene, data=text))


def test_people_walk_piecewise_linear_paths():
    walker = WalkingPerson(name="walker", times=[1.0, 3.0, 4.0],
                           waypoints=[[0.0, 0.0], [2.0, 4.0], [2.0, 5.0]])
    still = WalkingPerson(name="still", times=[0.0],
                          waypoints=[[-1.0, 7.0]])
    expected = {0.0: [0.0, 0.0], 1.0: [0.0, 0.0], 2.0: [1.0, 2.0],
                3.5: [2.0, 4.5], 4.0: [2.0, 5.0], 60.0: [2.0, 5.0]}
    for t, xy in expected.items():
        np.testing.assert_allclose(person_positions([walker, still], t),
                                   [xy, [-1.0, 7.0]], atol=1e-12)
    assert person_positions([], 1.0).shape == (0, 2)


def test_a_repeating_walk_starts_again_every_period():
    loop = WalkingPerson(times=[1.0, 3.0], waypoints=[[0.0, 0.0], [2.0, 0.0]],
                         repeat=4.0)
    expected = {0.0: 0.0, 2.0: 1.0, 4.0: 2.0, 5.0: 0.0, 6.0: 1.0,
                8.5: 2.0, 10.0: 1.0}
    for t, x in expected.items():
        np.testing.assert_allclose(person_positions([loop], t), [[x, 0.0]],
                                   atol=1e-12)


def test_the_hand_wrench_is_piecewise_linear_and_zero_outside():
    hand = HandForce(times=[1.0, 2.0, 4.0],
                     forces=[[0, 0, 0], [10, -4, 2], [10, -4, 2]])
    expected = {0.5: [0, 0, 0], 1.0: [0, 0, 0], 1.5: [5, -2, 1],
                3.0: [10, -4, 2], 4.0: [10, -4, 2], 4.001: [0, 0, 0]}
    for t, force in expected.items():
        np.testing.assert_allclose(hand_wrench(hand, t), force + [0] * 3,
                                   atol=1e-12)
    step = HandForce(times=[1.0, 2.0], forces=[[3, 0, 0], [3, 0, 0]])
    np.testing.assert_array_equal(hand_wrench(step, 0.999), [0] * 6)
    np.testing.assert_array_equal(hand_wrench(step, 1.0), [3, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(hand_wrench(HandForce(), 1.0), [0] * 6)
    twist = HandForce(times=[0.0, 2.0], forces=[[0, 0, 0], [2, 0, 0]],
                      torques=[[0, 0, 0], [0, 1, -4]])
    np.testing.assert_allclose(hand_wrench(twist, 0.5),
                               [0.5, 0, 0, 0, 0.25, -1], atol=1e-12)


def test_hand_torques_must_match_the_times():
    with pytest.raises(ValueError, match="torques"):
        HandForce(times=[0.0, 1.0], forces=[[0, 0, 0], [1, 0, 0]],
                  torques=[[0, 0, 1]])


def test_a_full_scene_loads_and_round_trips_through_yaml():
    scene = load(FULL_SCENE)
    assert scene.cylinders == [CylinderObstacle(
        name="pillar", position=[2.0, 1.0], radius=0.15, height=2.5)]
    assert scene.boxes[1] == BoxObstacle(
        name="table", center=[-1.0, 2.0, 0.4], size=[1.2, 0.8, 0.8], yaw=0.5)
    assert scene.boxes[0].yaw == 0.0
    assert scene.people[0].radius == 0.25 and scene.people[0].height == 1.75
    assert scene.people[1].repeat == 5.0
    assert scene.hand.forces[1] == [0.0, 15.0, -5.0]
    again = load(yaml_dump_typed(scene))
    assert again == scene
    # The checks keep lists as lists, so the loader can assign them again.
    assert type(again.people[1].waypoints) is list
    assert type(again.people[1].waypoints[0]) is list
    assert validate(again) == scene
    assert load("{}") == Scene()


@pytest.mark.parametrize("text, message", [
    ("people: [{name: a, times: [0, 1, 1], waypoints: [[0, 0], [1, 0], "
     "[2, 0]]}]",
     "people[0].times = [0.0, 1.0, 1.0] is not allowed: must be strictly "
     "increasing"),
    ("people: [{name: a, times: [0, 1], waypoints: [[0, 0], [1, 0], "
     "[2, 0]]}]",
     "people[0].waypoints = [[0. 0.] [1. 0.] [2. 0.]] has shape (3, 2), "
     "which is not allowed: must have shape (2, 2)"),
    ("people: [{name: a, radius: -0.1}]",
     "people[0].radius = -0.1 is not allowed: must be greater than 0"),
    ("people: [{name: a, times: [0, 2], waypoints: [[0, 0], [1, 0]], "
     "repeat: 1}]", "people[0].repeat = 1.0 is not allowed"),
    ("cylinders: [{name: a}, {name: b, radius: -0.5}]",
     "cylinders[1].radius = -0.5 is not allowed: must be greater than 0"),
    ("cylinders: [{name: ''}]", "cylinders[0].name = '' is not allowed"),
    ("boxes: [{name: a, size: [1, 1, 0]}]",
     "boxes[0].size[2] = 0.0 is not allowed: must be greater than 0"),
    ("hand: {times: [0, 2, 1], forces: [[0, 0, 0], [1, 0, 0], [0, 0, 0]]}",
     "hand.times = [0.0, 2.0, 1.0] is not allowed: must be strictly "
     "increasing"),
    ("hand: {times: [0, 1], forces: [[0, 0, 0]]}",
     "hand.forces = [[0. 0. 0.]] has shape (1, 3), which is not allowed: "
     "must have shape (2, 3)"),
    ("cylinders: [{name: a}]\nboxes: [{name: a}]",
     "boxes[0].name = 'a' is not allowed: cylinders[0].name has that name "
     "already"),
    ("people: [{name: bob}, {name: bob}]",
     "people[1].name = 'bob' is not allowed: people[0].name has that name "
     "already"),
])
def test_errors_in_a_loaded_scene_name_the_field(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        load(text)


@pytest.mark.parametrize("text, message", [
    ("hand: {times: [0, 1], forces: [[0, 0, 0], [0, 0, 1e20]]}",
     "hand.forces[1][2] = 1e+20 N is not allowed: must lie within +-1000 N"),
    ("hand: {times: [0, 1], forces: [[0, 0, 0], [0, 0, 0]],"
     " torques: [[0, -150, 0], [0, 0, 0]]}",
     "hand.torques[0][1] = -150.0 N m is not allowed: must lie within "
     "+-100 N m"),
])
def test_a_hand_beyond_any_persons_strength_is_refused_when_loaded(
        text, message):
    # A push of 1e20 N loaded and then failed the run in Drake's contact
    # solver ("The Hessian of the momentum cost ... is NaN").
    with pytest.raises(ValueError, match=re.escape(message)):
        load(text)
    edge = HandForce(times=[0, 1], forces=[[0, 0, 0], [-1000, 0, 1000]],
                     torques=[[0, 0, 0], [100, -100, 0]])
    np.testing.assert_array_equal(hand_wrench(edge, 1.0),
                                  [-1000, 0, 1000, 100, -100, 0])


def test_errors_in_direct_construction_name_the_argument():
    with pytest.raises(ValueError, match=re.escape("radius = -1.0")):
        CylinderObstacle(radius=-1.0)
    with pytest.raises(ValueError, match=re.escape("cylinders[0] = 3")):
        Scene(cylinders=[3])
    with pytest.raises(ValueError, match=re.escape("people[1].name = 'p'")):
        PeopleSource([WalkingPerson(name="p"), WalkingPerson(name="p")])
    with pytest.raises(ValueError, match="hand = 'push'"):
        HandForceSource(*make_robot_plant(), hand="push")


def test_planar_shapes_cut_the_obstacles_at_the_scan_height():
    scene = Scene(
        cylinders=[CylinderObstacle(name="post", position=[1.0, 2.0],
                                    radius=0.2, height=1.0)],
        boxes=[BoxObstacle(name="shelf", center=[3.0, -1.0, 1.5],
                           size=[0.4, 2.0, 1.0], yaw=0.3),
               BoxObstacle(name="table", center=[-2.0, 0.5, 0.4],
                           size=[1.0, 0.6, 0.8])])
    circles, boxes = planar_shapes(scene, 0.2)
    np.testing.assert_array_equal(circles, [[1.0, 2.0, 0.2]])
    np.testing.assert_array_equal(boxes, [[-2.0, 0.5, 0.5, 0.3, 0.0]])
    circles, boxes = planar_shapes(scene, 1.2)
    assert circles.shape == (0, 3)
    np.testing.assert_array_equal(boxes, [[3.0, -1.0, 0.2, 1.0, 0.3]])
    for height in (-0.1, 2.5):
        circles, boxes = planar_shapes(scene, height)
        assert circles.shape == (0, 3) and boxes.shape == (0, 5)
    circles, boxes = planar_shapes(scene, 1.0)  # the bounds are included
    assert len(circles) == 1 and len(boxes) == 1


def test_static_obstacles_are_drawn_and_touched_but_not_perceived():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    ids = add_static_obstacles(plant, load(FULL_SCENE))
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    assert set(ids) == {"pillar", "wall", "table"}
    for name, geometry_id in ids.items():
        properties = inspector.GetProximityProperties(geometry_id)
        assert inspector.GetName(geometry_id) == name
        # Rigid hydroelastic: a compliance type but no modulus.
        assert properties.HasProperty("hydroelastic", "compliance_type")
        assert not properties.HasProperty("hydroelastic",
                                          "hydroelastic_modulus")
        friction = properties.GetProperty("material", "coulomb_friction")
        assert friction.dynamic_friction() > 0
        assert properties.GetProperty("material", "relaxation_time") > 0
    visual = inspector.GetGeometries(inspector.world_frame_id(),
                                     Role.kIllustration)
    assert len(visual) == 3
    assert not inspector.GetGeometries(inspector.world_frame_id(),
                                       Role.kPerception)
    with pytest.raises(ValueError, match="plant is finalized"):
        add_static_obstacles(plant, Scene())
    with pytest.raises(ValueError, match="plant has no SceneGraph"):
        add_static_obstacles(MultibodyPlant(time_step=1e-3), Scene())


def test_people_source_positions_and_geometry_poses():
    people = load(FULL_SCENE).people
    builder = DiagramBuilder()
    scene_graph = builder.AddSystem(SceneGraph())
    source = add_people(builder, scene_graph, people)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    source_context = source.GetMyContextFromRoot(context)
    query_port = scene_graph.get_query_output_port()
    inspector = scene_graph.model_inspector()
    frames = inspector.GetAllFrameIds()
    names = {inspector.GetName(f): f for f in frames}
    assert {"people::alice", "people::bob"} <= set(names)
    for frame_id in (names["people::alice"], names["people::bob"]):
        (body,) = inspector.GetGeometries(frame_id)
        assert inspector.GetIllustrationProperties(body) is not None
        assert inspector.GetProximityProperties(body) is None
        assert inspector.GetPerceptionProperties(body) is None
    for t, alice, bob in [(0.0, [3, -2], [0, 4]), (2.5, [3, -1], [0.5, 4]),
                          (5.0, [3, 0], [1, 4]), (8.0, [3, 1.2], [1, 4])]:
        # The drawn poses are those of the last sample (here at t).
        context.SetTime(t)
        source_context.SetDiscreteState(
            source.EvalUniquePeriodicDiscreteUpdate(source_context)
            .get_vector().CopyToVector())
        context.SetTime(t + 0.5 * source.period)
        positions = source.GetOutputPort("positions").Eval(source_context)
        if t < 8.0:  # walking: the positions move on, the drawing holds
            assert np.max(np.abs(positions - [*alice, *bob])) > 1e-4
        context.SetTime(t)
        positions = source.GetOutputPort("positions").Eval(source_context)
        np.testing.assert_allclose(positions, [*alice, *bob], atol=1e-12)
        context.SetTime(t + 0.5 * source.period)
        poses = source.GetOutputPort("geometry_pose").Eval(source_context)
        query = query_port.Eval(scene_graph.GetMyContextFromRoot(context))
        for name, xy in (("alice", alice), ("bob", bob)):
            frame_id = names[f"people::{name}"]
            X = poses.value(frame_id)
            np.testing.assert_allclose(X.translation(), [*xy, 0.0],
                                       atol=1e-12)
            np.testing.assert_allclose(X.rotation().matrix(), np.eye(3))
            np.testing.assert_allclose(
                query.GetPoseInWorld(frame_id).translation(), [*xy, 0.0],
                atol=1e-12)


def test_meshcat_draws_the_people_in_a_recording():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    scene = load(FULL_SCENE)
    add_static_obstacles(plant, scene)
    plant.Finalize()
    add_people(builder, scene_graph, scene.people)
    meshcat = Meshcat()
    visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph,
                                                meshcat)
    simulator = Simulator(builder.Build())
    visualizer.StartRecording()
    simulator.AdvanceTo(0.2)
    visualizer.StopRecording()
    visualizer.PublishRecording()
    for path in ("people/alice/body", "people/bob/body", "wall_visual"):
        assert meshcat.HasPath(f"/drake/visualizer/{path}"), path
    assert visualizer.get_mutable_recording().frame(0.2) > 0
    assert len(meshcat.StaticHtml()) > 0


def test_hand_force_source_outputs():
    plant, model = make_robot_plant()
    hand = HandForce(times=[0.0, 1.0], forces=[[0, 0, 0], [4, -2, 6]],
                     torques=[[0, 0, 0], [1, 0, -3]])
    source = HandForceSource(plant, model, hand)
    context = source.CreateDefaultContext()
    # The wrench is sampled (here at 0.5 s) and held until the next sample.
    context.SetTime(0.5)
    context.SetDiscreteState(source.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector())
    context.SetTime(0.5 + 0.9 * source.period)
    (applied,) = source.GetOutputPort("spatial_forces").Eval(context)
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    assert applied.body_index == tool.index()
    np.testing.assert_allclose(applied.p_BoBq_B, [0.0, 0.0, 0.1])
    np.testing.assert_allclose(applied.F_Bq_W.translational(), [2, -1, 3])
    np.testing.assert_allclose(applied.F_Bq_W.rotational(), [0.5, 0, -1.5])
    np.testing.assert_allclose(source.GetOutputPort("force").Eval(context),
                               [2, -1, 3, 0.5, 0, -1.5])
    # A simulation samples it every period from t = 0.
    simulator = Simulator(source)
    simulator.AdvanceTo(0.25 + 1e-9)
    np.testing.assert_allclose(
        source.GetOutputPort("force").Eval(simulator.get_context()),
        [1, -0.5, 1.5, 0.25, 0, -0.75], atol=1e-12)
    # No hand: no force, at any time.
    idle = HandForceSource(plant, model, HandForce())
    context = idle.CreateDefaultContext()
    context.SetTime(0.5)
    assert idle.GetOutputPort("spatial_forces").Eval(context) == []
    np.testing.assert_array_equal(
        idle.GetOutputPort("force").Eval(context), np.zeros(6))
    with pytest.raises(ValueError, match="plant is not finalized"):
        add_hand(DiagramBuilder(), MultibodyPlant(time_step=1e-3), model,
                 hand)


def _horizontal_tool():
    """The home pose with joint 5 turned so that the tool points along the
    world's x axis (base at the origin, mount at rest); returns (q_a,
    X_WT), X_WT the tool centre point's pose."""
    plant, model = make_robot_plant()
    context = plant.CreateDefaultContext()
    indices = joint_position_indices(model.arm_joints)
    q_a = HOME_ARM_POSITIONS.copy()
    for _ in range(2):  # joint 5 pitches the tool: exact up to round-off
        q = plant.GetPositions(context)
        q[indices] = q_a
        plant.SetPositions(context, q)
        axis = model.tcp_frame.CalcPoseInWorld(context).rotation().col(2)
        q_a[4] += np.arctan2(axis[2], axis[0])
    X_WT = model.tcp_frame.CalcPoseInWorld(context)
    assert abs(X_WT.rotation().col(2)[2]) < 1e-9
    return q_a, X_WT


def _simulate(q_a, hand, duration, scene=None, free_base_x_damping=None):
    """The robot with every joint locked at arm configuration `q_a` (base
    at the origin, mount at rest), or all but base_x, which then has the
    given damping (N s/m); the hand on the tool; SAP contact. Returns
    (plant, model, plant_context, obstacle ids)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
    model = add_robot(plant)
    ids = add_static_obstacles(plant, scene) if scene else {}
    plant.Finalize()
    add_hand(builder, plant, model, hand)
    simulator = Simulator(builder.Build())
    context = plant.GetMyMutableContextFromRoot(
        simulator.get_mutable_context())
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    base_x = plant.GetJointByName("base_x", model.base)
    for i in plant.GetJointIndices():
        joint = plant.get_joint(i)
        free = free_base_x_damping is not None and joint is base_x
        if joint.num_velocities() == 1 and not free:
            joint.Lock(context)
    if free_base_x_damping is not None:
        base_x.SetDampingVector(context, [free_base_x_damping])
    simulator.AdvanceTo(duration)
    return plant, model, context, ids


def test_the_hand_force_shows_up_in_the_sensing_weld():
    """The weld's reaction (on the tool, at and in the measurement frame M)
    changes by minus the hand's wrench about M; the sensor's reading, its
    negative, by plus."""
    q_a = HOME_ARM_POSITIONS + np.array([0.3, 0.2, -0.1, 0.4, 0.2, 0.5])
    force_W = np.array([4.0, -6.0, 9.0])
    torque_W = np.array([0.5, 1.0, -2.0])  # about the tool centre point
    hand = HandForce(times=[0.0, 1.0], forces=[force_W, force_W],
                     torques=[torque_W, torque_W])
    pushed = _simulate(q_a, hand, 0.05)[:3]
    alone = _simulate(q_a, HandForce(), 0.05)[:3]
    plant, model, context = pushed
    X_WM = model.ft_measurement_frame.CalcPoseInWorld(context)
    p_WT = model.tcp_frame.CalcPoseInWorld(context).translation()
    R_MW = X_WM.rotation().inverse().matrix()
    wrench_M = np.concatenate([
        R_MW @ force_W,
        R_MW @ (np.cross(p_WT - X_WM.translation(), force_W) + torque_W)])
    change = (sensing_weld_reaction(*pushed).get_coeffs()
              - sensing_weld_reaction(*alone).get_coeffs())
    scale = 1e-6 * np.linalg.norm(force_W)
    np.testing.assert_allclose(np.concatenate([change[3:], change[:3]]),
                               -wrench_M, atol=scale)
    np.testing.assert_allclose(
        sensor_reading(*pushed) - sensor_reading(*alone), wrench_M,
        atol=scale)


def test_the_wall_holds_the_pad_against_the_hand():
    """The tool points at a wall whose face touches the pad; base_x alone
    is free (heavily damped), so the hand pushes the whole robot, pad
    first, into the wall until the contact force balances the push: the
    sensor then reads the tool's weight alone."""
    q_a, X_WT = _horizontal_tool()
    face_x, _, z = X_WT.translation()
    wall = BoxObstacle(name="wall", center=[face_x + 0.05, 0.0, z],
                       size=[0.1, 1.0, 1.0])
    push = 10.0  # the paper's wiping force
    hand = HandForce(times=[0.0, 0.1, 10.0],
                     forces=[[0, 0, 0], [push, 0, 0], [push, 0, 0]])
    plant, model, context, ids = _simulate(
        q_a, hand, 6.0, Scene(boxes=[wall]), free_base_x_damping=1500.0)
    # The contact force on the pad balances the push.
    contacts = plant.get_contact_results_output_port().Eval(context)
    assert contacts.num_hydroelastic_contacts() == 1
    info = contacts.hydroelastic_contact_info(0)
    surface = info.contact_surface()
    sign = -1.0 if surface.id_M() == ids["wall"] else 1.0
    assert ids["wall"] in (surface.id_M(), surface.id_N())
    on_pad = sign * info.F_Ac_W().translational()
    np.testing.assert_allclose(on_pad, [-push, 0.0, 0.0], atol=1e-3 * push)
    # The robot moved in by the pad's compression alone (a soft sponge,
    # about 3 mm at 10 N; less than its half thickness, 10 mm).
    base_x = plant.GetJointByName("base_x", model.base)
    assert 1e-3 < base_x.get_translation(context) < 1e-2
    # The reading is that of the tool's weight alone.
    weight_only = _simulate(q_a, HandForce(), 0.05)[:3]
    difference = sensor_reading(plant, model, context) - sensor_reading(
        *weight_only)
    np.testing.assert_allclose(difference[:3], 0.0, atol=1e-3 * push)
    # The soft pad, slightly tilted, shifts its centre of pressure off the
    # tool centre point by about a millimetre.
    np.testing.assert_allclose(difference[3:], 0.0, atol=2e-3 * push)
