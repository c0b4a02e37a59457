"""Speed and separation from moving people (ISO/TS 15066): the protective
separation distance against its closed form, the tracker's velocity
against finite differences of the truth, and the base command limiter on
an ideal robot (its velocity is its command) scanned at 15 Hz: a person
walking head-on at 1.6 m/s and one stepping in ahead of the base at full
speed, one crossing behind and one walking away (neither may halt the
base), and the protective stop of a point inside the footprint."""

import math

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from shipped_names import (
    BASE_ACCELERATION_LIMITS,
    BASE_LIMITS,
    BASE_VELOCITY_LIMITS,
)

from drake_wbc.controller import build_controller
from drake_wbc.math import people as tracking
from drake_wbc.math.repulsion import footprint_gap
from drake_wbc.math.safety import (
    SafetyParameters,
    check_within_robot,
)
from drake_wbc.math.separation import (
    HUMAN_SPEED,
    HUMAN_SPEED_NEAR,
    PeopleSeparationParameters,
    ProtectiveTiming,
    people_rows,
    protective_separation,
    protective_speeds,
    protective_timing,
)
from drake_wbc.robot.description import load_robot_description, models_dir
from drake_wbc.stages import BaseCommandLimiter
from drake_wbc.station.lidar import LidarParameters, scan, scan_points

HALF = (0.4, 0.3)
H = 0.01
LAG = BASE_LIMITS["base_lag"]
"""s: the shipped base's velocity loop lag (its description's)."""
SCAN_TICKS = 7
SCAN = SCAN_TICKS * H
"""The scan period of the ideal runs: every 7th tick, 0.07 s (15 Hz is
0.067 s; the tracker's tests use the same period)."""
MOUNTS = ((0.4, 0.3, math.pi / 4), (-0.4, -0.3, -3 * math.pi / 4))
"""Two scanners on opposite corners of the footprint, as on the robot."""

LIDAR = LidarParameters()


# --- eq. (protective) -------------------------------------------------------


def test_the_protective_separation_is_its_closed_form():
    """S_p = v_h (T_r + T_s) + v_r T_r + S_s + C + Z_d + Z_r with
    T_s = 3 tau + v_r / a and S_s = v_r tau + v_r^2 / (2 a), term by term
    at the defaults: T_r = 1/15 + 0.02 + 0.01 s, tau = 0.3 s, a = 1."""
    people = PeopleSeparationParameters()
    timing = protective_timing(people, H, (1.0, 1.0, 1.0), LAG)
    t_r = 1.0 / 15.0 + 0.02 + 0.01
    assert timing == pytest.approx(ProtectiveTiming(t_r, 0.3, 1.0))
    margin = 0.2 + 0.05 + 0.02
    assert people.margin == pytest.approx(margin)
    for v_r, v_h in ((0.0, 1.6), (0.5, 1.6), (1.0, 2.0), (0.3, 0.0)):
        t_s = 0.9 + v_r / 1.0
        s_s = v_r * 0.3 + v_r ** 2 / 2.0
        expected = v_h * (t_r + t_s) + v_r * t_r + s_s + margin
        assert protective_separation(v_r, v_h, timing, margin) == \
            pytest.approx(expected, rel=1e-14)
    # The figures of the README: 1.86 m from a base at rest, 4.36 m from
    # one at full speed, for a person at 1.6 m/s.
    assert protective_separation(0.0, 1.6, timing, margin) == \
        pytest.approx(1.8647, abs=1e-4)
    assert protective_separation(1.0, 1.6, timing, margin) == \
        pytest.approx(4.3613, abs=1e-4)


def test_the_protective_speed_is_the_inverse_of_the_separation():
    timing = ProtectiveTiming(0.1, 0.25, 0.8)
    margin = 0.3
    d = np.linspace(0.0, 5.0, 101)
    for v_h in (1.6, 2.0, 2.7):
        v = protective_speeds(d, np.full(d.size, v_h), timing, margin)
        rest = protective_separation(0.0, v_h, timing, margin)
        assert np.all(v[d <= rest] == 0.0)
        beyond = d > rest
        assert np.all(v[beyond] > 0.0)
        np.testing.assert_allclose(
            protective_separation(v[beyond], v_h, timing, margin),
            d[beyond], rtol=1e-12)
        assert np.all(np.diff(v) >= 0.0)


