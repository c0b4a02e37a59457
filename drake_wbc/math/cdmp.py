"""Coupling DMPs of the controller (paper Sec. III-C and IV-B).

Each function returns the time derivatives of its state pieces, to be
integrated by a Drake system whose output is the velocity y_dot, the
paper's velocity interface ("Admittance-coupled DMP exhibits equivalence
as velocity control interface from C_dot to y_dot"): on its goal, y_dot =
z / tau + C_dot = C_dot. A coupling C with a given C_dot is a state
integrated alongside y and z. The goal g is a constant input; f(s) an
optional value (default 0, as in all of the paper's experiments).

Force convention: F, F_e, F_ext and F_d are the wrench [force; torque]
that the environment or a person exerts ON the robot, in the frame of y.
Then every coupling yields to it: y moves along F in eqs. (stiff-dmp) and
(cdmp-arm) (stiffness), along F_e - F_d in eq. (admit-dmp), along F_ext in
eq. (cdmp-wb). Sign note on eq. (cdmp-arm): its force term is printed as
k_f (I - S_m)(F_d - F_ext), the opposite sign of eq. (admit-dmp); with a
single convention for F_ext that term is unstable against any contact of
positive stiffness K_env (C_a grows at the rate k_f K_env), so it is
implemented as k_f (I - S_m)(F_ext - F_d), the sign of eq. (admit-dmp).
The paper's F_d = -10 N along x thus means the surface pushes the tool
with 10 N along -x, i.e. the tool presses 10 N along +x.

Derivative of the input (k_d C_dot of eqs. (stiff-dmp), (cdmp-arm)). With
C = k_p F algebraic, tau z_dot contains k_d k_p F_dot. No derivative of a
measured force is needed if the state holds the shifted velocity

    z~ = z - (k_d / tau) C,

for then tau z~_dot = alpha_z (beta_z (g - y) - z~ - (k_d / tau) C) + f
and tau y_dot = z~ + (k_d / tau) C + (the velocity coupling). This is the
same system (the transfer function of eq. (lp-admit) holds exactly); a
step of F steps z by (k_d / tau) k_p dF as in the paper while z~ stays
continuous. `shifted_velocity` and `paper_velocity` convert.

All derivative functions use elementwise arithmetic and products with
float matrices only, so they accept numpy object arrays of AutoDiffXd;
their parameters are checked once, in the dataclasses.

The whole-body CDMP runs in the world frame, its twists [v; w] turned
about the vertical by the base's yaw (eq. (3): drake_wbc.math.kinematics
`twist_in_base` and its inverse `twist_in_world`).
"""

import math
from dataclasses import dataclass, field, fields

import numpy as np

from drake_wbc.math.dmp import DmpParameters, transformation_derivative
from drake_wbc.math.repulsion import RepulsiveFieldParameters, repulsive_force
from drake_wbc.math.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    checked_instance,
    non_negative,
    positive,
    selection,
    within_site,
)


def _dmp(params):
    if not isinstance(params, DmpParameters):
        raise ValueError(f"dmp = {params!r} is not allowed: must be a "
                         "DmpParameters")


def _set(obj, name, value):
    """Stores a checked value in `obj`, an array as a read-only copy (so
    that it changes only by assignment, which `validate` checks)."""
    if isinstance(value, np.ndarray):
        value = np.array(value, dtype=float)
        value.flags.writeable = False
    setattr(obj, name, value)


def _fields_equal(a, b):
    """The == of a parameters dataclass with array fields: the same class
    and every field equal, arrays by np.array_equal (shape and values).
    The classes using it define __eq__, so that, like the other
    parameters dataclasses (mutable, compared by value), they are
    unhashable."""
    if a.__class__ is not b.__class__:
        return NotImplemented
    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not np.array_equal(x, y):
                return False
        elif x != y:
            return False
    return True


