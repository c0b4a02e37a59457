"""drake_wbc: whole-body control of velocity-controlled mobile collaborative
robots with Coupling Dynamic Movement Primitives (CDMP-WBC), on Drake.

The math layer (numpy only) is importable without Drake:
`drake_wbc.kinematics`, `drake_wbc.pseudoinverse`, `drake_wbc.distribution`,
`drake_wbc.capability`, `drake_wbc.compensation`, `drake_wbc.filtering`.
The robot model and its kinematics from a `MultibodyPlant` are in
`drake_wbc.robot_model`; the controller's stages, as Drake systems, are in
`drake_wbc.systems` and importable from the package itself (`from
drake_wbc import BaseVelocityFilter`).
"""

__version__ = "0.1.0"

_SYSTEMS = (
    "ArmCdmp",
    "BaseCdmp",
    "WholeBodyCdmp",
    "ArmCartesianVelocityController",
    "BaseVelocityFilter",
    "ArmCapability",
    "MotionDistributor",
    "RobustCompensator",
    "WorkspaceAdapter",
)


def __getattr__(name):
    # The stages import Drake's systems framework; load them on first use
    # so that the math layer stays importable on its own.
    if name in _SYSTEMS:
        from drake_wbc import systems

        return getattr(systems, name)
    raise AttributeError(f"module 'drake_wbc' has no attribute {name!r}")