def test_the_protective_speed_differentiates_in_autodiff():
    from pydrake.autodiffutils import AutoDiffXd

    timing = ProtectiveTiming(0.1, 0.3, 1.0)
    d, eps = 2.0, 1e-6
    v = protective_speeds(np.array([AutoDiffXd(d, [1.0])]),
                          np.array([1.6]), timing, 0.27)[0]
    ahead, behind = (protective_speeds(np.array([x]), np.array([1.6]),
                                       timing, 0.27)[0]
                     for x in (d + eps, d - eps))
    assert v.value() == pytest.approx(ahead / 2 + behind / 2, abs=1e-9)
    assert v.derivatives()[0] == pytest.approx(
        (ahead - behind) / (2 * eps), rel=1e-6)


def test_people_rows_use_iso_speed_at_least():
    """An approaching person faster than ISO's speed uses the measured
    speed; slower, or walking away, ISO's (2.0 m/s within 0.5 m)."""
    people = PeopleSeparationParameters()
    timing = protective_timing(people, H, (1.0, 1.0, 1.0), LAG)
    nearest = [[2.4, 0.0], [2.4, 0.0], [2.4, 0.0], [0.7, 0.0]]
    velocities = [[-3.0, 0.0], [-1.0, 0.0], [1.5, 0.0], [0.0, 0.0]]
    rows, allowed = people_rows(nearest, velocities, HALF, people, timing, 6)
    np.testing.assert_array_equal(rows[0], [1.0, 0.0, 0.0])
    d = np.array([2.0, 2.0, 2.0, 0.3])
    speeds = np.array([3.0, HUMAN_SPEED, HUMAN_SPEED, HUMAN_SPEED_NEAR])
    np.testing.assert_allclose(allowed[:4], protective_speeds(
        d, speeds, timing, people.margin), rtol=1e-14)
    assert allowed[0] < allowed[1] == allowed[2]
    assert np.all(rows[4:] == 0.0)


def test_human_speeds_cannot_be_set_below_iso():
    for name, value in (("human_speed", 1.2), ("human_speed_near", 1.9),
                        ("near_distance", 0.3)):
        with pytest.raises(ValueError, match=f"{name} = {value}.*ISO 13855"):
            PeopleSeparationParameters(**{name: value})
    with pytest.raises(ValueError, match="people.human_speed = 1.0"):
        from drake_wbc.math.validation import validate

        params = SafetyParameters(**BASE_LIMITS)
        params.people.human_speed = 1.0
        validate(params)
    for name in ("intrusion", "processing_time"):
        with pytest.raises(ValueError, match=name):
            PeopleSeparationParameters(**{name: -0.1})
    check_within_robot(SafetyParameters(), BASE_VELOCITY_LIMITS,
                       BASE_ACCELERATION_LIMITS, LAG)


# --- the tracker ------------------------------------------------------------


def scan_of(pose, circles, boxes=None):
    """The points (T_b) both scanners see from the base at `pose`."""
    return np.concatenate([
        scan_points(scan(pose, mount, LIDAR, circles, boxes, 0),
                    LIDAR.beam_angles, mount) for mount in MOUNTS])