@dataclass
class StiffnessCouplingParameters:
    """Eq. (stiff-dmp): C_f = k_p F and the gain k_d of k_d C_f_dot,
    both >= 0 (defaults: the paper's k_p of the arm, k_d = 0)."""

    k_p: float = 0.0005
    k_d: float = 0.0
    dmp: DmpParameters = field(default_factory=DmpParameters)

    def __post_init__(self):
        non_negative("k_p", self.k_p)
        non_negative("k_d", self.k_d)
        _dmp(self.dmp)


@dataclass(eq=False)
class AdmittanceCouplingParameters:
    """Eq. (admit-dmp): C_dot = V + D_a (F_e - F_d).

    Attributes:
        D_a: admittance D_a, a number > 0 (D_a I) or a symmetric positive
            definite (d, d) matrix; m/(N s). Default 0.01 (the paper's
            k_f). Stored as a read-only array (0-d for a number).
        F_d: desired wrench F_d, a number or (d,); default 0. Stored like
            D_a.
    """

    D_a: np.ndarray = 0.01
    F_d: np.ndarray = 0.0
    dmp: DmpParameters = field(default_factory=DmpParameters)

    def __post_init__(self):
        if np.ndim(self.D_a) == 0:
            D_a = positive("D_a", self.D_a)
        else:
            D_a = as_matrix("D_a", self.D_a, (None, None))
            if (D_a.shape[0] != D_a.shape[1]
                    or not np.allclose(D_a, D_a.T, rtol=0, atol=1e-12)
                    or np.linalg.eigvalsh(D_a)[0] <= 0.0):
                raise ValueError(
                    f"D_a = {D_a!r} is not allowed: must be a number > 0 or "
                    "a symmetric positive definite matrix")
        _set(self, "D_a", np.asarray(D_a))
        if np.ndim(self.F_d) == 0:
            F_d = as_scalar("F_d", self.F_d)
        else:
            F_d = as_vector("F_d", self.F_d, np.shape(D_a)[0] if np.ndim(
                D_a) else None)
        _set(self, "F_d", np.asarray(F_d))
        _dmp(self.dmp)

    def __eq__(self, other):
        return _fields_equal(self, other)


@dataclass
class MovementReplay:
    """A learned movement played by the whole-body CDMP (eq. (cdmp-wb)
    with the forcing term f(s) of eq. (6); drake_wbc.math.movement).

    Attributes:
        file: the learned movement (a YAML file written by
            `drake-wbc teach`); a relative path is looked up in the
            working folder, then in the repository's diagrams/.
        goal: the TCP's goal [x, y, z, yaw] in the world (m, rad; x, y
            and z within the scene's site, +-SITE_EXTENT of
            drake_wbc.math.validation), or None for the demonstrated goal.
        tau: the temporal scaling tau > 0 (the movement runs tau / tau_0
            times slower, tau_0 the learned one), or None for the learned
            one.
        start_time: when the movement starts, s >= 0 of the controller's
            clock; before it the DMP runs with g = 0 and f = 0.
        start: the TCP's pose [x, y, z, yaw] in the world where the
            controller starts (its DMP's origin; within the site as the
            goal), or None for the demonstration's start.
        tracking_gain: K >= 0, 1/s: from start_time, the task adds
            V_ee^ref = K (p*(t) - p(t)) on x, y, z and yaw, p* the pose
            the DMP plays (its own rollout) and p the TCP's pose from the
            measured joints and odometry (drake_wbc.experiments.runner wires it,
            drake_wbc.stages.whole_body_cdmp.MovementTracking); 0 plays the
            movement open loop. Default 3: the paper's controller is a
            velocity interface, and without it the TCP lags the DMP by
            the whole body's tracking delay (the base's velocity loop)
            and drifts with the base's yaw lag.

    Checked here for form; the file is read (and its existence checked:
    an empty name is not allowed then) when the controller is built.
    """

    file: str = ""
    goal: list[float] | None = None
    tau: float | None = None
    start_time: float = 0.0
    start: list[float] | None = None
    tracking_gain: float = 3.0

    def __post_init__(self):
        if not isinstance(self.file, str):
            raise ValueError(f"file = {self.file!r} is not allowed: must "
                             "be the path of the learned movement's file")
        for name in ("goal", "start"):
            if getattr(self, name) is not None:
                pose = tuple(float(v) for v in as_vector(
                    name, getattr(self, name), 4))
                # A point of the scene (goal: [1e300, ...] ran into NaN
                # references and a safety stop).
                _set(self, name, within_site(name, pose, lengths=pose[:3]))
        if self.tau is not None:
            positive("tau", self.tau)
        non_negative("start_time", self.start_time)
        non_negative("tracking_gain", self.tracking_gain)


