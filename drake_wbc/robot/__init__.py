"""The robot: its Drake model and the kinematics read from it.

- description: the robot as data (`RobotDescription`, one YAML file:
  its model, joints, frames, limits and home; `load_robot_description`,
  `shipped_robot`).
- model: a described robot loaded into a MultibodyPlant and checked
  against its description (`add_robot`, `RobotModel`), and
  `ArmKinematics`, the arm's nominal kinematics from such a plant.
- footprint: the base's footprint and the start-pose check.

May import the math layer and pydrake's multibody parts; never a stage,
the controller, the station or the hardware.
"""
