"""The CDMP-WBC stages as Drake systems, thin over the math layer.

Every stage is a scalar-convertible `TemplateSystem` (double and
AutoDiffXd), so that Drake's `Linearize` runs on the very systems the
controller uses.

May import the math layer and the robot (its kinematics); never the
controller, the station or the hardware.

Parameters are read when a stage is constructed: it checks them and keeps
a validated copy (drake_wbc.math.validation.validated_copy), shared with its
scalar-converted copies, so changing a parameters object afterwards has
no effect on the stages built from it.
"""

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
    ArmCapabilityParameters,
    CapabilityBand,
    WorkspaceAdapter,
    WorkspaceAdapter_,
    WorkspaceAdapterParameters,
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
    MotionDistributorParameters,
    RobustCompensator,
    RobustCompensator_,
    RobustCompensatorParameters,
)
from drake_wbc.stages.safety import (
    GuardedInput,
    InputGuard,
    InputGuard_,
    StopGate,
    StopGate_,
)
from drake_wbc.stages.whole_body_cdmp import (
    WholeBodyCdmp,
    WholeBodyCdmp_,
)

__all__ = [
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
    "ArmCartesianVelocityController",
    "ArmCartesianVelocityController_",
    "BaseVelocityFilter",
    "BaseVelocityFilter_",
    "ArmCapability",
    "ArmCapabilityParameters",
    "ArmCapability_",
    "CapabilityBand",
    "MotionDistributor",
    "MotionDistributorParameters",
    "MotionDistributor_",
    "RobustCompensator",
    "RobustCompensatorParameters",
    "RobustCompensator_",
    "WorkspaceAdapter",
    "WorkspaceAdapterParameters",
    "WorkspaceAdapter_",
]
