"""The closed-form motion distribution against QP-based peers.

Every contender solves the same seeded problems of the robot's arm
(any arm of n >= 6 joints, ArmKinematics): at an arm configuration q_a
(n,), split an end-effector twist V_ee (T_b) into the whole-body input
V_wb = [V_a; V_b] by the weighted least-norm problem of eq. (wln) with
Q(sigma_xy, sigma_phi) of eq. (weight-factors) and the null-space
velocity V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm):

    min (V_wb - V_n^0)^T Q^-1 (V_wb - V_n^0)   s.t.   J_wb V_wb = V_ee,

whose solution is eq. (wbsln) with the null-space term,
V_wb = J^+ V_ee + (I - J^+ J_wb) V_n^0. J_wb = [R_ba, J_b] (eq. (fk),
bottom line) needs p_ee from the arm's kinematics (ArmKinematics:
the compiled chain read from the MultibodyPlant). The arm's input V_a is
its 6-D twist in T_a whatever n (the arm controller maps it to the n
joints), so this problem has 9 variables and 6 equalities on every arm;
the QP peers take their sizes from J_wb (`problem_size`), not from
literals.

Two races, each contender a "solver" (problem, given) -> V_wb, `given`
a Given (p_ee, and J_wb, the diagonal of Q and V_n^0 for the QP peers):
- the solve: every contender is given the same data, computed
  beforehand (p_ee for the closed form, which forms the rest itself
  within its time; J_wb, Q and V_n^0 for the peers, which only arrange
  them as their solver takes them), so it times the distribution alone;
- with kinematics: every contender first evaluates the same kinematics
  (ArmKinematics.evaluate at a new q_a each problem, as the controller's
  ArmCapability does each tick), then prepares its data (the peers by
  `qp_data`) and solves.
`kinematics` (alone) and `qp_data` (the QP peers' data preparation
alone) are timed beside them: the first is the floor of every contender
with the same kinematics.

Solvers:
- closed_form: the controller's own path
  (distribution.whole_body_distribution as MotionDistributor runs it in
  double: its float kernel, the closed form for R_ba = I, after the
  per-tick check of the sigmas and k_n).
- the QP peers, with the same unchecked data preparation as the
  controller's (`qp_data`: J_wb, the diagonal of Q and V_n^0 by the
  bodies the stages run in double, kernels.body_for), then
  P = Q^-1 = diag(1 / w), q = -Q^-1 V_n^0, equality constraints
  J_wb V_wb = V_ee only:
  - daqp: DAQP called directly (daqp.solve, the six rows as equalities);
  - proxsuite: proxsuite's dense ProxQP called directly, initialised
    once and updated per problem (qp.update, qp.solve);
  - quadprog: quadprog.solve_qp (Goldfarb-Idnani, dense);
  - drake_diffik: Drake's DoDifferentialInverseKinematics (a QP solved
    inside Drake) in the scaled input u = Q^-1/2 V_wb, where the
    weighted problem is its unweighted one: J = J_wb Q^1/2, joint
    centering gain I and nominal position Q^-1/2 V_n^0 at q = 0;
  - qpsolvers_<solver>: the same QP through qpsolvers (OSQP, Clarabel,
    ProxQP when installed; each pays the wrapper's conversions),
    tolerances tightened to 1e-9 so they agree.
- drake_diffik_plant (with kinematics only; informative, not the same
  problem): Drake's overload that evaluates its own kinematics on the
  robot's MultibodyPlant, in joint velocities, unweighted. Its
  variables are the arm's n joint velocities and the base's 3 (n + 3);
  the plant's other velocities (the shipped robot's flexible mount, two)
  are held at zero by velocity bounds. Its null-space velocity is that
  of eq. (wbccm) at the arm's joints: V_n^0's arm part, the twist
  k_n grad_x C_m in T_a, as joint velocities, J_a^+ k_n grad_x C_m
  (J_a^+ = J_a^T (J_a J_a^T)^-1, J_a^-1 on six joints), and 0 for the
  base (the problem's `joint_null_velocity`, computed with it: given
  data, as the gradient is). Drake builds the null-space cost from a
  non-orthonormal basis, so with bounds its answer is not the
  least-norm one of its (n + 3)-DoF problem; its difference is
  reported, not checked (without bounds, on a robot without a mount,
  they agree).

sigma is drawn inside (0.05, 0.95) so that Q is invertible (the QPs need
Q^-1); no inequality constraint is present, so all the same-problem
contenders must agree (fairness, checked before any timing).
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsParameters,
    DifferentialInverseKinematicsStatus,
    DoDifferentialInverseKinematics,
)

from drake_wbc.math import distribution, kernels, kinematics
from drake_wbc.math.joint_range import configuration_range
from drake_wbc.math.validation import (
    in_closed_range,
    non_negative,
    whole_number,
)
from drake_wbc.robot.model import (
    ArmKinematics,
    joint_position_indices,
    joint_velocity_indices,
)

REFERENCE = "closed_form"
"""The contender whose time the ratios divide by."""

QP_SOLVERS = ("osqp", "clarabel", "proxqp")
"""The qpsolvers back-ends raced, those installed."""

QP_SETTINGS = {
    "osqp": dict(eps_abs=1e-10, eps_rel=1e-10, polishing=True,
                 verbose=False),
    "clarabel": dict(tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10,
                     verbose=False),
    "proxqp": dict(eps_abs=1e-10, eps_rel=0.0, verbose=False),
}
"""Tolerances tight enough for the solvers to agree with the closed form
to about 1e-8 (their defaults stop near 1e-5)."""

SPARSE_SOLVERS = ("osqp", "clarabel")
"""Back-ends that take sparse matrices (given as CSC directly, so that
qpsolvers converts nothing)."""


@dataclass(frozen=True)
class DistributionProblem:
    """One problem of the race (see the module docstring).

    Attributes:
        arm_position: q_a (n,), rad.
        base_yaw: phi_b, rad (for drake_diffik_plant's world frame).
        end_effector_velocity: V_ee (6) in T_b, [v; w].
        sigma_xy, sigma_phi: weighting factors in (0, 1).
        capability_gradient: grad_x C_m (6), T_a.
        null_space_gain: k_n >= 0.
        joint_null_velocity: V_n^0's arm part at the arm's joints,
            J_a(q_a)^+ k_n grad_x C_m (n,), rad/s: the joint-space
            peer's null-space velocity (PlantDiffIk).
    """

    arm_position: np.ndarray
    base_yaw: float
    end_effector_velocity: np.ndarray
    sigma_xy: float
    sigma_phi: float
    capability_gradient: np.ndarray
    null_space_gain: float
    joint_null_velocity: np.ndarray


def joint_null_velocity(J_a, capability_gradient, null_space_gain):
    """V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm), its arm part (a
    twist in T_a) at the arm's n joints: the least-norm joint velocity
    J_a^+ k_n grad_x C_m with J_a^+ = J_a^T (J_a J_a^T)^-1 (J_a^-1 when
    n = 6), for J_a (6, n) of full row rank."""
    J_a = np.asarray(J_a, dtype=float)
    twist = null_space_gain * np.asarray(capability_gradient, dtype=float)
    return J_a.T @ np.linalg.solve(J_a @ J_a.T, twist)


def make_problems(count, seed, arm):
    """`count` problems drawn with numpy's generator seeded by `seed`:
    q_a uniform in 80 % of the joint ranges of `arm` (ArmKinematics, its
    n joints; a continuous joint's range one turn,
    drake_wbc.math.joint_range.configuration_range), V_ee normal with
    0.1 m/s, rad/s per component, sigma uniform in (0.05, 0.95),
    grad_x C_m normal with 0.3 (6,), k_n uniform in [0, 0.2]; the
    joint-space null velocity from J_a at q_a (no
    draw: the same seed gives the same problems as without it)."""
    count = whole_number("count", count, minimum=1)
    rng = np.random.default_rng(seed)
    lower, upper = configuration_range(arm.lower, arm.upper)
    middle = 0.5 * (lower + upper)
    half = 0.4 * (upper - lower)
    problems = []
    for _ in range(count):
        q_a = rng.uniform(middle - half, middle + half)
        base_yaw = float(rng.uniform(-np.pi, np.pi))
        V_ee = rng.normal(0.0, 0.1, 6)
        sigma_xy = float(rng.uniform(0.05, 0.95))
        sigma_phi = float(rng.uniform(0.05, 0.95))
        gradient = rng.normal(0.0, 0.3, 6)
        k_n = float(rng.uniform(0.0, 0.2))
        problems.append(DistributionProblem(
            arm_position=q_a, base_yaw=base_yaw, end_effector_velocity=V_ee,
            sigma_xy=sigma_xy, sigma_phi=sigma_phi,
            capability_gradient=gradient, null_space_gain=k_n,
            joint_null_velocity=joint_null_velocity(
                arm.evaluate(q_a).J_a, gradient, k_n)))
    return problems


def problem_size(arm):
    """(variables, equalities) of the whole-body problem of `arm`: the
    columns and rows of its J_wb = [R_ba, J_b] (eq. (fk), bottom line),
    formed at the arm's home as `qp_data` forms it."""
    p_ee = arm.evaluate(arm.home).p_ee_in_base
    J = kinematics.whole_body_jacobian_of(None, p_ee,
                                          np.array(arm.R_ba, dtype=float))
    equalities, variables = np.shape(J)
    return variables, equalities


