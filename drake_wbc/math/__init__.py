"""The math layer: the paper's equations as plain functions.

numpy (and pydrake's AutoDiffXd scalars) only: nothing here imports
`pydrake.systems`, a stage, the controller, the station or the hardware,
so every equation is testable without a diagram. Each equation of the
paper has one scalar-generic reference body here, cited by its label in
the docstring; where the control tick needs speed, at most one float
kernel beside it.

Names say which is which, in every module:
- a reference body checks nothing; it has the equation's plain name
  (`whole_body_distribution`, `capability_terms`, `twist_in_base`), or
  that name with `_of` where a checked public function already holds the
  plain name (`base_jacobian_of` beside `base_jacobian`, `transition_of`
  beside `transition`);
- a function a user calls by hand checks its arguments (one thin layer,
  drake_wbc.math.validation) and calls the reference body;
- a fast kernel is the reference's name with `_float`, registered with
  `kernels.fast_kernel`; a stage picks one of the two once, when it is
  built (`kernels.body_for`).

- validation, scalar_support, loading: argument checks; math for every
  scalar type; parameters dataclasses from YAML, safe against hostile
  files.
- kinematics: J_b of eq. (2), J_wb of eq. (fk), the rotations of eq. (3).
- distribution: the weighted distribution and pseudo-inverse, eqs. (wln),
  (wbsln), (weight-factors), (wbccm).
- capability: C_m = m P_jnt and its gradient; the transition of eq.
  (transition).
- workspace, motion_mode: the local workspace and the weighting factors
  of intuitive pHRI (Sec. IV-C), the motion modes (Table I).
- filtering: the base filter, eq. (filtering).
- compensation: the robust compensation, eqs. (wb_error), (compensation),
  (deviation).
- dmp, cdmp, repulsion: the DMP core (eqs. (6), (7), and learning its
  forcing term), the coupled DMPs (eqs. (stiff-dmp), (admit-dmp),
  (cdmp-wb), (cdmp-base), (cdmp-arm), (cdmp-wb-error)) and the repulsive
  field U_rep, f_avoid.
- wrench: the external wrench F_ext on the tool from the wrist reading.
- movement, demonstration: a whole-body movement learned from
  demonstrations as a DMP (teach and repeat).
- arm_control: the arm's Cartesian velocity controller (Sec. III-A).
- joint_range: joint position ranges where a continuous joint has none
  (limits -inf and inf), and the range to draw its angles from.
- arm_servo: what a cobot's position servo refuses (a command beyond a
  joint's position, speed or acceleration limit) and its stop.
- base_state: the layout of the base's state (base.state_estimated),
  [x, y, yaw, vx, vy, wz], by name.
- task_inputs: the controller's task inputs, the size and range of
  each (S_hri, k_n, s_c, ...), the one table every check of them reads.
- safety, command_limits, separation, people, gating: the run-time
  checks, the command limits, the speed-and-separation rules, the people
  tracked between scans, and the stop switch of the couplings.
"""
