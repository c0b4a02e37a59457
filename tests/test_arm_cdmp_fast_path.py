"""The float paths of the arm and CDMP stages give exactly the values of
the general formulas: the capability's sliced outputs, the base CDMP's
repulsive force."""

import numpy as np
from pydrake.autodiffutils import ExtractValue
from pydrake.common.value import AbstractValue

from drake_wbc.math import cdmp, repulsion
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages.capability_stage import ArmCapability
from drake_wbc.stages.cdmp_stages import BaseCdmp

_OUTPUTS = (("end_effector_position", slice(0, 3)),
            ("capability", slice(3, 4)),
            ("capability_gradient", slice(4, 10)),
            ("alpha", slice(10, 11)))


def test_arm_capability_outputs_are_the_slices_of_evaluate():
    rng = np.random.default_rng(5)
    system = ArmCapability(arm=ArmKinematics())
    autodiff = system.ToAutoDiffXd()
    context = system.CreateDefaultContext()
    autodiff_context = autodiff.CreateDefaultContext()
    for _ in range(5):
        q_a = np.asarray(HOME_ARM_POSITIONS) + rng.uniform(-0.3, 0.3, 6)
        expected = system.evaluate(q_a)
        system.GetInputPort("arm_position").FixValue(context, q_a)
        autodiff.GetInputPort("arm_position").FixValue(
            autodiff_context, q_a.astype(object))
        for name, part in _OUTPUTS:
            value = system.GetOutputPort(name).Eval(context)
            np.testing.assert_array_equal(value, expected[part])
            value = autodiff.GetOutputPort(name).Eval(autodiff_context)
            np.testing.assert_array_equal(
                ExtractValue(value).ravel(), expected[part])


def test_base_cdmp_force_is_the_repulsive_force_with_no_yaw_part():
    rng = np.random.default_rng(7)
    params = cdmp.BaseCdmpParameters()
    system = BaseCdmp(params)
    context = system.CreateDefaultContext()
    port = system.GetInputPort("obstacle_points")
    for size in (0, 1, 5, 40, 40):
        points = rng.uniform(-1.5, 1.5, (size, 2))
        port.FixValue(context, AbstractValue.Make(points))
        f_x, f_y = repulsion.repulsive_force_float(points,
                                                   params.repulsion)
        force = system.repulsive_force(context)
        assert force.dtype == np.float64
        np.testing.assert_array_equal(force, [f_x, f_y, 0.0])
