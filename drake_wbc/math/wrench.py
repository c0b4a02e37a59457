"""The external wrench F_ext on the tool from the wrist sensor's reading,
the input of the coupled DMPs (eqs. (stiff-dmp), (admit-dmp), (cdmp-wb),
(cdmp-arm)).

The sensor reads the wrench [f; tau] that the tool exerts on it, at and
in its measurement frame M: the tool's weight plus every external wrench
on the tool. Removing the weight (payload compensation) and moving the
result to the tool centre point T, expressed in a frame L whose z axis
points up (gravity along -z of L):

    w = R_LM^T [0, 0, -m g] = -m g R_LM[2, :]               (in M),
    f_M = f - w,   tau_M = tau - p_com x w,
    F_ext = [R_LM f_M;  R_LM (tau_M + p_TM x f_M)],

p_com the tool's centre of mass and p_TM the position of M from T, both
in M (r_TM = R_LM p_TM in L). The controller's L is T_b, level on the
floor in the nominal kinematics (R_LM = ^bR_a R_AM): the frame in which
the whole-body CDMP takes F_ext (eq. (cdmp-wb), with V_ee in T_b), and
where the weight's direction is known whatever the arm's mount; the arm's
CDMP takes it in T_a (eq. (cdmp-arm), with V_a), R_ba^T F_ext
(drake_wbc.stages.wrench). `external_wrench` is the reference body
(float or AutoDiffXd readings); its float kernel runs the same formula
as two constant linear maps and a rotation (`ToolPayload.weight_map`,
`ToolPayload.lever_map`), the control tick's arithmetic.

The tool's own inertia. When the tool accelerates, the sensor
also reads its inertial reaction: Newton-Euler for the tool, with a its
centre of mass's acceleration and dH the rate of its angular momentum
about that centre (both in L), gives

    F_ext = reading - [w_a; p_com x w_a] + [0; R_LM^T dH]   (at M, in M),
    w_a = R_LM^T m (g_L - a),    g_L = [0, 0, -g],

the weight w replaced by the weight in the tool's accelerating frame
(g_L - a) and the tool's spin added to the torque, then moved to T as
above; `motion` = [a; dH] of `external_wrench`, None for a tool at rest.
`tool_motion` is [a; dH] from three consecutive poses of the sensor,
central differences (second order in the sample period, no phase: they
stand for the middle sample). A wrist sensor in a velocity loop of
gain k_hri sees this reaction to the loop's own command; uncompensated,
k_hri m times the tool's acceleration at the loop's Nyquist rate closes
a loop of gain above one (the 50 Hz limit cycle of the paper's pure
admittance in pHRI; the whole body's admittance lag,
math.cdmp.admittance_filter_model, rolls that loop off instead).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from drake_wbc.math.compiled import compiled
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.scalar_support import cross, value_of
from drake_wbc.math.validation import boolean, whole_number

STANDARD_GRAVITY = 9.81
"""m/s^2, along -z of T_b when the base stands level."""


def _skew(p):
    """S(p) with S(p) v = p x v."""
    return np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]],
                     [-p[1], p[0], 0.0]])


@dataclass(frozen=True, eq=False)
class ToolPayload:
    """The tool beyond the measuring plane, and where F_ext is wanted.

    Attributes:
        mass: the tool's mass m, kg.
        com_in_sensor: (3,) its centre of mass p_com in M, m.
        sensor_from_tcp: (3,) p_TM, the position of M from the tool
            centre point T, in M, m (constant when the tool is welded to
            the sensor).
        weight_map: (6, 3) [w; p_com x w] = weight_map R_LM[2, :]
            (derived).
        lever_map: (6, 6) [f_M; tau_M + p_TM x f_M] = lever_map [f_M;
            tau_M] (derived).
        moment_map: (6, 3) [w; p_com x w] = moment_map w (derived).
        inertia: (3, 3) the tool's rotational inertia about its centre of
            mass, in M's axes, kg m^2 (zero if not given; only `tool_motion`
            reads it).
    """

    mass: float
    com_in_sensor: np.ndarray
    sensor_from_tcp: np.ndarray
    inertia: np.ndarray = None
    weight_map: np.ndarray = field(init=False, repr=False)
    lever_map: np.ndarray = field(init=False, repr=False)
    moment_map: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        identity = np.eye(3)
        if self.inertia is None:
            object.__setattr__(self, "inertia", np.zeros((3, 3)))
        object.__setattr__(self, "moment_map", np.vstack(
            [identity, _skew(self.com_in_sensor)]))
        object.__setattr__(self, "weight_map", (
            -self.mass * STANDARD_GRAVITY) * np.vstack(
                [identity, _skew(self.com_in_sensor)]))
        object.__setattr__(self, "lever_map", np.block(
            [[identity, np.zeros((3, 3))],
             [_skew(self.sensor_from_tcp), identity]]))


def external_wrench(reading, R_LM, payload, motion=None):
    """The wrench that the environment exerts on the tool (module
    docstring).

    Args:
        reading: (6,) [f; tau] in M, N and N m (float or AutoDiffXd).
        R_LM: (3, 3) the rotation of M in L, a frame whose z axis points
            up (the controller's T_b).
        payload: ToolPayload.
        motion: (6,) [a; dH], the tool's centre-of-mass acceleration
            (m/s^2) and rate of angular momentum about it (N m), both in L
            (`tool_motion`), or None for a tool at rest.

    Returns:
        (6,) F_ext = [force; torque] on the tool, at T, in L: the force
        convention of drake_wbc.math.cdmp; all NaN if an entry of
        reading, R_LM or motion is not finite (the lever and the rotation
        mix the wrench's parts, so no part of it is known).
    """
    R_LM = np.asarray(R_LM)
    finite = all(np.isfinite(value_of(x)).all() for x in (
        reading, R_LM, () if motion is None else motion))
    if motion is None:
        weight = (-payload.mass * STANDARD_GRAVITY) * R_LM[2]
        spin = 0.0
    else:
        weight = R_LM.T @ (payload.mass * (np.array(
            [0.0, 0.0, -STANDARD_GRAVITY]) - motion[:3]))
        spin = R_LM.T @ motion[3:]
    f_M = reading[:3] - weight
    tau_M = reading[3:] - cross(payload.com_in_sensor, weight) + spin
    lever = cross(payload.sensor_from_tcp, f_M)
    F_ext = np.concatenate([R_LM @ f_M, R_LM @ (tau_M + lever)])
    return F_ext if finite else F_ext * math.nan


def _vee_of_rotation(R):
    """The rotation vector of a small rotation R (3, 3): vee of its skew
    part, sin(theta) times the axis (relative error theta^2 / 6, 4e-5 at
    the arm's 1.57 rad/s over 10 ms)."""
    return 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0],
                           R[1, 0] - R[0, 1]])


