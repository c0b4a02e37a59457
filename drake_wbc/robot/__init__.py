"""The robot: its Drake model and the kinematics read from it.

- model: the mobile collaborative robot of models/ loaded into a
  MultibodyPlant (`add_mcr`), and `ArmKinematics`, the arm's nominal
  kinematics from such a plant.
- footprint: the base's footprint and the start-pose check.

May import the math layer and pydrake's multibody parts; never a stage,
the controller, the station or the hardware.
"""
