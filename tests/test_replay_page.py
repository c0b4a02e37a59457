"""The Meshcat replay of a simulated run (drake_wbc.experiments.replay).

The browser tests record a 2 s run of the robot driving along x, open the
written replay in a real headless browser and check the pictures: the robot
is drawn (it differs from a picture of an empty scene), and it has moved to
the right between two moments of the replay, which a script added to a copy
of the page selects with the page's own animation controls (see
tests/browser.py). They skip, saying why, where no browser is installed,
and each browser run is killed after 60 s.
"""

import base64
import re

import numpy as np
import pytest
from browser import (
    difference_mask,
    distinct_colours,
    find_browser,
    mask_centroid,
    read_png,
    screenshot,
    seek_copy,
)
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Cylinder,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    MakePhongIllustrationProperties,
    Rgba,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink
from shipped_names import ARM_JOINTS, BASE_JOINTS

from drake_wbc.experiments.replay import (
    PATHS_PREFIX,
    ReplayRecorder,
    quiet_meshcat,
    write_static_html,
)
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    add_robot,
    joint_position_indices,
)

DURATION = 2.0
"""The recorded run, s."""

BASE_SPEED = 0.3
"""The base's commanded speed along the world's x, m/s."""

MOMENTS = (0.2, 1.9)
"""The two replay times compared, s: the base is 0.5 m apart."""


def _page_commands(html):
    """The decoded Meshcat commands embedded in a static page."""
    blobs = re.findall(r"data:application/octet-binary;base64,([^\"']+)",
                       html)
    return [base64.b64decode(blob) for blob in blobs]


def _record_run(page, duration=DURATION):
    """Simulates the robot driving along x with its arm locked at home and
    writes the replay, with the tool centre point's path, to `page`.

    Returns:
        (page, tcp_W): the written page and the (N, 3) tool path.
    """
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.set_discrete_contact_approximation(
        plant.get_discrete_contact_approximation().kSap
    )
    model = add_robot(plant)
    for name in BASE_JOINTS:
        # p = 0: a stiff velocity servo on each base joint.
        plant.GetJointActuatorByName(name, model.base).set_controller_gains(
            PdControllerGains(p=0.0, d=3e4)
        )
    plant.Finalize()
    desired = np.zeros(2 * len(BASE_JOINTS))
    desired[len(BASE_JOINTS)] = BASE_SPEED
    source = builder.AddSystem(ConstantVectorSource(desired))
    builder.Connect(source.get_output_port(),
                    plant.get_desired_state_input_port(model.base))
    log = builder.AddSystem(VectorLogSink(
        plant.num_multibody_states(), publish_period=1.0 / 30.0
    ))
    builder.Connect(plant.get_state_output_port(), log.get_input_port())
    recorder = ReplayRecorder.add_to(builder, scene_graph)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = plant.GetPositions(plant_context)
    q[joint_position_indices(model.arm_joints)] = (
        HOME_ARM_POSITIONS
    )
    plant.SetPositions(plant_context, q)
    for name in ARM_JOINTS:
        plant.GetJointByName(name, model.arm).Lock(plant_context)
    simulator.AdvanceTo(duration)
    states = log.FindLog(context).data()
    scratch = plant.CreateDefaultContext()
    tcp_W = []
    for x in states.T:
        plant.SetPositionsAndVelocities(scratch, x)
        tcp_W.append(model.tcp_frame.CalcPoseInWorld(scratch).translation())
    tcp_W = np.array(tcp_W)
    recorder.add_path("tcp", tcp_W)
    return recorder.write(page), tcp_W


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay")
    return _record_run(folder / "run" / "replay.html")


@pytest.fixture(scope="module")
def browser():
    path, reason = find_browser()
    if path is None:
        pytest.skip(f"the replay page's browser test needs Chromium or "
                    f"Chrome: {reason}")
    return path


@pytest.fixture(scope="module")
def empty_scene(browser, tmp_path_factory):
    """A picture of an empty Meshcat scene: background, grid and axes."""
    folder = tmp_path_factory.mktemp("empty_scene")
    page = write_static_html(quiet_meshcat(), folder / "empty.html")
    screenshot(browser, page, folder / "empty.png", budget_ms=500)
    return read_png(folder / "empty.png")


