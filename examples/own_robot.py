"""A robot of your own: a URDF, its description and a scenario
(examples/own_robot/), simulated in the station and checked by the demo's
tuning survey. Run it from anywhere: python examples/own_robot.py"""

from pathlib import Path

import numpy as np

from drake_wbc.experiments.runner import build_closed_loop, start_simulator
from drake_wbc.experiments.scenario import controller_for, load_scenario
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import ArmKinematics, make_robot_plant
from drake_wbc.robot.tuning import check_tuning, survey_capability

HERE = Path(__file__).resolve().parent / "own_robot"

# The description, checked against its model.
robot = load_robot_description(HERE / "omni_arm.robot.yaml")
arm = ArmKinematics(*make_robot_plant(robot))
survey = survey_capability(arm, count=300)
band = survey.proposed_band()
print(f"{robot.name}: {arm.num_joints} arm joints; C_m at home "
      f"{survey.home:.3f}; proposed k_j {survey.k_j:.3g}, band "
      f"({band.lower:.3f}, {band.upper:.3f})")

# The scenario on it, in the simulated station.
scenario = load_scenario(HERE / "own_robot.yaml")
params = controller_for(scenario)  # the robot's tuning and limits filled in
print("tuning:", check_tuning(arm, params.capability_band,
                              params.capability.joint_limit_gain)
      or "suits the arm")
loop = build_closed_loop(scenario)
simulator = start_simulator(loop)
root = simulator.get_mutable_context()
pose = loop.station.diagram.GetOutputPort("truth.end_effector_pose")
context = loop.station.diagram.GetMyContextFromRoot(root)
start = pose.Eval(context)[:3].copy()
simulator.AdvanceTo(scenario.duration)
moved = pose.Eval(context)[:3] - start
print(f"the tool moved {np.array2string(moved, precision=3)} m in "
      f"{scenario.duration} s (asked: 0.05 m/s along x, 0.02 m/s up)")
