"""The base's state layout (drake_wbc.math.base_state) and its readers."""

import numpy as np

from drake_wbc.controller.diagram import build_controller
from drake_wbc.math.base_state import (
    BASE_POSE,
    BASE_STATE_SIZE,
    BASE_TWIST,
    BASE_YAW,
)


def test_the_pose_and_the_twist_make_up_the_state():
    entries = np.arange(BASE_STATE_SIZE)
    np.testing.assert_array_equal(
        np.concatenate([entries[BASE_POSE], entries[BASE_TWIST]]), entries)
    assert entries[BASE_POSE][-1] == BASE_YAW


def test_the_controller_reads_the_yaw_of_the_base_state():
    controller = build_controller()
    gain = controller.stages["base_yaw"]
    state = np.array([1.0, -2.0, 0.3, 0.4, -0.5, 0.6])
    context = gain.CreateDefaultContext()
    gain.get_input_port().FixValue(context, state)
    assert gain.get_output_port().Eval(context)[0] == state[BASE_YAW]
