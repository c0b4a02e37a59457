"""The CDMP-WBC stages as Drake systems, thin over the math layer.

Every stage is a scalar-convertible `TemplateSystem` (double and
AutoDiffXd), so that Drake's `Linearize` runs on the very systems the
controller uses.
"""

from drake_wbc.systems.arm_control import (
    ArmCartesianVelocityController,
    ArmCartesianVelocityController_,
)
from drake_wbc.systems.base_filter import (
    BaseVelocityFilter,
    BaseVelocityFilter_,
)

__all__ = [
    "ArmCartesianVelocityController",
    "ArmCartesianVelocityController_",
    "BaseVelocityFilter",
    "BaseVelocityFilter_",
]
