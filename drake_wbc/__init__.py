"""drake_wbc: whole-body control of velocity-controlled mobile collaborative
robots with Coupling Dynamic Movement Primitives (CDMP-WBC), on Drake.

The math layer (numpy only) is importable without Drake:
`drake_wbc.kinematics`, `drake_wbc.distribution`, `drake_wbc.capability`,
`drake_wbc.compensation`. The robot model and its kinematics from a
`MultibodyPlant` are in `drake_wbc.robot_model`.
"""

__version__ = "0.1.0"