def mounting(arm):
    """^bR_a of `arm` as the controller's distributor takes it: None for
    the identity (the closed form's case), the matrix otherwise."""
    R_ba = np.array(arm.R_ba, dtype=float)
    return None if np.array_equal(R_ba, np.eye(3)) else R_ba


def kinematics_of(arm):
    """The kinematics every contender starts from: p_ee (T_b) at q_a by
    ArmKinematics.evaluate, as the controller's ArmCapability runs it."""

    def evaluate(problem):
        return arm.evaluate(problem.arm_position).p_ee_in_base

    return evaluate


class Given(NamedTuple):
    """What a solver is given: p_ee (3, T_b), and for the QP peers
    J_wb (6, 9), the diagonal w of Q (9,) and V_n^0 (9,) (None for the
    closed form, which forms them itself); 9 = V_a's 6 and V_b's 3 on
    an arm of any number of joints."""

    p_ee: np.ndarray
    J_wb: np.ndarray | None = None
    weights: np.ndarray | None = None
    null_velocity: np.ndarray | None = None


def qp_data(arm):
    """The QP peers' data preparation, unchecked, by the bodies the
    controller's stages run in double: (problem, p_ee) -> Given with
    J_wb, the diagonal w of Q and V_n^0."""
    R_ba = np.array(arm.R_ba, dtype=float)
    jacobian = kernels.body_for(kinematics.whole_body_jacobian_of, float)
    weights = kernels.body_for(distribution.weight_factors, float)
    null = kernels.body_for(distribution.capability_null_velocity_of, float)

    def prepare(problem, p_ee):
        return Given(p_ee, jacobian(None, p_ee, R_ba),
                     weights(problem.sigma_xy, problem.sigma_phi),
                     null(problem.capability_gradient,
                          problem.null_space_gain))

    return prepare