MAX_K_HRI = 1.0
"""The largest admittance gain k_hri, m/(N s): k_hri F_ext is a velocity
of eq. (cdmp-wb), and at 1 m/(N s) a push of 1 N already asks for 1 m/s,
the base's limit (a larger gain moves the robot at its limits on the
wrist's noise alone, and overflows the DMP's discretisation near
1e300)."""


MAX_HRI_TIME_CONSTANT = 10.0
"""The longest admittance time constant T_hri, s: at 10 s the robot takes
half a minute to follow a push (a virtual mass of 200 kg at the paper's
k_hri), no longer a hand guide."""


@dataclass
class WholeBodyCdmpParameters:
    """Eq. (cdmp-wb): admittance gain k_hri in [0, MAX_K_HRI] (m/(N s);
    paper 0.05), the admittance's time constant hri_time_constant T_hri
    in [0, MAX_HRI_TIME_CONSTANT] (s; default 0.1, 0 for the paper's pure
    admittance; `admittance_filter_model`), and an optional learned
    movement to play (MovementReplay; None, the default, keeps the
    paper's g = 0 and f = 0). The pHRI switch S_hri is an input (its
    default is ControllerParameters.phri_switch, one for both DMPs that
    take it)."""

    k_hri: float = 0.05
    hri_time_constant: float = 0.1
    dmp: DmpParameters = field(default_factory=DmpParameters)
    movement: MovementReplay | None = None

    def __post_init__(self):
        if non_negative("k_hri", self.k_hri) > MAX_K_HRI:
            raise ValueError(
                f"k_hri = {self.k_hri!r} m/(N s) is not allowed: must be at "
                f"most {MAX_K_HRI!r} m/(N s) (k_hri F_ext is a velocity: "
                f"at {MAX_K_HRI!r} a push of 1 N already asks for 1 m/s)")
        if (non_negative("hri_time_constant", self.hri_time_constant)
                > MAX_HRI_TIME_CONSTANT):
            raise ValueError(
                f"hri_time_constant = {self.hri_time_constant!r} s is not "
                f"allowed: must be at most {MAX_HRI_TIME_CONSTANT!r} s (a "
                "longer one no longer follows a hand)")
        _dmp(self.dmp)
        self.movement = checked_instance("movement", self.movement,
                                         MovementReplay, lambda: None)


@dataclass
class BaseCdmpParameters:
    """Eq. (cdmp-base): the repulsive field and the DMP."""

    repulsion: RepulsiveFieldParameters = field(
        default_factory=RepulsiveFieldParameters)
    dmp: DmpParameters = field(default_factory=DmpParameters)

    def __post_init__(self):
        if not isinstance(self.repulsion, RepulsiveFieldParameters):
            raise ValueError(f"repulsion = {self.repulsion!r} is not "
                             "allowed: must be a RepulsiveFieldParameters")
        _dmp(self.dmp)


