"""The controller deployed over LCM, and the robot's side of the protocol.

- deploy: the controller Diagram against the LCM hardware interface, in
  real time (`drake-wbc deploy`).
- robot_side: the simulated station speaking the robot's side of the
  protocol (`drake-wbc robot-sim`).
- loopback: both sides in one Diagram over an in-process LCM, for tests
  and rehearsals.
- lcm_logs, plots: a log of lcm-logger read as the signals of a run, and
  its metrics and figures (`drake-wbc plot`).

Above the hardware interface (drake_wbc.hardware) and the scenarios
(drake_wbc.experiments); only the command line imports it.
"""
