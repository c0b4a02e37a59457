"""The cases of the randomised stress run (drake_wbc.stress.run).

`random_scenario(seed, index, duration)` draws one closed-loop scenario
from `numpy.random.default_rng([seed, index])` and nothing else, so a case
is the same whichever process, machine or cluster builds it:

- the controller's mode: loco-manipulation (random sigma_xy, sigma_phi of
  eq. (weight-factors), a random V_ee^ref in the world) or intuitive pHRI
  (S_hri = 1 in eqs. (cdmp-wb) and (cdmp-arm), a hand guiding the tool);
  a random null-space gain k_n of eq. (wbccm) and a random k_obs of the
  repulsive field of eq. (cdmp-base);
- static obstacles (pillars and crates) beside the base's way: at least
  `CLEARANCE` m from the disc swept by the footprint's corners along the
  straight line that the reference velocity would carry the base, so that
  a base that follows its task never needs to touch them;
- people walking past, a hand pushing (and twisting) the tool, a start
  pose of the arm near its home pose.

`run_case(seed, index, duration)` builds the scenario, runs it with
drake_wbc.experiments.runner and returns its record (`case_record`): plain
numbers,
the same for the same arguments wherever it runs (its `wall_time_s` and
`real_time_factor` aside). `violations(record)` lists the invariants a
record breaks (see drake_wbc.stress.run).
"""

import math
import time
from pathlib import Path

import numpy as np

from drake_wbc.controller.task import Schedule
from drake_wbc.experiments.common import run_metrics, static_distances
from drake_wbc.experiments.scenario import (
    Scenario,
    check_on_robot,
    controller_arm,
    controller_for,
    scenario_robot,
)
from drake_wbc.math.validation import validate
from drake_wbc.robot.description import load_robot_description, shipped_robot
from drake_wbc.station.scene import (
    BoxObstacle,
    CylinderObstacle,
    HandForce,
    WalkingPerson,
)
from drake_wbc.stress.stopping import stop_within

MODES = ("loco-manipulation", "intuitive-phri")
"""The controller's modes a case is drawn from (Table T:motion-mode)."""

CLEARANCE = 0.25
"""The least gap, m, between a static obstacle and the disc swept along
the base's nominal way by its footprint (`footprint_radius`)."""

LIDAR_BEAMS = 271
"""Beams per scan in the stress cases (1 degree over 270 degrees instead of
the TiM571's 811, to keep a case cheap; obstacles of 0.1 m or more are
still hit by several beams within a few metres)."""

TIMING_KEYS = ("wall_time_s", "real_time_factor")
"""The keys of a record that depend on the machine, not on the case."""


def _path_distance(point, end):
    """The distance from `point` (2,) to the segment from 0 to `end`."""
    length2 = float(end @ end)
    t = 0.0 if length2 == 0.0 else min(max(point @ end / length2, 0.0), 1.0)
    return float(np.linalg.norm(point - t * end))


def footprint_radius(base):
    """The distance, m, from the centre of the robot's base (its
    BaseDescription) to a corner of its footprint: the footprint stays
    inside this disc whatever its yaw (0.5 m for the shipped 0.8 x 0.6 m
    base)."""
    return math.hypot(*base.footprint_half_sizes)


def _place(rng, end, size, footprint):
    """A random position 0.9 to 2.5 m from the way's start whose distance
    to the segment [0, end] is at least `footprint` (the footprint's
    radius) + CLEARANCE + `size` (the obstacle's radius)."""
    for _ in range(100):
        radius = rng.uniform(0.9, 2.5)
        angle = rng.uniform(-math.pi, math.pi)
        point = radius * np.array([math.cos(angle), math.sin(angle)])
        if _path_distance(point, end) >= footprint + CLEARANCE + size:
            return point
    return None


def _obstacles(rng, end, footprint):
    cylinders, boxes = [], []
    for i in range(int(rng.integers(0, 3))):
        radius = rng.uniform(0.08, 0.25)
        point = _place(rng, end, radius, footprint)
        if point is not None:
            cylinders.append(CylinderObstacle(
                name=f"pillar_{i}", position=point.tolist(), radius=radius,
                height=rng.uniform(0.6, 2.0)))
    for i in range(int(rng.integers(0, 2))):
        size = rng.uniform(0.2, 0.6, 3)
        point = _place(rng, end, 0.5 * math.hypot(size[0], size[1]),
                       footprint)
        if point is not None:
            boxes.append(BoxObstacle(
                name=f"crate_{i}", center=[*point, 0.5 * size[2] + 0.1],
                size=[size[0], size[1], size[2] + 0.2],
                yaw=rng.uniform(-math.pi, math.pi)))
    return cylinders, boxes


def _people(rng, duration):
    people = []
    for i in range(int(rng.integers(0, 3))):
        start = rng.uniform(-2.5, 2.5, 2)
        goal = rng.uniform(-2.5, 2.5, 2)
        begin = rng.uniform(0.0, 0.5 * duration)
        walk = np.linalg.norm(goal - start) / rng.uniform(0.5, 1.5)
        people.append(WalkingPerson(
            name=f"person_{i}", radius=rng.uniform(0.15, 0.3),
            times=[begin, begin + max(walk, 0.1)],
            waypoints=[start.tolist(), goal.tolist()]))
    return people


