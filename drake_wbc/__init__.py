"""drake_wbc: whole-body control of velocity-controlled mobile collaborative
robots with Coupling Dynamic Movement Primitives (CDMP-WBC), on Drake.

One folder a layer, each importing only those below it
(tests/test_layers.py holds them to it):

- drake_wbc.math: the paper's equations as plain functions (numpy; no
  Drake systems), importable without a diagram.
- drake_wbc.robot: the robot's model in a MultibodyPlant and its
  kinematics.
- drake_wbc.stages: each stage of the controller as a Drake system.
- drake_wbc.controller: the parameters and the controller Diagram.
- drake_wbc.station, drake_wbc.hardware: what the controller drives, the
  simulated station or the LCM interface to the real robot, with the
  same ports.
- drake_wbc.experiments: scenarios, the closed loop in simulation, and
  the paper's experiments' metrics and figures.
- drake_wbc.analysis, drake_wbc.deployment: frequency responses; the
  controller deployed over LCM and the robot's side.
- drake_wbc.bench, drake_wbc.stress: benchmarks; the randomised stress
  run.
- drake_wbc.cli: the `drake-wbc` command.
"""

__version__ = "0.1.0"