@dataclass(eq=False)
class ArmCdmpParameters:
    """Eq. (cdmp-arm), with the paper's wiping values as defaults.

    Attributes:
        k_p: stiffness gain k_p >= 0 (paper 0.0005); steady offset
            k_p F / beta_z.
        k_d: gain k_d >= 0 of k_d C_s_dot (not given; default 0).
        k_f: force gain k_f >= 0 (paper 0.01), m/(N s) and rad/(N m s).
        S_m: (6,) diagonal of the selection matrix S_m, each 0 (force
            control) or 1 (stiffness); default (0, 1, 1, 1, 1, 1).
        F_d: (6,) desired wrench F_d on the tool; default -10 N along x.

    S_m and F_d are stored as read-only float arrays. The pHRI switch
    S_hri is an input (its default is ControllerParameters.phri_switch,
    one for both DMPs that take it).
    """

    k_p: float = 0.0005
    k_d: float = 0.0
    k_f: float = 0.01
    S_m: np.ndarray = (0.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    F_d: np.ndarray = (-10.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    dmp: DmpParameters = field(default_factory=DmpParameters)

    def __post_init__(self):
        for name in ("k_p", "k_d", "k_f"):
            non_negative(name, getattr(self, name))
        _set(self, "S_m", selection("S_m", self.S_m, 6))
        _set(self, "F_d", as_vector("F_d", self.F_d, 6))
        _dmp(self.dmp)

    def __eq__(self, other):
        return _fields_equal(self, other)


def shifted_velocity(z, C, k_d, tau):
    """z~ = z - (k_d / tau) C, the state used for eqs. (stiff-dmp) and
    (cdmp-arm) (module docstring)."""
    return z - (k_d / tau) * C


def paper_velocity(z_tilde, C, k_d, tau):
    """The paper's z = z~ + (k_d / tau) C."""
    return z_tilde + (k_d / tau) * C


def stiffness_coupled_derivative(y, z_tilde, g, F, params, forcing=0.0):
    """Stiffness-coupled DMP, eq. (stiff-dmp), transfer function
    eq. (lp-admit):

        tau z_dot = alpha_z (beta_z (g - y) - z) + k_d C_f_dot + f,
        tau y_dot = z + tau C_f,    C_f = k_p F,

    with the state (y, z~), z~ = z - (k_d / tau) C_f (module docstring).

    State (y, z~), each (d,); inputs the goal g and the force F, (d,);
    StiffnessCouplingParameters; forcing f(s) (default 0). Returns
    (y_dot, z_tilde_dot); y_dot is the velocity command.
    """
    tau = params.dmp.tau
    C_f = params.k_p * F
    return transformation_derivative(
        y, paper_velocity(z_tilde, C_f, params.k_d, tau), g, None,
        params.dmp, forcing, coupling_velocity=tau * C_f)


def _admittance(D_a, v):
    return D_a @ v if D_a.ndim == 2 else D_a * v


def admittance_coupled_derivative(y, z, C, g, F_e, params, V=0.0,
                                  forcing=0.0):
    """Admittance-coupled DMP, eq. (admit-dmp), with the velocity input of
    Sec. IV-B:

        tau z_dot = alpha_z (beta_z (g + C - y) - z) + f,
        tau y_dot = z + tau C_dot,    C_dot = V + D_a (F_e - F_d).

    Transfer function (derivation): e = y - g - C obeys tau e_dot = z,
    tau z_dot = -alpha_z (beta_z e + z), with no input, so from e(0) =
    z(0) = 0, y = g + C exactly and L(y) = D_a L(F_e) / s, eq.
    (tf-admit), at every frequency (the attractor's poles cancel); an
    initial mismatch e(0) decays critically damped on top.

    State (y, z, C), each (d,); inputs the goal g, the wrench F_e and
    the velocity V (default 0), (d,); AdmittanceCouplingParameters;
    forcing f(s) (default 0). Returns (y_dot, z_dot, C_dot); y_dot is the
    velocity command.
    """
    tau = params.dmp.tau
    C_dot = V + _admittance(params.D_a, F_e - params.F_d)
    y_dot, z_dot = transformation_derivative(
        y, z, g + C, None, params.dmp, forcing, coupling_velocity=tau * C_dot)
    return y_dot, z_dot, C_dot


def whole_body_cdmp_derivative(y, z, C, E, g, V_ee, F_ext, delta_V_ee,
                               params, S_hri=0.0, forcing=0.0, dmp=None):
    """CDMP of the whole body, eq. (cdmp-wb) with the tracking-error term
    of eq. (cdmp-wb-error):

        tau z_dot = alpha_z (beta_z (g + C - (y + E)) - z) + f,
        tau y_dot = z + tau C_dot,  C_dot = V_ee + k_hri F_ext S_hri,
        E_dot = delta_V_ee          (E = int delta_V_ee dt),

    E integrated here from the deviation delta_V_ee of eq. (deviation)
    (it only enters E_dot, so no algebraic loop through the distributor).
    y + E is where the end effector really is; the DMP drives it to g + C,
    commanding back any accumulated deviation. Set E = delta_V_ee = 0 for
    eq. (cdmp-wb) alone.

    State (y, z, C, E), each (d,) (d = 6, twists [v; w]); inputs the
    goal g, the velocity V_ee, the wrench F_ext on the end effector and
    delta_V_ee, (d,); WholeBodyCdmpParameters; S_hri 0 or 1 (default
    0); forcing f(s) (default 0); dmp: the DmpParameters of
    the transformation system (None: params.dmp; a learned movement's
    gains and tau while it plays). Returns (y_dot, z_dot, C_dot, E_dot);
    y_dot is the velocity V_ee^ref sent to the distributor.
    """
    dmp = params.dmp if dmp is None else dmp
    C_dot = V_ee + (params.k_hri * S_hri) * F_ext
    y_dot, z_dot = transformation_derivative(
        y + E, z, g + C, None, dmp, forcing,
        coupling_velocity=dmp.tau * C_dot)
    return y_dot, z_dot, C_dot, delta_V_ee


def admittance_filter_model(time_constant, time_step, axes=6):
    """(A, B, C, D) of the admittance's first-order lag on F_ext, the
    virtual mass of the whole body's admittance (beyond the paper):

        T_hri F_bar_dot = F_ext - F_bar,   C_dot = V_ee + k_hri F_bar S_hri

    in eq. (cdmp-wb) instead of F_ext itself. With S_hri = 1 and V_ee = 0
    the end effector then obeys M V_dot + D V = F_ext with the damping
    D = 1 / k_hri of the paper and the virtual mass M = T_hri / k_hri
    (2 kg for translation, 2 kg m^2 for rotation at T_hri = 0.1 s and the
    paper's k_hri = 0.05): the classic admittance of eq. (admit-ctrl)
    with K = 0, in velocity form. Why: the paper's M = 0 feeds the
    wrist sensor's reading straight back into the velocity command, and
    with the 100 Hz loop's tick of delay the sensor weighs the tool's
    own reaction to that command (k_hri m / h, about 3 for the 0.4 kg
    tool and a 0.2 kg hand) and a stiff grip's damping (k_hri D_hand)
    with a loop gain above one at the Nyquist rate: the command buzzes
    at 50 Hz. The lag rolls that gain off above 1 / (2 pi T_hri) (1.6
    Hz), under the hand's 2 to 8 Hz of intent; its phase is part of
    the loop that drake_wbc.analysis's admittance loop analyses.

    - time_step = 0: the continuous lag, A = -I / T, B = I / T, C = I,
      D = 0;
    - time_step = h > 0: F_bar_k = F_bar_(k-1) + (1 - a) (F_ext_k -
      F_bar_(k-1)), a = exp(-h / T): the exact zero-order-hold step of
      the lag over the period in which F_ext_k is held, taken at its end,
      so the filter adds no tick of delay (x+ = a x + (1 - a) u,
      y = a x + (1 - a) u, the state the last output).

    Args:
        time_constant: T_hri in s, > 0 (0 is no filter: its stage is
            left out).
        time_step: the control period h in s, >= 0.
        axes: the wrench's components (6: [f; tau]).

    Returns:
        (A, B, C, D): float arrays (axes, axes) each.
    """
    T = positive("time_constant", time_constant)
    h = non_negative("time_step", time_step)
    eye = np.eye(axes)
    if h == 0.0:
        return -eye / T, eye / T, eye.copy(), np.zeros((axes, axes))
    a = math.exp(-h / T)
    return a * eye, (1.0 - a) * eye, a * eye, (1.0 - a) * eye


def base_cdmp_derivative(y, z, C, g, V_b, obstacle_points, params,
                         forcing=0.0):
    """CDMP of the base, eq. (cdmp-base):

        tau z_dot = alpha_z (beta_z (g + C - y) - z) + f_avoid + f,
        tau y_dot = z + tau C_dot,    C_dot = V_b,

    f_avoid from `repulsive_force` on x and y; the yaw (third entry, if
    any) is unaffected by obstacles. The state integrates the commanded
    motion in the coordinates of T_b (as a velocity filter), where the
    obstacle points are given.

    State (y, z, C), each (3,) [x, y, yaw] (or (2,)); inputs the goal
    g, the velocity V_b = [vx, vy, wz] and the (M, 2) obstacle points in
    T_b; BaseCdmpParameters; forcing f(s) (default 0). Returns (y_dot,
    z_dot, C_dot); y_dot is the base command V_b'.
    """
    f_xy = repulsive_force(obstacle_points, params.repulsion)
    f_avoid = np.concatenate([f_xy, 0.0 * y[2:]])
    y_dot, z_dot = transformation_derivative(
        y, z, g + C, None, params.dmp, forcing, f_avoid,
        params.dmp.tau * V_b)
    return y_dot, z_dot, V_b


def arm_cdmp_derivative(y, z_tilde, C_a, g, V_a, F_ext, params, S_hri=0.0,
                        forcing=0.0):
    """CDMP of the arm, hybrid stiffness/force control, eq. (cdmp-arm):

        tau z_dot = alpha_z (beta_z (g + C_a - y) - z) + f + k_d C_s_dot,
        tau y_dot = z + C_s + tau C_a_dot,    C_s = k_p S_m F_ext,
        C_a_dot = V_a + k_f (I - S_m)(F_ext - F_d)(1 - S_hri),

    (force-term sign and the state z~ = z - (k_d / tau) C_s: module
    docstring; C_s enters tau y_dot without the factor tau of eq.
    (stiff-dmp), as printed; the same for the paper's tau = 1). Steady
    state with V_a = 0: y = g + C_a + C_s / beta_z on the stiffness
    axes; F_ext = F_d on the force axes (S_hri = 0).

    State (y, z~, C_a), each (6,) (T_a, [v; w] axes); inputs the goal
    g, the velocity V_a and the wrench F_ext on the tool, (6,);
    ArmCdmpParameters; S_hri 0 or 1 (default 0); forcing f(s)
    (default 0). Returns (y_dot, z_tilde_dot, C_a_dot); y_dot is the
    arm's velocity command.
    """
    tau = params.dmp.tau
    C_s = params.k_p * params.S_m * F_ext
    C_a_dot = V_a + (params.k_f * (1.0 - params.S_m)) * (
        F_ext - params.F_d) * (1.0 - S_hri)
    y_dot, z_tilde_dot = transformation_derivative(
        y, paper_velocity(z_tilde, C_s, params.k_d, tau), g + C_a, None,
        params.dmp, forcing, coupling_velocity=C_s + tau * C_a_dot)
    return y_dot, z_tilde_dot, C_a_dot