def _check_robot_drawn(image, empty_scene, label):
    """Checks the picture is a rendered scene with the robot in it and
    returns the mask of the robot's pixels."""
    assert image.shape == empty_scene.shape, label
    colours = distinct_colours(image)
    assert colours >= 256, (
        f"{label}: only {colours} distinct colours; the page looks blank "
        "(did WebGL fail?)"
    )
    robot = difference_mask(image, empty_scene)
    share = robot.mean()
    # The robot covers about 1.5 % of an 800 x 600 window in the default
    # view; a failed scene or a wrong camera would show nothing or chaos.
    assert 0.005 < share < 0.3, (
        f"{label}: {share:.2%} of the pixels differ from an empty scene; "
        "expected the robot to cover about 1.5 %"
    )
    return robot


def test_replay_page_shows_the_robot_at_two_moments(
    recorded_run, browser, empty_scene, tmp_path
):
    page, _ = recorded_run
    images, robots = [], []
    for time in MOMENTS:
        copy = seek_copy(page, tmp_path / f"at_{time}.html", time)
        png = tmp_path / f"at_{time}.png"
        status = screenshot(browser, copy, png, budget_ms=2000)
        assert status is not None and status.startswith(
            f"seeked {time} of"
        ), f"the page's animation was not seeked to {time} s: {status!r}"
        image = read_png(png)
        robots.append(_check_robot_drawn(image, empty_scene, f"t = {time}"))
        images.append(image)
    changed = difference_mask(*images, threshold=0.05).mean()
    assert changed > 0.005, (
        f"only {changed:.2%} of the pixels changed between t = "
        f"{MOMENTS[0]} and {MOMENTS[1]} s; the replay does not move"
    )
    # The base drove 0.5 m along +x, which the default camera shows as a
    # move to the right.
    shift = mask_centroid(robots[1])[0] - mask_centroid(robots[0])[0]
    assert shift > 20, (
        f"the robot moved {shift:.0f} pixels to the right between the two "
        "moments; expected it to drive right"
    )


def test_replay_page_as_written_shows_the_robot(
    recorded_run, browser, empty_scene, tmp_path
):
    page, _ = recorded_run
    png = tmp_path / "as_written.png"
    # The page plays its animation once it has loaded; 1.5 s of page time
    # shows the robot during or at the end of the run.
    assert screenshot(browser, page, png, budget_ms=1500) is None
    _check_robot_drawn(read_png(png), empty_scene, "the page as written")


def test_page_holds_the_animation_and_the_path(recorded_run):
    page, tcp_W = recorded_run
    html = page.read_text()
    assert html.lstrip().lower().startswith("<!doctype html")
    commands = _page_commands(html)
    animation = [c for c in commands if b"set_animation" in c]
    assert len(animation) == 1
    for body in (b"mcr_base/base_link", b"elfin5/link6",
                 b"ft300_wiping_tool/wiping_tool"):
        assert body in animation[0]
    assert any(b"paths/tcp" in c for c in commands)
    # The tool rode along with the base.
    assert tcp_W[-1, 0] - tcp_W[0, 0] == pytest.approx(
        BASE_SPEED * DURATION, abs=0.05
    )


class _Walker(LeafSystem):
    """A person as its own SceneGraph source: one cylinder walking along
    y, as another module registers people."""

    def __init__(self, scene_graph):
        super().__init__()
        self.source_id = scene_graph.RegisterSource("people")
        self.frame_id = scene_graph.RegisterFrame(
            self.source_id, GeometryFrame("alice")
        )
        body = GeometryInstance(
            RigidTransform([0.0, 0.0, 0.9]), Cylinder(0.2, 1.8), "alice_body"
        )
        body.set_illustration_properties(
            MakePhongIllustrationProperties([0.2, 0.5, 0.9, 1.0])
        )
        scene_graph.RegisterGeometry(self.source_id, self.frame_id, body)
        self.DeclareAbstractOutputPort(
            "poses", lambda: AbstractValue.Make(FramePoseVector()),
            self._calc_poses,
        )

    def _calc_poses(self, context, output):
        output.get_mutable_value().set_value(
            self.frame_id,
            RigidTransform([1.5, -1.0 + 0.5 * context.get_time(), 0.0]),
        )