def odometry(pose, world_twist):
    """[x, y, yaw, vx, vy, wz] with the twist in T_b, of a base at `pose`
    moving at `world_twist` (world frame)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    vx, vy, wz = world_twist
    return np.array([*pose, c * vx + s * vy, -s * vx + c * vy, wz])


def test_the_tracker_measures_a_walker_and_not_a_pillar():
    """A person (r = 0.25 m) walking at a constant velocity past a pillar
    while the base drives and turns: the tracked velocity is the finite
    difference of the true positions within 0.15 m/s (10%; a cluster's
    centroid is that of the arc a scanner sees, which turns with the
    view) from the third scan on, in the world and in T_b, and the
    pillar's track stays still (static)."""
    params = PeopleSeparationParameters()
    state = tracking.initial_tracker()
    velocity = np.array([-1.2, 0.9])
    start = np.array([3.5, -1.5])
    pillar = [1.5, 1.2, 0.15]
    base_velocity = np.array([0.4, 0.0, 0.1])
    walker = None
    for k in range(12):
        t = k * SCAN
        pose = base_velocity * t
        person = start + velocity * t
        points = scan_of(pose, [[*person, 0.25], pillar])
        state, found, inside = tracking.people_scan(
            state, points, odometry(pose, base_velocity), t, HALF, params)
        assert not inside
        tracks = tracking.tracks_of(state)
        live = tracks[tracks[:, 4] > 0]
        near_person = np.hypot(*(live[:, :2] - person).T) < 0.4
        near_pillar = np.hypot(*(live[:, :2] - pillar[:2]).T) < 0.3
        if k >= 2:
            truth = (person - (start + velocity * (t - SCAN))) / SCAN
            walker = live[near_person]
            assert len(walker) >= 1
            for track in walker:
                np.testing.assert_allclose(track[2:4], truth, atol=0.15)
            for track in live[near_pillar]:
                assert np.hypot(*track[2:4]) < 0.1
        if k >= 5:
            # Moving once it has walked min_travel (0.5 m: 5 scans at
            # 1.5 m/s); its velocity in T_b.
            assert found
            c, s = np.cos(pose[2]), np.sin(pose[2])
            in_base = np.array([c * velocity[0] + s * velocity[1],
                                -s * velocity[0] + c * velocity[1]])
            for _, nearest, v in found:
                np.testing.assert_allclose(v, in_base, atol=0.15)
                assert footprint_gap(nearest[None], HALF)[0] > 0.0
            assert not np.any(near_pillar & (
                tracks[tracks[:, 4] > 0][:, 7] > -1.0))
    assert walker is not None


def test_walls_and_crates_are_not_people():
    """A drive at full speed along a wall and past a crate seen from
    changing sides, and a turn on the spot: no track is ever moving."""
    params = PeopleSeparationParameters()
    state = tracking.initial_tracker()
    boxes = [[3.0, 1.2, 4.0, 0.05, 0.0], [2.0, -0.9, 0.2, 0.2, 0.4]]
    for k in range(60):
        t = k * SCAN
        pose = np.array([1.0 * t, 0.0, 0.15 * math.sin(t)])
        twist = np.array([1.0, 0.0, 0.15 * math.cos(t)])
        state, found, _ = tracking.people_scan(
            state, scan_of(pose, None, boxes), odometry(pose, twist), t,
            HALF, params)
        assert found == []
    # Turning on the spot at full rate beside a wall and a table: the
    # pieces at the edges of the scanners' fields turn with the base.
    state = tracking.initial_tracker()
    boxes = [[0.0, 1.5, 3.0, 0.05, 0.0], [1.2, -0.2, 0.3, 0.5, 0.0]]
    for k in range(120):
        t = k * SCAN
        pose = np.array([0.0, 0.0, 1.0 * t])
        state, found, _ = tracking.people_scan(
            state, scan_of(pose, None, boxes),
            odometry(pose, [0.0, 0.0, 1.0]), t, HALF, params)
        assert found == []


def test_a_long_moving_hold_makes_no_pillar_a_person():
    """A track that never moved has its last moving time at NEVER
    (-1e9 s): with moving_hold of 2e9 s (a person who stopped counts as
    moving for that long) every pillar counted as a moving person from
    its first scan, the base kept from it at a person's separation. A
    track is a person only once it has moved."""
    params = PeopleSeparationParameters(moving_hold=2e9)
    state = tracking.initial_tracker()
    for k in range(6):
        state, found, _ = tracking.people_scan(
            state, scan_of(np.zeros(3), [[1.5, 1.2, 0.15]]),
            odometry(np.zeros(3), np.zeros(3)), k * SCAN, HALF, params)
        assert found == []