def _hand(rng, duration, scale):
    """A hand that pushes for a random stretch of the run, ramped in and
    out, with forces up to `scale` N and torques up to scale / 20 N m."""
    if scale == 0.0:
        return HandForce()
    start = rng.uniform(0.0, 0.4 * duration)
    end = rng.uniform(start + 0.2 * duration, duration)
    ramp = 0.1 * (end - start)
    force = rng.uniform(-scale, scale, 3)
    torque = rng.uniform(-0.05 * scale, 0.05 * scale, 3)
    zero = [0.0, 0.0, 0.0]
    return HandForce(
        times=[start, start + ramp, end - ramp, end],
        forces=[zero, force.tolist(), force.tolist(), zero],
        torques=[zero, torque.tolist(), torque.tolist(), zero])


def _ramped(duration, value, size):
    """A Schedule that ramps from zero to `value` over the first fifth of
    the run and back to zero over the last fifth."""
    zero = [0.0] * size
    times = [0.0, 0.2 * duration, 0.8 * duration, duration]
    return Schedule(times=times, values=[zero, list(value), list(value),
                                         zero], interpolation="linear")


def random_scenario(seed, index, duration=4.0, robot=""):
    """The scenario of case `index` of the stress run of `seed`.

    Drawn from numpy.random.default_rng([seed, index]) only (module
    docstring).

    Args:
        seed: a whole number >= 0.
        index: the case's index, a whole number >= 0.
        duration: the simulated time, s.
        robot: the robot's description file ("" for the shipped robot):
            the arm starts near its home, every limit is its own.

    Returns:
        A validated drake_wbc.experiments.scenario.Scenario.
    """
    rng = np.random.default_rng([seed, index])
    scenario = Scenario(description=f"stress case {index} of seed {seed}",
                        duration=duration)
    scenario.outputs.replay = scenario.outputs.plots = False
    params = scenario.controller
    mode = MODES[int(rng.integers(0, len(MODES)))]
    params.workspace.mode = mode
    params.distributor.null_space_gain = float(rng.choice([0.0, 0.05, 0.1]))
    params.base_cdmp.repulsion.k_obs = rng.uniform(0.01, 0.04)
    velocity = np.zeros(6)
    if mode == "loco-manipulation":
        params.workspace.sigma_xy = rng.uniform(0.1, 0.9)
        params.workspace.sigma_phi = rng.uniform(0.1, 0.9)
        velocity[:3] = rng.uniform(-1.0, 1.0, 3) * [0.25, 0.25, 0.03]
        velocity[5] = rng.uniform(-0.3, 0.3)
        hand_scale = float(rng.choice([0.0, 3.0]))
    else:
        params.phri_switch = 1.0
        hand_scale = rng.uniform(2.0, 6.0)
    scenario.task.reference_velocity = _ramped(duration, velocity, 6)
    yaw = rng.uniform(-math.pi, math.pi)
    scenario.station.initial_base_pose = [0.0, 0.0, yaw]
    description = load_robot_description(robot) if robot else shipped_robot()
    home = np.asarray(description.arm.home)
    scenario.station.initial_arm_positions = (
        home + rng.uniform(-0.15, 0.15, home.size)).tolist()
    scenario.station.lidar.num_beams = LIDAR_BEAMS
    scenario.station.wrist.seed = int(rng.integers(0, 2**31))
    # The base's nominal way in the world: the end effector's reference
    # motion in the plane, at most all of it carried by the base.
    end = 0.6 * duration * velocity[:2]
    cylinders, boxes = _obstacles(rng, end,
                                  footprint_radius(description.base))
    scene = scenario.scene
    scene.cylinders, scene.boxes = cylinders, boxes
    scene.people = _people(rng, duration)
    scene.hand = _hand(rng, duration, hand_scale)
    scenario.robot = str(Path(robot).resolve()) if robot else ""
    scenario = validate(scenario)
    if robot:  # another robot's: checked against it (Scenario's own check
        check_on_robot(scenario)  # is the shipped robot's)
    return scenario


def _none_if_inf(x):
    """`x` as a float, None for +inf: nothing to measure to (no
    obstacle; no joint with a position limit, an arm of continuous
    joints alone)."""
    return None if x == math.inf else float(x)


def _limits(scenario):
    arm = controller_arm(scenario)
    return arm.lower, arm.upper, arm.velocity_limits


