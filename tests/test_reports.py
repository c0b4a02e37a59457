"""The reports' JSON (drake_wbc.experiments.reports.json_text): strict
JSON, which a strict reader takes, with the numbers JSON has none for
written as strings that float() reads back."""

import json
import math

import numpy as np

from drake_wbc.experiments.reports import from_json_text, json_text


def _refuse(constant):
    raise ValueError(f"{constant} is not JSON")


def test_json_text_is_strict_and_reads_back():
    value = {"a": np.float64(np.nan), "b": [math.inf, -np.inf, 1.5,
                                            np.int64(3)],
             "c": {"d": np.array([np.nan, 2.0])}, 4: np.bool_(True),
             "f": None}
    data = json.loads(json_text(value), parse_constant=_refuse)
    assert data == {"a": "nan", "b": ["inf", "-inf", 1.5, 3],
                    "c": {"d": ["nan", 2.0]}, "4": True, "f": None}
    assert math.isnan(float(data["a"]))
    assert [float(v) for v in data["b"][:2]] == [math.inf, -math.inf]
    assert json_text([1.0, 2], None) == "[1.0, 2]"


def test_from_json_text_reads_the_non_finite_numbers_back():
    value = {"a": [math.nan, math.inf, -math.inf, 1.5, "text"],
             "b": {"c": 2}}
    back = from_json_text(json_text(value))
    assert math.isnan(back["a"][0])
    assert back["a"][1:] == [math.inf, -math.inf, 1.5, "text"]
    assert back["b"] == {"c": 2}


def test_the_distances_to_obstacles_and_people_and_a_paths_length():
    """The experiments' shared measures (drake_wbc.experiments.common,
    each once: wiping, pHRI, fixed point, line tracking and the stress
    cases had their own copies), against closed forms: a base of half
    sizes (a, b) at x = 0 then 1 m (yaw 0), a pillar of radius 0.2 m at
    (3, 0), a box whose near face is at x = 4 m, a person of radius 0.25
    m at (0, 4) then (1, 5)."""
    from drake_wbc.controller.run_log import RunLog
    from drake_wbc.experiments.common import (
        path_length,
        person_distances,
        static_distances,
    )
    from drake_wbc.experiments.scenario import Scenario, footprint_of
    from drake_wbc.station.scene import (
        BoxObstacle,
        CylinderObstacle,
        Scene,
        WalkingPerson,
    )

    scenario = Scenario(scene=Scene(
        cylinders=[CylinderObstacle(name="pillar", position=[3.0, 0.0],
                                    radius=0.2, height=2.0)],
        boxes=[BoxObstacle(name="crate", center=[4.5, 0.0, 0.4],
                           size=[1.0, 1.0, 0.8])],
        people=[WalkingPerson(name="walker", radius=0.25, times=[0.0, 1.0],
                              waypoints=[[0.0, 4.0], [1.0, 5.0]])]))
    log = RunLog(np.array([0.0, 1.0]), {
        "truth.base_pose": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
        "truth.people_positions": np.array([[0.0, 4.0], [1.0, 5.0]])},
        {"truth.base_pose": ("x", "y", "yaw"),
         "truth.people_positions": ("x", "y")})
    a, b = footprint_of(scenario)
    np.testing.assert_allclose(static_distances(scenario, log),
                               [2.8 - a, 1.8 - a], atol=1e-12)
    np.testing.assert_allclose(person_distances(scenario, log),
                               [3.75 - b, 4.75 - b], atol=1e-12)
    empty = Scenario()
    assert np.all(static_distances(empty, log) == math.inf)
    assert np.all(person_distances(empty, log) == math.inf)
    assert path_length(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.0]])) == 9.0
    assert path_length(np.zeros((1, 3))) == 0.0
