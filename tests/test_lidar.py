"""The simulated LIDARs against hit distances worked out by hand, and the
Drake system's sampling in a simulation."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_wbc.math.validation import validate
from drake_wbc.station.lidar import (
    LidarParameters,
    ObstaclePointMerger,
    PlanarLidar,
    cast_rays,
    scan,
    scan_points,
)

ORIGIN = np.zeros(2)
FAR = 25.0


def rotation(yaw):
    return np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])


@pytest.mark.parametrize("D, r", [(2.0, 0.5), (1.0, 0.25), (10.0, 3.0)])
@pytest.mark.parametrize("heading", [0.0, 0.7, -2.5])
def test_circle_straight_ahead_is_hit_at_distance_minus_radius(D, r,
                                                               heading):
    centre = D * np.array([np.cos(heading), np.sin(heading)])
    ranges = cast_rays(ORIGIN, [heading], [[*centre, r]], None, FAR)
    assert ranges[0] == pytest.approx(D - r, abs=1e-12)


@pytest.mark.parametrize("phi", [0.05, -0.1, 0.2])
def test_oblique_ray_meets_the_circle_at_the_first_root(phi):
    D, r = 3.0, 0.8
    expected = D * np.cos(phi) - np.sqrt(r**2 - (D * np.sin(phi)) ** 2)
    ranges = cast_rays(ORIGIN, [phi], [[D, 0.0, r]], None, FAR)
    assert ranges[0] == pytest.approx(expected, abs=1e-12)


def test_tangent_ray_grazes_and_a_ray_just_outside_misses():
    # Centre (2, 0.5), r = 0.5: the x axis touches the circle at (2, 0).
    assert cast_rays(ORIGIN, [0.0], [[2.0, 0.5, 0.5]], None, FAR)[0] == 2.0
    missed = cast_rays(ORIGIN, [0.0], [[2.0, 0.5 + 1e-9, 0.5]], None, FAR)
    assert missed[0] == np.inf


def test_shapes_behind_the_scanner_are_not_seen():
    ranges = cast_rays(ORIGIN, [0.0], [[-2.0, 0.0, 0.5]],
                       [[-3.0, 0.0, 0.5, 0.5, 0.3]], FAR)
    assert ranges[0] == np.inf


@pytest.mark.parametrize("y0", [0.0, 0.2, -0.3])
def test_rectangle_rotated_45_degrees(y0):
    # A square of half size a turned by 45 degrees about (D, 0) is the
    # diamond |x - D| + |y| <= a sqrt(2): a ray along x at height y0 meets
    # it at x = D - a sqrt(2) + |y0|.
    D, a = 2.0, 0.5
    box = [[D, 0.0, a, a, np.pi / 4]]
    ranges = cast_rays([0.0, y0], [0.0], None, box, FAR)
    assert ranges[0] == pytest.approx(D - a * np.sqrt(2) + abs(y0),
                                      abs=1e-12)


@pytest.mark.parametrize("phi", [0.0, 0.3, -0.4])
def test_ray_meets_the_near_face_of_a_rectangle(phi):
    # Axis-aligned 2 x 4 m rectangle centred 4 m ahead: near face x = 3.
    ranges = cast_rays(ORIGIN, [phi], None, [[4.0, 0.0, 1.0, 2.0, 0.0]], FAR)
    assert ranges[0] == pytest.approx(3.0 / np.cos(phi), abs=1e-12)
    # The same rectangle turned a quarter turn: near face x = 2.
    turned = cast_rays(ORIGIN, [0.0], None,
                       [[4.0, 0.0, 1.0, 2.0, np.pi / 2]], FAR)
    assert turned[0] == pytest.approx(2.0, abs=1e-12)


def test_ray_parallel_to_a_rectangle_side():
    box = [[3.0, 0.0, 1.0, 0.5, 0.0]]
    along_edge = cast_rays([0.0, 0.5], [0.0], None, box, FAR)
    assert along_edge[0] == 2.0
    assert cast_rays([0.0, 0.6], [0.0], None, box, FAR)[0] == np.inf


def test_nearest_shape_wins():
    circles = [[5.0, 0.0, 0.5], [2.0, 0.0, 0.25]]
    box = [[3.5, 0.0, 0.1, 1.0, 0.0]]
    for shapes in (circles, circles[::-1]):
        assert cast_rays(ORIGIN, [0.0], shapes, box, FAR)[0] == 1.75
    assert cast_rays(ORIGIN, [0.0], circles[:1], box, FAR)[0] == (
        pytest.approx(3.4, abs=1e-12))


def test_origin_inside_a_shape_reports_zero_and_scan_no_return():
    angles = np.linspace(-np.pi, np.pi, 7)
    inside_circle = cast_rays(ORIGIN, angles, [[0.1, 0.0, 0.5]], None, FAR)
    inside_box = cast_rays(ORIGIN, angles, None,
                           [[0.2, 0.1, 0.5, 0.3, 1.0]], FAR)
    np.testing.assert_array_equal(inside_circle, 0.0)
    np.testing.assert_array_equal(inside_box, 0.0)
    blocked = scan([0, 0, 0], [0, 0, 0], None, [[0.1, 0.0, 0.5]], None, 0)
    assert np.all(blocked == np.inf)


def test_no_return_beyond_max_range_and_below_min_range():
    params = LidarParameters(num_beams=1, min_range=0.05, max_range=5.0)
    at_limit = cast_rays(ORIGIN, [0.0], [[5.5, 0.0, 0.5]], None, 5.0)
    assert at_limit[0] == 5.0
    assert cast_rays(ORIGIN, [0.0], [[5.6, 0.0, 0.5]], None, 5.0)[0] == (
        np.inf)

    def reading(distance):
        centre = distance + 0.3
        return scan([0, 0, 0], [0, 0, 0], params, [[centre, 0, 0.3]], None,
                    0)[0]

    assert reading(4.9) == pytest.approx(4.9, abs=1e-12)
    assert reading(5.1) == np.inf
    assert reading(0.06) == pytest.approx(0.06, abs=1e-12)
    assert reading(0.04) == np.inf


def assert_on_circle(points_b, base_pose, centre, r):
    points_w = base_pose[:2] + points_b @ rotation(base_pose[2]).T
    distances = np.linalg.norm(points_w - centre, axis=1)
    np.testing.assert_allclose(distances, r, atol=1e-9)


@pytest.mark.parametrize("base_pose, mount", [
    ([1.0, -0.5, 0.7], [0.3, 0.2, 2.0]),
    ([-2.0, 1.0, -2.8], [-0.4, -0.3, -2.356]),
])
def test_points_land_on_the_shapes_boundary(base_pose, mount):
    base_pose = np.array(base_pose)
    params = LidarParameters()
    circle = np.array([2.0, 1.5, 0.4])
    box = np.array([-1.0, 3.0, 0.6, 0.3, 0.5])
    for circles, boxes in (([circle], None), (None, [box])):
        ranges = scan(base_pose, mount, params, circles, boxes, 0)
        points = scan_points(ranges, params.beam_angles, mount)
        assert points.shape == (np.isfinite(ranges).sum(), 2)
        assert points.shape[0] > 20
        if circles is not None:
            assert_on_circle(points, base_pose, circle[:2], circle[2])
        else:
            world = base_pose[:2] + points @ rotation(base_pose[2]).T
            local = (world - box[:2]) @ rotation(box[4])
            np.testing.assert_allclose(
                np.max(np.abs(local) / box[2:4], axis=1), 1.0, atol=1e-9)


def test_a_person_a_metre_away_spans_the_right_angle():
    params = LidarParameters()
    d, r = 1.0, 0.25
    ranges = scan([0, 0, 0], [0, 0, 0], params, [[d, 0.0, r]], None, 0)
    hit = np.isfinite(ranges)
    width = 2.0 * np.arcsin(r / d)
    assert abs(hit.sum() * params.beam_spacing - width) <= (
        params.beam_spacing)
    assert params.beam_angles[hit].mean() == pytest.approx(0.0, abs=1e-12)
    assert ranges[hit].min() == pytest.approx(d - r, abs=1e-12)


def test_beams_of_the_tim571():
    params = LidarParameters()
    angles = params.beam_angles
    assert angles.shape == (811,)
    assert angles[0] == pytest.approx(-np.radians(135.0))
    assert angles[-1] == pytest.approx(np.radians(135.0))
    assert np.degrees(params.beam_spacing) == pytest.approx(1.0 / 3.0)
    np.testing.assert_allclose(np.diff(angles), params.beam_spacing)


@pytest.mark.parametrize("num_beams", [4, 360, 811])
def test_a_full_turn_scans_each_direction_once(num_beams):
    # A 360 degree scanner's beams lie 2 pi / N apart; the first and the
    # last were both at +-pi, one direction scanned twice, its return
    # reported twice.
    params = LidarParameters(field_of_view=2.0 * np.pi, num_beams=num_beams)
    angles = params.beam_angles
    assert params.beam_spacing == pytest.approx(2.0 * np.pi / num_beams)
    np.testing.assert_allclose(np.diff(angles), params.beam_spacing)
    assert angles[0] == pytest.approx(-np.pi)
    gap = angles[0] + 2.0 * np.pi - angles[-1]
    assert gap == pytest.approx(params.beam_spacing)
    # A wall all around, a square of half side 2 m: one return a beam,
    # each where the beam's ray meets the wall.
    walls = [[0.0, 2.05, 3.0, 0.05, 0.0], [0.0, -2.05, 3.0, 0.05, 0.0],
             [2.05, 0.0, 0.05, 3.0, 0.0], [-2.05, 0.0, 0.05, 3.0, 0.0]]
    ranges = scan([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], params, None, walls, 0)
    expected = 2.0 / np.maximum(np.abs(np.cos(angles)),
                                np.abs(np.sin(angles)))
    np.testing.assert_allclose(ranges, expected, rtol=1e-12)
    points = scan_points(ranges, angles, [0.0, 0.0, 0.0])
    assert len(np.unique(np.round(points, 9), axis=0)) == num_beams


def test_noise_is_a_function_of_seed_and_tick_only():
    params = LidarParameters(range_noise_std=0.01, seed=7)
    wall = [[3.0, 0.0, 0.1, 10.0, 0.0]]

    def noisy(tick, p=params):
        return scan([0, 0, 0], [0, 0, 0], p, None, wall, tick)

    first = noisy(5)
    for tick in (0, 9, 4):
        noisy(tick)
    np.testing.assert_array_equal(noisy(5), first)
    assert not np.array_equal(noisy(6), first)
    other_seed = LidarParameters(range_noise_std=0.01, seed=8)
    assert not np.array_equal(noisy(5, other_seed), first)
    exact = scan([0, 0, 0], [0, 0, 0], LidarParameters(), None, wall, 5)
    hit = np.isfinite(exact)
    errors = first[hit] - exact[hit]
    # A few hundred beams: the sample deviation is within 15% of the set
    # value with overwhelming probability (relative s.d. 1/sqrt(2n) < 5%).
    assert errors.size > 300
    assert np.std(errors) == pytest.approx(0.01, rel=0.15)


def moving_person_station(params, path):
    """A lidar at the world origin with one moving circle on `path`."""
    builder = DiagramBuilder()
    lidar = builder.AddSystem(PlanarLidar(params, moving_radii=[0.3]))
    pose = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    person = builder.AddSystem(TrajectorySource(path))
    builder.Connect(pose.get_output_port(),
                    lidar.GetInputPort("base_pose"))
    builder.Connect(person.get_output_port(),
                    lidar.GetInputPort("moving_positions"))
    return lidar, Simulator(builder.Build())


def test_scans_are_taken_at_multiples_of_the_period_and_held():
    params = LidarParameters(range_noise_std=0.005, seed=3)
    path = PiecewisePolynomial.FirstOrderHold(
        [0.0, 3.0], np.array([[2.0, 2.0], [-1.5, 1.5]]))
    lidar, simulator = moving_person_station(params, path)
    context = lidar.GetMyContextFromRoot(simulator.get_context())
    ranges_port = lidar.GetOutputPort("ranges")
    assert np.all(ranges_port.Eval(context) == np.inf)

    def expected(k):
        centre = path.value(k / params.rate).ravel()
        return scan([0, 0, 0], [0, 0, 0], params, [[*centre, 0.3]], None, k)

    simulator.Initialize()
    np.testing.assert_allclose(ranges_port.Eval(context), expected(0),
                               atol=1e-12)
    # Odd multiples of 1/200 s never fall on a multiple of 1/15 s.
    previous, changes = None, 0
    for j in range(100):
        t = (2 * j + 1) / 200.0
        simulator.AdvanceTo(t)
        k = int(np.floor(t * params.rate))
        ranges = ranges_port.Eval(context)
        np.testing.assert_allclose(ranges, expected(k), atol=1e-12)
        points = lidar.GetOutputPort("points").Eval(context)
        np.testing.assert_allclose(
            points, scan_points(ranges, params.beam_angles, np.zeros(3)))
        if previous is not None and not np.array_equal(ranges, previous):
            changes += 1
        previous = ranges
    assert changes == int(np.floor(0.995 * params.rate))


def test_initialize_scan_stores_the_scan_of_the_inputs_without_a_tick():
    params = LidarParameters(range_noise_std=0.01)
    lidar = PlanarLidar(params, mount=[0.3, 0.2, np.pi / 4],
                        circles=[[2.0, 2.0, 0.3]], moving_radii=[0.25, 0.4])
    context = lidar.CreateDefaultContext()
    lidar.GetInputPort("base_pose").FixValue(context, [0.1, 0.0, 0.2])
    lidar.GetInputPort("moving_positions").FixValue(context,
                                                    [1.0, 2.0, 0.0, 3.0])
    assert lidar.GetOutputPort("points").Eval(context).shape == (0, 2)
    lidar.initialize_scan(context)
    circles = [[2.0, 2.0, 0.3], [1.0, 2.0, 0.25], [0.0, 3.0, 0.4]]
    expected = scan([0.1, 0.0, 0.2], [0.3, 0.2, np.pi / 4], params, circles,
                    None, 0)
    np.testing.assert_array_equal(
        lidar.GetOutputPort("ranges").Eval(context), expected)
    lidar.initialize_scan(context)
    np.testing.assert_array_equal(
        lidar.GetOutputPort("ranges").Eval(context), expected)


def test_ports_and_no_direct_feedthrough():
    still = PlanarLidar()
    assert still.num_input_ports() == 1
    assert still.get_input_port(0).get_name() == "base_pose"
    assert [still.get_output_port(i).get_name() for i in range(2)] == [
        "ranges", "points"]
    assert not still.HasAnyDirectFeedthrough()
    moving = PlanarLidar(moving_radii=[0.3, 0.3])
    assert moving.GetInputPort("moving_positions").size() == 4
    assert not moving.HasAnyDirectFeedthrough()


def test_merger_concatenates_in_input_order():
    merger = ObstaclePointMerger(3)
    context = merger.CreateDefaultContext()
    arrays = [np.arange(4.0).reshape(2, 2), np.zeros((0, 2)),
              -np.arange(6.0).reshape(3, 2)]
    for i, points in enumerate(arrays):
        merger.GetInputPort(f"points_{i}").FixValue(
            context, AbstractValue.Make(points))
    merged = merger.GetOutputPort("points").Eval(context)
    np.testing.assert_array_equal(merged, np.vstack(arrays))
    merger.GetInputPort("points_1").FixValue(
        context, AbstractValue.Make(np.zeros((2, 3))))
    with pytest.raises(ValueError, match="points_1 = .* has shape"):
        merger.GetOutputPort("points").Eval(context)


def test_two_lidars_merge_into_the_controllers_obstacle_points():
    circles = [[1.5, 1.2, 0.3], [-1.4, -1.1, 0.3]]
    builder = DiagramBuilder()
    pose = builder.AddSystem(ConstantVectorSource([0.5, 0.2, 0.3]))
    merger = builder.AddSystem(ObstaclePointMerger(2))
    mounts = ([0.4, 0.3, np.pi / 4], [-0.4, -0.3, -3 * np.pi / 4])
    for i, mount in enumerate(mounts):
        lidar = builder.AddSystem(PlanarLidar(mount=mount, circles=circles))
        builder.Connect(pose.get_output_port(),
                        lidar.GetInputPort("base_pose"))
        builder.Connect(lidar.GetOutputPort("points"),
                        merger.GetInputPort(f"points_{i}"))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    points = merger.GetOutputPort("points").Eval(
        merger.GetMyContextFromRoot(simulator.get_context()))
    expected = [scan_points(scan([0.5, 0.2, 0.3], mount, None, circles,
                                 None, 0), LidarParameters().beam_angles,
                            mount) for mount in mounts]
    assert all(len(e) > 10 for e in expected)
    np.testing.assert_array_equal(points, np.vstack(expected))


@pytest.mark.parametrize("fields, name", [
    (dict(num_beams=0), "num_beams"),
    (dict(num_beams=2.5), "num_beams"),
    (dict(field_of_view=7.0), "field_of_view"),
    (dict(field_of_view=0.0), "field_of_view"),
    (dict(min_range=1.0, max_range=1.0), "max_range"),
    (dict(min_range=-0.1), "min_range"),
    (dict(rate=0.0), "rate"),
    (dict(range_noise_std=-0.01), "range_noise_std"),
    (dict(seed=-1), "seed"),
])
def test_parameters_are_checked(fields, name):
    with pytest.raises(ValueError, match=name):
        LidarParameters(**fields)


def test_parameters_load_from_yaml():
    loaded = validate(yaml_load_typed(
        schema=LidarParameters, data="num_beams: 271\nrate: 10.0\n"))
    assert loaded.num_beams == 271 and loaded.rate == 10.0
    assert loaded.max_range == 25.0
    assert yaml_load_typed(schema=LidarParameters,
                           data=yaml_dump_typed(loaded)) == loaded
    bad = yaml_load_typed(schema=LidarParameters, data="max_range: 0.01\n")
    with pytest.raises(ValueError, match="max_range = 0.01"):
        validate(bad)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match=r"circles\[1, 2\] = -0.2"):
        cast_rays(ORIGIN, [0.0], [[1, 1, 0.2], [2, 2, -0.2]], None, FAR)
    with pytest.raises(ValueError, match=r"boxes\[0, 3\]"):
        cast_rays(ORIGIN, [0.0], None, [[1, 1, 0.2, 0.0, 0.0]], FAR)
    with pytest.raises(ValueError, match="boxes = .* has shape"):
        cast_rays(ORIGIN, [0.0], None, [[1, 1, 0.2, 0.3]], FAR)
    with pytest.raises(ValueError, match="tick"):
        scan([0, 0, 0], [0, 0, 0], None, None, None, -1)
    with pytest.raises(ValueError, match="ranges"):
        scan_points([1.0, np.nan], [0.0, 0.1], [0, 0, 0])
    with pytest.raises(ValueError, match=r"moving_radii\[1\]"):
        PlanarLidar(moving_radii=[0.3, 0.0])
    with pytest.raises(ValueError, match="params"):
        PlanarLidar(params="tim571")
