"""Speed and separation from people in the closed loop: the controller
drives the simulated station (plant, base drive with its lag, both
LIDARs at 15 Hz) with the base at full speed in the locomotion mode, and
a WalkingPerson walks head-on at 1.6 m/s, or steps in ahead of the base.
The base is at rest (its measured velocity, truth.base_loop_velocity)
before the person reaches the footprint."""

import numpy as np

from drake_wbc.experiments.common import obstacle_distances
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import footprint_of, load_scenario

SCENARIO = """
description: the base at full speed towards a person
duration: {duration}
station:
  time_step: 0.005
controller:
  workspace:
    mode: locomotion
scene:
  people: {people}
task:
  reference_velocity:
    times: [0.0, 1.0, 30.0]
    values: [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
             [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
             [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]
    interpolation: linear
"""

AT_REST = 0.01
"""m/s: the base's loop velocity counted as at rest."""


def run(people, duration):
    scenario = load_scenario(text=SCENARIO.format(duration=duration,
                                                  people=people))
    log = simulate(build_closed_loop(scenario))
    gap = obstacle_distances(scenario.scene, log["truth.base_pose"],
                             footprint_of(scenario),
                             log["truth.people_positions"])
    speed = np.hypot(*log["truth.base_loop_velocity"][:, :2].T)
    return log, gap, speed


def test_a_person_walking_head_on_meets_the_base_at_rest():
    """From 10 m ahead at 1.6 m/s, while the base accelerates to 1 m/s:
    at rest before contact (the person then walks into a standing base,
    which the protective stop holds)."""
    people = ("[{name: walker, times: [0.0, 10.0], "
              "waypoints: [[10.0, 0.0], [-6.0, 0.0]]}]")
    log, gap, speed = run(people, 6.0)
    assert speed.max() > 0.7  # it did drive fast
    contact = np.flatnonzero(gap <= 1e-3)
    assert len(contact)
    before = slice(None, contact[0] + 1)
    rest = np.flatnonzero(speed[before] < AT_REST)
    rest = rest[rest > np.argmax(speed)]
    assert len(rest), "at rest before contact"
    assert np.all(speed[rest[0]:contact[0] + 1] < AT_REST)
    print(f"closed loop head-on: top speed {speed.max():.2f} m/s, at rest "
          f"{log.time[contact[0]] - log.time[rest[0]]:.2f} s before contact, "
          f"{gap[rest[0]]:.2f} m from the person")


def test_a_person_stepping_in_ahead_of_the_base_at_full_speed():
    """A person walks in from the side at 1.6 m/s and stops on the base's
    path, 0.25 m ahead of where the base's front would be at full speed:
    tracked while walking in, the person slows the base, which is at
    rest before contact."""
    # The base's front at full speed: x = 0.4 + (t - 1.2) at t >= 1.5 s
    # (the reference ramps over 1 s, the filter lags 0.3 s); the person
    # steps onto the path at t = 3.5 s, x = 0.4 + 2.3 + 0.25 + 0.25.
    people = ("[{name: stepper, times: [2.5, 3.5], "
              "waypoints: [[3.2, 1.6], [3.2, 0.0]]}]")
    log, gap, speed = run(people, 5.0)
    assert speed[log.time < 2.5].max() > 0.7
    assert gap.min() > 0.0, "no contact"
    assert speed[-1] < AT_REST
    print(f"closed loop step-in: top speed {speed.max():.2f} m/s, closest "
          f"{gap.min():.2f} m")