def closed_form(arm):
    """The controller's distribution, as its tick runs it
    (stages.MotionDistributor): eqs. (wbsln)/(wbccm) for
    J_wb = [R_ba, J_b] by the body MotionDistributor runs in double
    (distribution.whole_body_distribution's float kernel: the closed form
    for R_ba = I); the controller checks its parameters once, when it is
    built, and the sigmas and k_n on each tick, as here."""
    R_ba = mounting(arm)
    damping = distribution.DEFAULT_DAMPING
    distribute = kernels.body_for(distribution.whole_body_distribution,
                                  float)

    def solve(problem, given):
        sigma_xy, sigma_phi, k_n = (problem.sigma_xy, problem.sigma_phi,
                                    problem.null_space_gain)
        if not (0.0 <= sigma_xy <= 1.0 and 0.0 <= sigma_phi <= 1.0
                and 0.0 <= k_n < np.inf):
            in_closed_range("sigma_xy", sigma_xy, 0.0, 1.0)
            in_closed_range("sigma_phi", sigma_phi, 0.0, 1.0)
            non_negative("k_n", k_n)
        return distribute(problem.end_effector_velocity, given.p_ee, R_ba,
                          sigma_xy, sigma_phi, problem.capability_gradient,
                          k_n, damping)

    solve.needs_qp_data = False
    return solve