def test_a_long_hold_time_is_no_protective_stop_at_the_start(caplog):
    """The protective stop held while t - (the last time a point was
    inside) < hold_time, that last time NEVER (-1e9 s) before any: with a
    hold time of 2e9 s (legal: the base stays stopped that long after a
    point has gone) the base was in a protective stop from the start,
    with no point anywhere near, its reason that a point was inside the
    footprint. A point inside still stops it, and it then holds."""
    limiter = BaseCommandLimiter(
        SafetyParameters(**BASE_LIMITS, hold_time=2e9), H, HALF)
    context = limiter.CreateDefaultContext()
    limiter.GetInputPort("velocity").FixValue(context, [0.5, 0.0, 0.0])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    far = np.array([[5.0, 5.0], [5.0, 5.1]])
    inside = np.array([[0.1, 0.0], [5.0, 5.0]])
    stops = []
    for k in range(40):
        context.SetTime(k * H)
        limiter.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(inside if k == 20 else far))
        context.SetDiscreteState(limiter.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
        stops.append(limiter.GetOutputPort("protective_stop").Eval(
            context)[0])
        if k == 10:
            assert limiter.reason(context) == ""
            assert limiter.GetOutputPort("velocity_command").Eval(
                context)[0] > 0.0
    assert stops[:20] == [0.0] * 20
    assert stops[20:] == [1.0] * 20


def test_the_tracker_starts_again_when_time_is_set_back():
    """Eight pillars fill the tracker's slots; the time is then set 9 s
    back and a person walks towards the base at 1.2 m/s: the tracks,
    seen in the new time's future, neither followed a cluster nor ended,
    and the person was never tracked (nor kept at the protective
    separation) for those 9 s. It is taken for a person as soon as in a
    tracker started afresh."""
    params = PeopleSeparationParameters()
    pillars = [[2.0 * math.cos(a), 2.0 * math.sin(a), 0.1]
               for a in np.linspace(0.4, 2 * math.pi - 0.4, 8)]
    pose = np.zeros(3)

    def scans(state, start_time, person):
        found = []
        for k in range(25):
            circles = list(pillars)
            if person:
                circles.append([4.5 - 1.2 * k * SCAN, 0.0, 0.25])
            state, people, _ = tracking.people_scan(
                state, scan_of(pose, circles), odometry(pose, [0, 0, 0]),
                start_time + k * SCAN, HALF, params)
            found.append(len(people))
        return state, found

    state, found = scans(tracking.initial_tracker(), 10.0, False)
    assert found == [0] * 25
    assert (tracking.tracks_of(state)[:, 4] > 0).sum() == tracking.MAX_TRACKS
    _, after = scans(state, 1.0, True)
    _, fresh = scans(tracking.initial_tracker(), 1.0, True)
    assert fresh[-1] == 1
    assert after == fresh


# --- the limiter on an ideal robot ------------------------------------------


def ideal_run(person, duration, desired=(1.0, 0.0, 0.0), v0=0.0,
              radius=0.25):
    """The limiter driving an ideal base (its velocity is the command,
    from the origin facing +x) with the desired command `desired`, a
    person at person(t) (world), scanned at 15 Hz by both scanners.

    Returns:
        times, commands (N, 3), the footprint's gap to the person's circle
        (N,), the protective stop (N,), and the limiter.
    """
    limiter = BaseCommandLimiter(SafetyParameters(**BASE_LIMITS), H, HALF)
    context = limiter.CreateDefaultContext()
    limiter.set_previous(context, [v0, 0.0, 0.0])
    limiter.GetInputPort("velocity").FixValue(context, np.asarray(desired))
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    pose, velocity = np.zeros(3), np.array([v0, 0.0, 0.0])
    points = np.zeros((0, 2))
    times, commands, gaps, stops = [], [], [], []
    for k in range(int(round(duration / H))):
        t = k * H
        context.SetTime(t)
        centre = np.asarray(person(t), dtype=float)
        if k % SCAN_TICKS == 0:
            points = scan_of(pose, [[*centre, radius]])
        state_port = limiter.GetInputPort("base_state")
        state_port.FixValue(context, np.concatenate([pose, velocity]))
        limiter.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(points))
        command = limiter.GetOutputPort("velocity_command").Eval(
            context).copy()
        context.SetDiscreteState(limiter.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
        # The ideal base: the command, integrated over the tick.
        velocity = command
        c, s = np.cos(pose[2]), np.sin(pose[2])
        pose = pose + H * np.array([c * command[0] - s * command[1],
                                    s * command[0] + c * command[1],
                                    command[2]])
        c, s = np.cos(pose[2]), np.sin(pose[2])
        relative = centre - pose[:2]
        in_base = np.array([c * relative[0] + s * relative[1],
                            -s * relative[0] + c * relative[1]])
        times.append(t)
        commands.append(command)
        gaps.append(footprint_gap(in_base[None], HALF)[0] - radius)
        stops.append(limiter.GetOutputPort("protective_stop").Eval(
            context)[0])
    return (np.array(times), np.array(commands), np.array(gaps),
            np.array(stops), limiter)


def walker(start, end, t0, t1):
    start, end = np.asarray(start, float), np.asarray(end, float)

    def at(t):
        f = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
        return start + f * (end - start)

    return at


def test_a_person_walking_head_on_meets_a_base_at_rest():
    """The base drives forward at full speed (1 m/s desired) towards a
    person walking head-on at 1.6 m/s from 8 m: the base is at rest
    before the person reaches the footprint, and stays so."""
    person = walker([9.0, 0.0], [-3.0, 0.0], 0.0, 12.0 / 1.6)
    t, command, gap, stop, _ = ideal_run(person, 6.0)
    contact = np.flatnonzero(gap <= 0.0)
    assert len(contact), "the person reaches the base"
    first = contact[0]
    at_rest = np.flatnonzero(np.all(command == 0.0, axis=1))
    assert len(at_rest) and at_rest[0] < first
    # Once at rest before contact, it never approaches again.
    assert np.all(command[at_rest[0]:first + 1, 0] <= 1e-12)
    # The separation when the base came to rest: at least the base's
    # stop from rest against a person at 1.6 m/s, less what it can close
    # in one scan (the protective separation is kept at the scans).
    assert gap[at_rest[0]] > 0.5
    # Inside the footprint: a protective stop.
    assert stop[contact[-1]] == 1.0 or gap[-1] > 0.0
    print(f"head-on: at rest {t[first] - t[at_rest[0]]:.2f} s before "
          f"contact, {gap[at_rest[0]]:.2f} m from the person; top speed "
          f"{command[:, 0].max():.2f} m/s")


def test_a_person_stepping_in_ahead_of_the_base_at_full_speed():
    """A person walks in from the side at 1.6 m/s and stops with 0.25 m
    between the base's front and its body if the base had kept its 1 m/s.
    Tracked as moving from the side, the person slows the base before it
    steps in; the base is at rest before contact."""
    # Base front at 0.4 + t; at t = 1 s: 1.4, the person's edge at 1.65.
    person = walker([1.9, 1.6], [1.9, 0.0], 0.0, 1.0)
    t, command, gap, stop, _ = ideal_run(person, 3.0, v0=1.0)
    speed = command[:, 0]
    assert gap.min() > 0.0, "no contact"
    assert speed[-1] == 0.0
    print(f"step-in: closest {gap.min():.3f} m, at rest at "
          f"{t[np.flatnonzero(speed == 0.0)[0]]:.2f} s")


def test_a_person_stepping_in_unseen_is_met_at_the_slowest_speed_allowed():
    """A person appears 0.25 m ahead of the base at full speed (stepping
    out from behind cover: the first scan that sees them): no stop can
    avoid the contact (the base needs 0.5 m to stop from 1 m/s at
    1 m/s^2). The base brakes at its acceleration limit from the first
    scan that sees the person, and meets them at the speed of that
    braking after one scan period and a tick:
    v^2 = v0^2 - 2 a (g0 - v0 T), and a protective stop follows."""
    appear = 0.5
    radius = 0.25
    front = 0.4 + 1.0 * appear
    hidden = np.array([50.0, 50.0])

    def person(t):
        return hidden if t < appear else np.array([front + 0.25 + radius,
                                                   0.0])

    t, command, gap, stop, _ = ideal_run(person, 2.0, v0=1.0)
    seen = np.flatnonzero(t >= appear)[0]
    contact = np.flatnonzero((gap <= 0.0) & (t >= appear))[0]
    # The first scan at or after `appear`, and a tick for the state.
    first_scan = math.ceil(appear / SCAN - 1e-9) * SCAN  # 0.56 s
    reaction = first_scan - appear + H
    g0 = 0.25 - reaction * 1.0
    bound = math.sqrt(max(1.0 - 2.0 * 1.0 * g0, 0.0))
    speed_at_contact = command[contact - 1, 0]
    assert speed_at_contact <= bound + 0.011  # one tick of braking
    # Braking at the limit from the first scan on (no slower is allowed).
    braking = np.diff(command[seen:contact, 0]) / H
    assert braking.min() >= -1.0 - 1e-9
    assert stop[contact + 1:].max() == 1.0
    assert command[-1, 0] == 0.0
    print(f"step-in unseen: contact at {speed_at_contact:.3f} m/s "
          f"(limits allow {bound:.3f})")


def test_a_person_crossing_behind_or_walking_away_does_not_halt_the_base():
    """A person crossing 0.6 m behind the base at 1 m/s, and one walking
    away ahead of it at 1.2 m/s from 1.5 m: the base keeps moving (the
    crossing does not limit it at all; the one ahead is followed at a
    distance)."""
    crossing = walker([-1.6, 2.5], [-1.6, -2.5], 0.0, 5.0)
    t, command, gap, _, _ = ideal_run(crossing, 3.0, desired=(0.3, 0, 0),
                                      v0=0.3)
    np.testing.assert_array_equal(command[:, 0], 0.3)
    ahead = walker([2.4, 0.0], [9.4, 0.0], 0.0, 7.0 / 1.2)
    t, command, gap, _, _ = ideal_run(ahead, 5.0, desired=(0.8, 0, 0),
                                      v0=0.0)
    assert command[t > 1.0, 0].min() > 0.1
    assert gap.min() > 0.9


def test_a_point_inside_the_footprint_is_a_protective_stop(caplog):
    """A static point inside the footprint (nothing can be in it but a
    person or what the base has struck) stops the base within its
    acceleration limit, reported on `protective_stop` and by `reason`,
    and the base resumes hold_time after it has gone."""
    limiter = BaseCommandLimiter(SafetyParameters(**BASE_LIMITS), H, HALF)
    context = limiter.CreateDefaultContext()
    limiter.set_previous(context, [0.5, 0.0, 0.0])
    limiter.GetInputPort("velocity").FixValue(context, [0.5, 0.0, 0.0])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    far = np.array([[5.0, 5.0], [5.0, 5.1]])
    inside = np.array([[0.1, -0.5], [0.1, 0.0], [5.0, 5.0]])
    speeds, stops = [], []
    for k in range(150):
        context.SetTime(k * H)
        points = inside if 10 <= k < 20 else far
        limiter.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(points))
        speeds.append(limiter.GetOutputPort("velocity_command").Eval(
            context)[0])
        context.SetDiscreteState(limiter.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
        stops.append(limiter.GetOutputPort("protective_stop").Eval(
            context)[0])
        if k == 15:
            assert "protective stop" in limiter.reason(context)
    speeds, stops = np.array(speeds), np.array(stops)
    assert stops[10] == 1.0 and stops[9] == 0.0
    # Braking at the acceleration limit (1 m/s^2), to rest.
    np.testing.assert_allclose(np.diff(speeds[10:61]), -H, atol=1e-12)
    assert speeds[61:70].max() == 0.0
    # Cleared hold_time (0.5 s) after the last scan with the point.
    assert stops[68] == 1.0 and stops[69] == 0.0
    assert speeds[-1] > 0.0
    assert limiter.reason(context) == ""
    assert "protective stop at t = 0.100 s" in caplog.text
    assert "protective stop cleared at t = 0.690 s" in caplog.text


def test_the_scan_period_is_at_least_the_lidars():
    from drake_wbc.experiments.scenario import load_scenario

    text = """
controller:
  safety:
    people:
      scan_period: 0.05
"""
    with pytest.raises(ValueError, match=(
            r"controller.safety.people.scan_period = 0.05 s is not allowed "
            r"with station.lidar.rate = 15.0 Hz")):
        load_scenario(text=text)
    load_scenario(text=text.replace("0.05", "0.1"))


def test_a_point_inside_is_seen_in_any_beam_of_a_scan():
    """A base at rest in a room scans as many returns each time, the
    first, middle and last beams on the walls: a person stepping into
    another beam, inside the footprint, changes that scan alone, and is a
    protective stop all the same."""
    limiter = BaseCommandLimiter(SafetyParameters(**BASE_LIMITS), H, HALF)
    context = limiter.CreateDefaultContext()
    limiter.GetInputPort("velocity").FixValue(context, [0.0, 0.0, 0.0])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    walls = np.column_stack([np.full(9, 3.0), np.linspace(-2.0, 2.0, 9)])
    stepped_in = walls.copy()
    stepped_in[2] = [0.1, 0.0]
    stops = []
    for k in range(30):
        context.SetTime(k * H)
        points = stepped_in if k >= 10 else walls
        limiter.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(points.copy()))
        context.SetDiscreteState(limiter.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
        stops.append(limiter.GetOutputPort("protective_stop").Eval(
            context)[0])
    assert stops[9] == 0.0
    assert stops[10:] == [1.0] * 20


@pytest.mark.parametrize("hold_time", [1e-10, 1e-9])
def test_a_point_inside_stops_the_base_whatever_the_hold_time(hold_time):
    """SafetyParameters take any hold_time > 0: one of a nanosecond or
    less still stops the base while a point is inside the footprint
    (the tick itself counts, not only the time after it)."""
    limiter = BaseCommandLimiter(
        SafetyParameters(**BASE_LIMITS, hold_time=hold_time), H, HALF)
    context = limiter.CreateDefaultContext()
    limiter.set_previous(context, [0.5, 0.0, 0.0])
    limiter.GetInputPort("velocity").FixValue(context, [0.5, 0.0, 0.0])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    limiter.GetInputPort("obstacle_points").FixValue(
        context, AbstractValue.Make(np.array([[0.1, 0.0], [5.0, 5.0]])))
    for k in range(5):
        context.SetTime(k * H)
        context.SetDiscreteState(limiter.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
        assert limiter.GetOutputPort("protective_stop").Eval(
            context)[0] == 1.0
        assert limiter.GetOutputPort("velocity_command").Eval(
            context)[0] == pytest.approx(0.5 - (k + 1) * H)


def test_time_set_back_neither_makes_up_nor_forgets_a_protective_stop():
    """A context whose time is set back (9 s) after a point inside the
    footprint has gone: a stop that had cleared stays clear (it held the
    base for 9.5 s, naming a point inside that was not there), and one
    that still holds restarts its hold_time from the new time."""
    params = SafetyParameters(**BASE_LIMITS)
    far, inside = np.array([[5.0, 5.0]]), np.array([[0.1, 0.0]])
    for cleared, resumes in ((True, 0), (False, 50)):
        limiter = BaseCommandLimiter(params, H, HALF)
        context = limiter.CreateDefaultContext()
        limiter.GetInputPort("velocity").FixValue(context, [0.3, 0.0, 0.0])
        limiter.GetInputPort("stopped").FixValue(context, [0.0])

        def tick(time, points, limiter=limiter, context=context):
            context.SetTime(time)
            limiter.GetInputPort("obstacle_points").FixValue(
                context, AbstractValue.Make(points))
            context.SetDiscreteState(
                limiter.EvalUniquePeriodicDiscreteUpdate(context)
                .get_vector().CopyToVector())
            return limiter.GetOutputPort("protective_stop").Eval(context)[0]

        stops = [tick(10.0 + k * H, inside if k < 5 else far)
                 for k in range(80 if cleared else 20)]
        assert stops[-1] == (0.0 if cleared else 1.0)
        stops = [tick(1.0 + k * H, far) for k in range(100)]
        assert stops == [1.0] * resumes + [0.0] * (100 - resumes)
        assert limiter.reason(context) == ""


@pytest.mark.parametrize("people, message", [
    (dict(tracked_range=3.0),
     r"controller.safety.people.tracked_range = 3.0 is not allowed: must "
     r"be at least 4.86 m"),
    (dict(min_travel=2.0),
     r"controller.safety.people.tracked_range = 6.0 is not allowed: must "
     r"be at least 6.36 m"),
    (dict(moving_scans=30),
     r"controller.safety.people.tracked_range = 6.0 is not allowed: must "
     r"be at least 7.56 m"),
    (dict(gate=0.1), r"controller.safety.people.gate = 0.1 is not "
     r"allowed: must be at least 0.133 m"),
])
def test_a_tracking_that_cannot_protect_a_walker_is_refused(people,
                                                            message):
    """Each value legal alone, the tracking could not protect a person
    walking at the base: one seen from 3 m, or counted as moving only
    after 2 m or 30 scans, is first a person where the base at its full
    1 m/s cannot stop short any more (the protective separation 4.36 m,
    eq. (protective)); a gate smaller than a person's step between two
    scans loses every walker. They are refused when the scenario is
    loaded, naming the field and the least that protects; the defaults
    (6 m, 0.5 m) pass on both shipped robots."""
    from drake_wbc.experiments.scenario import load_scenario

    lines = "\n".join(f"      {k}: {v}" for k, v in people.items())
    with pytest.raises(ValueError, match=message):
        load_scenario(text=f"controller:\n  safety:\n    people:\n{lines}\n")
    load_scenario(text="controller:\n  safety:\n    people:\n"
                  "      tracked_range: 4.9\n")
    build_controller(robot=load_robot_description(
        models_dir() / "lbr_omni.robot.yaml"))