def test_other_scene_graph_sources_are_animated(tmp_path):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    add_robot(plant)
    plant.Finalize()
    walker = builder.AddSystem(_Walker(scene_graph))
    builder.Connect(walker.get_output_port(),
                    scene_graph.get_source_pose_port(walker.source_id))
    recorder = ReplayRecorder.add_to(builder, scene_graph,
                                     publish_period=0.1)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    for k in range(11):
        context.SetTime(0.1 * k)
        diagram.ForcedPublish(context)
    page = recorder.write(tmp_path / "people.html")
    animation = [c for c in _page_commands(page.read_text())
                 if b"set_animation" in c]
    # The visualizer names a frame of another source by its own name.
    assert len(animation) == 1 and b"/alice" in animation[0]


def test_every_publish_gets_its_own_frame(tmp_path):
    builder = DiagramBuilder()
    _, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    recorder = ReplayRecorder.add_to(builder, scene_graph)
    animation = recorder.meshcat.get_mutable_recording()
    period = recorder.publish_period
    # Periodic publishes happen at k * period; floor(k * period * 30) is
    # k - 1 for some k (31, 62, ...), which the recorder compensates.
    frames = [animation.frame(k * period) for k in range(30 * 60 + 1)]
    assert frames == list(range(30 * 60 + 1))
    assert recorder.frames_per_second == pytest.approx(30.0)
    assert recorder.is_recording
    recorder.write(tmp_path / "empty_run.html")
    assert not recorder.is_recording


def test_a_minute_of_replay_stays_small(tmp_path):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_robot(plant)
    plant.Finalize()
    recorder = ReplayRecorder.add_to(builder, scene_graph)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    base = joint_position_indices(model.base_joints)
    arm = joint_position_indices(model.arm_joints)
    # Every body moves in every frame: the largest animation of the robot.
    for k in range(30 * 60 + 1):
        t = k / 30.0
        context.SetTime(t)
        q = plant.GetPositions(plant_context)
        q[base] = [0.3 * t, 0.2 * np.sin(t), 0.1 * t]
        q[arm] = HOME_ARM_POSITIONS + 0.3 * np.sin(t + np.arange(6))
        plant.SetPositions(plant_context, q)
        diagram.ForcedPublish(context)
    page = recorder.write(tmp_path / "deep" / "folder" / "minute.html")
    assert page.is_file()
    assert page.stat().st_size < 20e6


def test_add_path_checks_its_arguments():
    builder = DiagramBuilder()
    _, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    recorder = ReplayRecorder.add_to(builder, scene_graph)
    line = np.array([[0.0, 0.0, 0.1], [1.0, 0.5, 0.1], [2.0, 0.0, 0.1]])
    assert recorder.add_path("people/alice", line) == (
        f"{PATHS_PREFIX}/people/alice"
    )
    assert recorder.add_path("tcp", line, Rgba(0, 0, 1, 1), 2.0) == (
        f"{PATHS_PREFIX}/tcp"
    )
    with pytest.raises(ValueError, match="name"):
        recorder.add_path("", line)
    with pytest.raises(ValueError, match="name"):
        recorder.add_path("a//b", line)
    with pytest.raises(ValueError, match="points_W = .* has shape"):
        recorder.add_path("tcp", line[:, :2])
    with pytest.raises(ValueError, match="at least 2"):
        recorder.add_path("tcp", line[:1])
    with pytest.raises(ValueError, match="finite"):
        recorder.add_path("tcp", [[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match="rgba"):
        recorder.add_path("tcp", line, rgba=(1, 0, 0, 1))
    with pytest.raises(ValueError, match="line_width"):
        recorder.add_path("tcp", line, line_width=0.0)


def test_add_to_rejects_a_bad_publish_period():
    builder = DiagramBuilder()
    _, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    with pytest.raises(ValueError, match="publish_period"):
        ReplayRecorder.add_to(builder, scene_graph, publish_period=0.0)