def daqp_solver(arm):
    """DAQP called directly: daqp.solve with the rows of J_wb as
    equalities (sense 5)."""
    import daqp

    _, equalities = problem_size(arm)
    sense = np.full(equalities, 5, dtype=np.int32)

    def solve(problem, given):
        _, J, w, V_n = given
        inverse = 1.0 / w
        b = problem.end_effector_velocity
        x, _, flag, _ = daqp.solve(np.diag(inverse), -inverse * V_n, J, b,
                                   b, sense)
        if flag != 1:
            raise RuntimeError(f"DAQP returned exit flag {flag} on a "
                               "problem with equalities only")
        return x

    return solve


PROXSUITE_TOLERANCE = 1e-12
"""ProxQP's eps_abs (eps_rel 0): its default, 1e-5, stops far from the
others."""


def proxsuite_solver(arm):
    """proxsuite's dense ProxQP called directly, initialised once (here)
    and updated with each problem's data (qp.update)."""
    from proxsuite import proxqp

    n, m = problem_size(arm)
    qp = proxqp.dense.QP(n, m, 0)
    qp.settings.eps_abs = PROXSUITE_TOLERANCE
    qp.settings.eps_rel = 0.0
    qp.settings.verbose = False
    qp.init(np.eye(n), np.zeros(n), np.zeros((m, n)), np.zeros(m), None,
            None, None)

    def solve(problem, given):
        _, J, w, V_n = given
        inverse = 1.0 / w
        qp.update(H=np.diag(inverse), g=-inverse * V_n, A=J,
                  b=problem.end_effector_velocity)
        qp.solve()
        if qp.results.info.status != proxqp.QPSolverOutput.PROXQP_SOLVED:
            raise RuntimeError(f"ProxQP returned {qp.results.info.status}"
                               " on a problem with equalities only")
        return qp.results.x.copy()

    return solve


def quadprog_solver(arm):
    """quadprog.solve_qp: min 1/2 x^T G x - a^T x s.t. C^T x >= b with
    the first meq rows (all of J_wb's) as equalities."""
    import quadprog

    _, equalities = problem_size(arm)

    def solve(problem, given):
        _, J, w, V_n = given
        inverse = 1.0 / w
        return quadprog.solve_qp(np.diag(inverse), inverse * V_n,
                                 np.ascontiguousarray(J.T),
                                 problem.end_effector_velocity,
                                 equalities)[0]

    return solve


def drake_diffik(arm, time_step=0.01):
    """Drake's DoDifferentialInverseKinematics on the scaled problem."""
    n, _ = problem_size(arm)
    params = DifferentialInverseKinematicsParameters(n, n)
    params.set_time_step(time_step)
    params.set_joint_centering_gain(np.eye(n))
    zero = np.zeros(n)

    def solve(problem, given):
        _, J, weights, V_n = given
        root = np.sqrt(weights)
        params.set_nominal_joint_position(V_n / root)
        result = DoDifferentialInverseKinematics(
            zero, zero, problem.end_effector_velocity, J * root, params)
        _check_status(result)
        return root * result.joint_velocities

    return solve


def _check_status(result):
    if result.status != DifferentialInverseKinematicsStatus.kSolutionFound:
        raise RuntimeError(
            f"DoDifferentialInverseKinematics returned {result.status} on "
            "a problem without active constraints")


