"""The task inputs' one table (drake_wbc.math.task_inputs): every check of
a task input reads its range there, and says what is allowed."""

import math

import numpy as np
import pytest

from drake_wbc.controller.diagram import build_controller
from drake_wbc.math.task_inputs import TASK_INPUTS, TaskInput
from drake_wbc.stages import MotionDistributor, RobustCompensator


@pytest.mark.parametrize("name, value, message", [
    ("phri_switch", 0.5, "phri_switch = 0.5 is not allowed: must be 0 or 1"),
    ("null_space_gain", -0.1,
     "null_space_gain = -0.1 is not allowed: must be 0 or greater"),
    ("compensation_switch", 1.5,
     "compensation_switch = 1.5 is not allowed: must lie in [0, 1]"),
    ("compensation_switch", math.nan,
     "compensation_switch = nan is not allowed: must lie in [0, 1]"),
])
def test_a_bad_entry_is_named_with_what_is_allowed(name, value, message):
    with pytest.raises(ValueError) as error:
        TASK_INPUTS[name].check(name, value)
    assert str(error.value) == message


@pytest.mark.parametrize("name, value", [
    ("phri_switch", 0.0), ("phri_switch", 1), ("null_space_gain", 0.0),
    ("null_space_gain", 1e9), ("compensation_switch", 0.0),
    ("compensation_switch", 1.0), ("reference_velocity", -1e3)])
def test_an_allowed_entry_is_returned_as_it_is(name, value):
    assert TASK_INPUTS[name].check(name, value) is value


def test_a_parameter_must_be_one_number():
    with pytest.raises(ValueError, match="single number"):
        TASK_INPUTS["phri_switch"].check_number("phri_switch", "on")
    assert TASK_INPUTS["phri_switch"].check_number("phri_switch", 1) == 1.0


def test_the_input_guard_reads_the_table():
    guard = build_controller().stages["guard"]
    specs = {spec.name: spec for spec in guard.inputs}
    for name, entry in TASK_INPUTS.items():
        spec = specs[name]
        assert TaskInput(spec.size, spec.lower, spec.upper,
                         spec.switch) == entry, name


def test_a_nan_task_input_of_a_stage_used_alone_is_an_error():
    """k_n and s_c of a stage used alone (in the controller the input
    guard stops at a NaN) raise, as a value out of range does."""
    distributor, compensator = MotionDistributor(), RobustCompensator()
    for stage, port in ((distributor, "null_space_gain"),
                        (compensator, "compensation_switch")):
        context = stage.CreateDefaultContext()
        for i in range(stage.num_input_ports()):
            input_port = stage.get_input_port(i)
            input_port.FixValue(context, np.full(input_port.size(), 0.5))
        stage.GetInputPort(port).FixValue(context, [math.nan])
        with pytest.raises(ValueError, match=f"{port} = nan"):
            stage.get_output_port(0).Eval(context)