def case_record(seed, index, scenario, log):
    """The record of one case: what drake_wbc.stress.run checks and reports.

    Args:
        seed, index: the case.
        scenario: its Scenario.
        log: its drake_wbc.controller.run_log.RunLog.

    Returns:
        dict of plain numbers and strings (JSON-ready; distances and
        joint limit margins are None when there is nothing to measure
        them to).
    """
    lower, upper, joint_speed_limits = _limits(scenario)
    metrics = run_metrics(scenario, log)
    distance = static_distances(scenario, log)
    command = log["arm.position_command"]
    dt = np.diff(log.time)[:, None]
    joint_speed = np.abs(np.diff(command, axis=0)) / dt
    base = np.abs(log["base.velocity_command"])
    # The robot's own (its description's), not the simulated drive's
    # (station.base, which a scenario may give limits of its own).
    base_limits = np.asarray(scenario_robot(scenario).base.velocity_limits)
    filtered = np.abs(log["filtered_base_velocity"])
    filter_limits = np.asarray(
        controller_for(scenario).safety.base_velocity_limits)
    with np.errstate(invalid="ignore"):
        command_margin = np.min(np.minimum(command - lower, upper - command))
    return {
        "case": int(index),
        "seed": int(seed),
        "mode": str(scenario.controller.workspace.mode),
        "obstacles": len(scenario.scene.cylinders) + len(scenario.scene.boxes),
        "people": len(scenario.scene.people),
        "hand": bool(scenario.scene.hand.times),
        "duration_s": metrics["duration_s"],
        "all_finite": metrics["all_finite"],
        "min_capability": metrics["min_capability"],
        "min_static_obstacle_distance_m": _none_if_inf(np.min(distance)),
        "min_obstacle_distance_m": _none_if_inf(
            metrics["min_obstacle_distance_m"]),
        "min_joint_limit_margin_rad": _none_if_inf(
            metrics["min_joint_limit_margin_rad"]),
        "min_command_joint_limit_margin_rad": _none_if_inf(command_margin),
        "max_base_speed_command_m_s":
            metrics["max_base_speed_command_m_s"],
        "max_base_command_ratio": float(np.max(base / base_limits)),
        "max_filter_state_ratio": float(np.max(filtered / filter_limits)),
        "max_joint_speed_command_rad_s":
            metrics["max_arm_joint_speed_command_rad_s"],
        "max_joint_speed_command_ratio": float(
            np.max(joint_speed / joint_speed_limits)),
        "arm_fault": metrics.get("arm_fault"),  # None: not known
        "error": "",
        "wall_time_s": float("nan"),
        "real_time_factor": metrics["real_time_factor"],
    }


def failed_record(seed, index, error):
    """The record of a case whose simulation raised `error`."""
    return {"case": int(index), "seed": int(seed),
            "error": f"{type(error).__name__}: {error}",
            "wall_time_s": float("nan"), "real_time_factor": float("nan")}


def run_case(seed, index, duration=4.0, robot=""):
    """Builds and simulates case `index` of `seed` (on the robot of the
    description file `robot`, "" for the shipped one); returns its
    record.

    An exception in drawing, building, simulating or measuring the case
    (e.g. a non-finite state, a stage's IndexError) does not propagate:
    the record then holds it in "error" as "Type: message", a broken
    invariant. A stop of the run (drake_wbc.stress.stopping.Stopped, a
    BaseException, also as the cause of another exception) propagates.
    """
    from drake_wbc.experiments.runner import build_closed_loop, simulate

    started = time.perf_counter()
    try:
        scenario = random_scenario(seed, index, duration, robot)
        log = simulate(build_closed_loop(scenario))
        record = case_record(seed, index, scenario, log)
    except (Exception, SystemExit) as error:
        if stop_within(error) is not None:
            raise
        record = failed_record(seed, index, error)
    record["wall_time_s"] = time.perf_counter() - started
    return record


TOLERANCE = 1e-6
"""Relative slack of the limit checks (rounding of the logged commands)."""


def violations(record):
    """The invariants that `record` breaks, each as one line of text (an
    empty list for a sound case); see drake_wbc.stress.run for the list."""
    if record.get("error"):
        return [f"the simulation failed: {record['error']}"]
    found = []
    for key, value in record.items():
        if key in TIMING_KEYS or isinstance(value, (str, bool)) or \
                value is None:
            continue
        if not math.isfinite(value):
            found.append(f"{key} = {value!r}: not finite")
    if not record["all_finite"]:
        found.append("a logged signal is NaN or infinite")
    if record.get("arm_fault") not in (None, "none"):
        found.append(f"the arm faulted: {record['arm_fault']}")
    checks = (
        ("max_base_command_ratio", "a base velocity command exceeds the "
         "base's velocity limit", lambda x: x <= 1.0 + TOLERANCE),
        ("max_filter_state_ratio", "the base filter's output exceeds the "
         "base's velocity limit (wind-up)", lambda x: x <= 1.0 + TOLERANCE),
        ("max_joint_speed_command_ratio", "a joint position command moves "
         "faster than the joint's velocity limit",
         lambda x: x <= 1.0 + TOLERANCE),
        ("min_command_joint_limit_margin_rad", "a joint position command "
         "lies beyond a joint limit", lambda x: x >= -TOLERANCE),
        ("min_static_obstacle_distance_m", "the base touched a static "
         "obstacle", lambda x: x is None or x > 0.0),
    )
    for key, what, holds in checks:
        value = record[key]
        if value is not None and math.isfinite(value) and not holds(value):
            found.append(f"{what} ({key} = {value:.6g})")
    return found