def qpsolvers_solver(arm, solver):
    """The weighted QP through qpsolvers with back-end `solver`."""
    import qpsolvers
    import scipy.sparse

    if solver not in qpsolvers.available_solvers:
        raise ValueError(
            f"solver = {solver!r} is not allowed: must be one of the "
            f"installed qpsolvers back-ends {qpsolvers.available_solvers}")
    sparse = solver in SPARSE_SOLVERS
    settings = QP_SETTINGS.get(solver, {})

    def solve(problem, given):
        _, J, weights, V_n = given
        inverse = 1.0 / weights
        if sparse:
            P = scipy.sparse.diags(inverse, format="csc")
            A = scipy.sparse.csc_matrix(J)
        else:
            P, A = np.diag(inverse), J
        x = qpsolvers.solve_qp(P, -inverse * V_n, A=A,
                               b=problem.end_effector_velocity,
                               solver=solver, **settings)
        if x is None:
            raise RuntimeError(f"qpsolvers back-end {solver!r} found no "
                               "solution")
        return x

    return solve


class PlantDiffIk:
    """Drake's DiffIK overload on the robot's MultibodyPlant (its own
    kinematics), joint space (the arm's n joints and the base's 3), mount
    held by velocity bounds; its null-space velocity is
    problem.joint_null_velocity (eq. (wbccm) at the arm's joints).

    Args:
        arm: ArmKinematics whose plant (the robot alone) is used.
        time_step: DiffIK's time step, s.
    """

    def __init__(self, arm, time_step=0.01):
        plant, model = arm.plant, arm.model
        self.plant, self.frame = plant, model.tcp_frame
        self.context = plant.CreateDefaultContext()
        nv = plant.num_velocities()
        self.iq_arm = joint_position_indices(model.arm_joints)
        self.iq_base = joint_position_indices(model.base_joints)
        self.iv_arm = joint_velocity_indices(model.arm_joints)
        self.iv_base = joint_velocity_indices(model.base_joints)
        mount = joint_velocity_indices(model.passive_joints)
        limit = np.full(nv, np.inf)
        limit[mount] = 0.0
        self.params = DifferentialInverseKinematicsParameters(
            plant.num_positions(), nv)
        self.params.set_time_step(time_step)
        self.params.set_joint_velocity_limits((-limit, limit))
        self.params.set_joint_centering_gain(np.eye(nv))

    def _world_twist(self, problem):
        """V_ee in the world, Drake's order [w; v]."""
        c, s = np.cos(problem.base_yaw), np.sin(problem.base_yaw)
        R_wb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        V = problem.end_effector_velocity
        return np.concatenate([R_wb @ V[3:], R_wb @ V[:3]])

    def __call__(self, problem):
        """The solution as [dq_a (n,); V_b (3, T_b)]."""
        q = np.zeros(self.plant.num_positions())
        q[self.iq_arm] = problem.arm_position
        q[self.iq_base[2]] = problem.base_yaw
        self.plant.SetPositions(self.context, q)
        nominal = q.copy()
        nominal[self.iq_arm] += problem.joint_null_velocity
        self.params.set_nominal_joint_position(nominal)
        result = DoDifferentialInverseKinematics(
            self.plant, self.context, self._world_twist(problem),
            self.frame, self.params)
        _check_status(result)
        v = result.joint_velocities
        c, s = np.cos(problem.base_yaw), np.sin(problem.base_yaw)
        vx, vy, wz = v[self.iv_base]
        return np.concatenate([v[self.iv_arm],
                               [c * vx + s * vy, -s * vx + c * vy, wz]])

    def least_norm(self, problem):
        """The (n + 3)-DoF least-norm answer of the same joint-space
        problem (J^+ of eq. (wbsln) with Q = I), to compare."""
        self(problem)  # sets the configuration
        from pydrake.multibody.tree import JacobianWrtVariable

        world = self.plant.world_frame()
        J = self.plant.CalcJacobianSpatialVelocity(
            self.context, JacobianWrtVariable.kV, self.frame, np.zeros(3),
            world, world)
        columns = np.concatenate([self.iv_arm, self.iv_base])
        J = np.vstack([J[3:], J[:3]])[:, columns]
        twist = self._world_twist(problem)
        V = np.concatenate([twist[3:], twist[:3]])
        n = len(self.iv_arm)
        z = np.zeros(n + 3)
        z[:n] = problem.joint_null_velocity
        # J^+ with Q = I (weighted_pseudoinverse's body, which checks
        # for 9 columns; this problem has n + 3).
        J_pinv = distribution.weighted_distribution(
            J, np.eye(6), np.eye(n + 3), None, distribution.DEFAULT_DAMPING)
        v = J_pinv @ V + z - J_pinv @ (J @ z)
        c, s = np.cos(problem.base_yaw), np.sin(problem.base_yaw)
        vx, vy, wz = v[n:]
        return np.concatenate([v[:n], [c * vx + s * vy, -s * vx + c * vy,
                                       wz]])