def tool_motion(rotations, positions, payload, h):
    """[a; dH] of the tool at the middle of three samples h apart, by
    central differences (module docstring), for any scalar type.

    Args:
        rotations: (3, 3, 3) R_LM at t - h, t, t + h.
        positions: (3, 3) the tool's centre of mass in L at those times, m.
        payload: ToolPayload (its inertia about the centre of mass, in M).
        h: the sample period, s.

    Returns:
        (6,) [a (m/s^2); dH = I w_dot + w x I w (N m)] at t, in L, I the
        inertia in L's axes at t.
    """
    R0, R1, R2 = rotations
    p0, p1, p2 = positions
    a = (p2 - 2.0 * p1 + p0) / (h * h)
    w_after = _vee_of_rotation(R2 @ R1.T) / h
    w_before = _vee_of_rotation(R1 @ R0.T) / h
    w, w_dot = 0.5 * (w_after + w_before), (w_after - w_before) / h
    inertia = R1 @ payload.inertia @ R1.T
    return np.concatenate([a, inertia @ w_dot + cross(w, inertia @ w)])


def _wrench_inputs(rng):
    """A reading (the tool's weight alone, or of any size), a rotation
    and a payload (none, or of any mass and lever); in one case in ten an
    entry of the reading, the rotation or the motion NaN or infinite."""
    R_LM = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R_LM *= np.sign(np.linalg.det(R_LM))
    payload = ToolPayload(
        float(rng.choice([0.0, rng.uniform(0.0, 5.0)])),
        rng.uniform(-0.2, 0.2, 3),
        np.zeros(3) if rng.random() < 0.2 else rng.uniform(-0.3, 0.3, 3))
    weight = payload.weight_map.dot(R_LM[2])
    reading = (weight if rng.random() < 0.2
               else 10.0 ** rng.uniform(-2, 3) * rng.normal(size=6))
    motion = (None if rng.random() < 0.4
              else 10.0 ** rng.uniform(-2, 2) * rng.normal(size=6))
    if rng.random() < 0.1:
        value = rng.choice([np.nan, np.inf, -np.inf])
        spoilt = [reading, R_LM] + ([] if motion is None else [motion])
        spoilt = spoilt[rng.integers(len(spoilt))]
        spoilt[np.unravel_index(rng.integers(spoilt.size),
                                spoilt.shape)] = value
    return reading, R_LM, payload, motion


