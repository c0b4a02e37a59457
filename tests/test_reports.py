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