def make_solvers(arm=None, time_step=0.01, solvers=QP_SOLVERS):
    """The solvers of the same problem by name: callables
    (problem, given) -> V_wb (9,), closed_form first, then the direct
    peers (DAQP, ProxQP, quadprog, Drake's DiffIK), then the qpsolvers
    back-ends of `solvers` that are installed."""
    import qpsolvers

    arm = arm or ArmKinematics()
    same = {REFERENCE: closed_form(arm),
            "daqp": daqp_solver(arm),
            "proxsuite": proxsuite_solver(arm),
            "quadprog": quadprog_solver(arm),
            "drake_diffik": drake_diffik(arm, time_step)}
    for solver in solvers:
        if solver in qpsolvers.available_solvers:
            same[f"qpsolvers_{solver}"] = qpsolvers_solver(arm, solver)
    return same


def with_kinematics(arm, solve):
    """problem -> V_wb: the kinematics of `arm`, the data preparation
    `solve` needs (`qp_data` unless it has needs_qp_data False), then
    `solve`."""
    evaluate = kinematics_of(arm)
    if getattr(solve, "needs_qp_data", True):
        prepare = qp_data(arm)

        def solve_from_scratch(problem):
            return solve(problem, prepare(problem, evaluate(problem)))
    else:
        def solve_from_scratch(problem):
            return solve(problem, Given(evaluate(problem)))

    return solve_from_scratch


def given_data(arm, problems):
    """The Given of every problem (the kinematics and `qp_data`)."""
    evaluate, prepare = kinematics_of(arm), qp_data(arm)
    return [prepare(problem, evaluate(problem)) for problem in problems]


def fairness(problems, solvers, given, informative=None):
    """Largest difference of each solver's V_wb from closed_form's.

    Args:
        problems: the problems.
        solvers: dict name -> (problem, given) -> V_wb (make_solvers).
        given: the Given of each problem (given_data).
        informative: dict name -> PlantDiffIk-like solvers (problem ->
            V_wb, with `least_norm`), compared with the least-norm answer
            of their own joint-space problem.

    Returns:
        dict name -> {"max_abs_difference": float, "same_problem": bool}.
    """
    reference = solvers[REFERENCE]
    expected = [reference(p, g) for p, g in zip(problems, given,
                                                 strict=True)]
    report = {}
    for name, solve in solvers.items():
        difference = max(float(np.max(np.abs(solve(p, g) - x)))
                         for p, g, x in zip(problems, given, expected,
                                            strict=True))
        report[name] = {"max_abs_difference": difference,
                        "same_problem": True}
    for name, solver in (informative or {}).items():
        difference = max(
            float(np.max(np.abs(solver(p) - solver.least_norm(p))))
            for p in problems)
        report[name] = {"max_abs_difference": difference,
                        "same_problem": False}
    return report


def batch(solve, problems, given=None):
    """A contender for timing.interleave: solves every problem once
    (`solve(problem, given)` when `given` holds one entry per problem;
    `solve(problem)` otherwise)."""
    if given is None:
        def run():
            for problem in problems:
                solve(problem)
            return len(problems)
    else:
        pairs = list(zip(problems, given, strict=True))

        def run():
            for problem, p in pairs:
                solve(problem, p)
            return len(pairs)

    return run