@compiled
def _external_wrench(reading, R_LM, mass, weight_map, moment_map, lever_map,
                     moving, motion):
    """The compiled body of `external_wrench_float` (`motion` read only
    when `moving`); all NaN if an entry of reading, R_LM or motion is not
    finite, as the reference."""
    finite = True
    for r in range(6):
        finite = finite and math.isfinite(reading[r])
        if moving:
            finite = finite and math.isfinite(motion[r])
    for r in range(3):
        for c in range(3):
            finite = finite and math.isfinite(R_LM[r, c])
    relieved = np.empty(6)
    if not moving:
        for r in range(6):
            relieved[r] = reading[r] - (weight_map[r, 0] * R_LM[2, 0]
                                        + weight_map[r, 1] * R_LM[2, 1]
                                        + weight_map[r, 2] * R_LM[2, 2])
    else:
        load = np.empty(3)
        load[0] = mass * (0.0 - motion[0])
        load[1] = mass * (0.0 - motion[1])
        load[2] = mass * (-STANDARD_GRAVITY - motion[2])
        w_a = np.empty(3)
        spin = np.empty(3)
        for c in range(3):
            w_a[c] = (R_LM[0, c] * load[0] + R_LM[1, c] * load[1]
                      + R_LM[2, c] * load[2])
            spin[c] = (R_LM[0, c] * motion[3] + R_LM[1, c] * motion[4]
                       + R_LM[2, c] * motion[5])
        for r in range(6):
            relieved[r] = reading[r] - (moment_map[r, 0] * w_a[0]
                                        + moment_map[r, 1] * w_a[1]
                                        + moment_map[r, 2] * w_a[2])
        for r in range(3):
            relieved[3 + r] += spin[r]
    in_M = np.empty(6)
    for r in range(6):
        total = 0.0
        for c in range(6):
            total += lever_map[r, c] * relieved[c]
        in_M[r] = total
    result = np.empty(6)
    for half in range(2):
        for r in range(3):
            result[3 * half + r] = (in_M[3 * half] * R_LM[r, 0]
                                    + in_M[3 * half + 1] * R_LM[r, 1]
                                    + in_M[3 * half + 2] * R_LM[r, 2])
    if not finite:
        result[:] = math.nan
    return result


_NO_MOTION = np.zeros(6)


@fast_kernel(external_wrench, sample=_wrench_inputs)
def external_wrench_float(reading, R_LM, payload, motion=None):
    """`external_wrench` of a float reading in machine code
    (drake_wbc.math.compiled), as two constant linear maps and a rotation
    (the control tick):

        [f_M; tau_M + p_TM x f_M] = lever_map (reading - weight_map
        R_LM[2, :]),   F_ext = diag(R_LM, R_LM) [...],

    with a moving tool weight_map R_LM[2, :] replaced by moment_map w_a
    and R_LM^T dH added to the torque.
    """
    moving = motion is not None
    return _external_wrench(
        np.ascontiguousarray(reading, dtype=float),
        np.ascontiguousarray(R_LM, dtype=float), float(payload.mass),
        payload.weight_map, payload.moment_map, payload.lever_map, moving,
        np.ascontiguousarray(motion, dtype=float) if moving else _NO_MOTION)


@dataclass
class WrenchEstimatorParameters:
    """Parameters of ExternalWrenchEstimator (drake_wbc.stages.wrench).

    Attributes:
        inertia_compensation: also remove the tool's inertial reaction
            (module docstring), its motion from the measured arm
            positions: the sensor's poses at three consecutive control
            ticks through the nominal kinematics, central differences
            centred on the reading's time. False (the default): the
            weight alone, as the paper.
        sensor_delay: control ticks by which the wrench reading the
            controller receives is older than the arm position it
            receives with it, 1 or 2: the central difference is centred
            on the reading's own time, so the compensation has no phase
            error, and F_ext is that much older (1 in the simulated
            station, measured: the FT-300's sample of tick k - 1 arrives
            with the joints of tick k).
    """

    inertia_compensation: bool = False
    sensor_delay: int = 1

    def __post_init__(self):
        self.inertia_compensation = boolean("inertia_compensation",
                                            self.inertia_compensation)
        delay = whole_number("sensor_delay", self.sensor_delay, minimum=1)
        if delay > 2:
            raise ValueError(f"sensor_delay = {delay!r} is not allowed: "
                             "must be 1 or 2 control ticks")
        self.sensor_delay = delay
