"""The CDMP-WBC stages as Drake systems, thin over the math layer.

Every stage is a scalar-convertible `TemplateSystem` (double and
AutoDiffXd), so that Drake's `Linearize` runs on the very systems the
controller uses; where a stage is linear or a switch it is a small
Diagram of Drake's C++ systems instead (BaseVelocityFilter, StopSwitch:
stages.support.define_composite_stage), with the same ports, which
converts as Drake's own systems do.

May import the math layer and the robot (its kinematics); never the
controller, the station or the hardware.

Parameters are checked where they enter (their dataclasses, at load and
build time) and read when a stage is constructed: a stage takes what it
needs from them then, shares them with its scalar-converted copies
(stages.support.define_stage), and never checks them again, so changing
a parameters object afterwards has no effect on the stages built from it.
The values that the controller holds once for several stages (the control
period, the C_m band, the default pHRI switch S_hri) are not in the
stages' dataclasses but constructor arguments (`time_step`, `band`,
`phri_switch`, with the paper's defaults), which build_controller hands
down from ControllerParameters.
"""

from drake_wbc.stages.admittance_filter import (
    AdmittanceFilter,
    AdmittanceFilter_,
)
from drake_wbc.stages.arm_control import (
    ArmCartesianVelocityController,
    ArmCartesianVelocityController_,
)
from drake_wbc.stages.base_command import (
    BaseCommandLimiter,
    BaseCommandLimiter_,
)
from drake_wbc.stages.base_filter import (
    BaseVelocityFilter,
    BaseVelocityFilter_,
)
from drake_wbc.stages.capability_stage import (
    ArmCapability,
    ArmCapability_,
    WorkspaceAdapter,
    WorkspaceAdapter_,
)
from drake_wbc.stages.cdmp_stages import (
    ArmCdmp,
    ArmCdmp_,
    BaseCdmp,
    BaseCdmp_,
)
from drake_wbc.stages.coordination import (
    MotionDistributor,
    MotionDistributor_,
    RobustCompensator,
    RobustCompensator_,
)
from drake_wbc.stages.safety import (
    GuardedInput,
    InputGuard,
    InputGuard_,
    StopGate,
    StopGate_,
)
from drake_wbc.stages.stop_switch import StopSwitch, StopSwitch_
from drake_wbc.stages.whole_body_cdmp import (
    WholeBodyCdmp,
    WholeBodyCdmp_,
)
from drake_wbc.stages.wrench import (
    ExternalWrenchEstimator,
    ExternalWrenchEstimator_,
)

__all__ = [
    "AdmittanceFilter",
    "AdmittanceFilter_",
    "ArmCdmp",
    "ArmCdmp_",
    "BaseCdmp",
    "BaseCdmp_",
    "WholeBodyCdmp",
    "WholeBodyCdmp_",
    "BaseCommandLimiter",
    "BaseCommandLimiter_",
    "GuardedInput",
    "InputGuard",
    "InputGuard_",
    "StopGate",
    "StopGate_",
    "StopSwitch",
    "StopSwitch_",
    "ArmCartesianVelocityController",
    "ArmCartesianVelocityController_",
    "BaseVelocityFilter",
    "BaseVelocityFilter_",
    "ArmCapability",
    "ArmCapability_",
    "MotionDistributor",
    "MotionDistributor_",
    "RobustCompensator",
    "RobustCompensator_",
    "WorkspaceAdapter",
    "WorkspaceAdapter_",
    "ExternalWrenchEstimator",
    "ExternalWrenchEstimator_",
]
