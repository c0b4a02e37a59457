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
"""

from dataclasses import dataclass, field

import numpy as np

from drake_wbc.math.kernels import fast_kernel

STANDARD_GRAVITY = 9.81
"""m/s^2, along -z of T_b when the base stands level."""


def _cross(a, b):
    """a x b of 3-vectors of any scalar type (np.cross is slow for one
    pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


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
    """

    mass: float
    com_in_sensor: np.ndarray
    sensor_from_tcp: np.ndarray
    weight_map: np.ndarray = field(init=False, repr=False)
    lever_map: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        identity = np.eye(3)
        object.__setattr__(self, "weight_map", (
            -self.mass * STANDARD_GRAVITY) * np.vstack(
                [identity, _skew(self.com_in_sensor)]))
        object.__setattr__(self, "lever_map", np.block(
            [[identity, np.zeros((3, 3))],
             [_skew(self.sensor_from_tcp), identity]]))


def external_wrench(reading, R_LM, payload):
    """The wrench that the environment exerts on the tool (module
    docstring).

    Args:
        reading: (6,) [f; tau] in M, N and N m (float or AutoDiffXd).
        R_LM: (3, 3) the rotation of M in L, a frame whose z axis points
            up (the controller's T_b).
        payload: ToolPayload.

    Returns:
        (6,) F_ext = [force; torque] on the tool, at T, in L: the force
        convention of drake_wbc.math.cdmp.
    """
    weight = (-payload.mass * STANDARD_GRAVITY) * np.asarray(R_LM)[2]
    f_M = reading[:3] - weight
    tau_M = reading[3:] - _cross(payload.com_in_sensor, weight)
    lever = _cross(payload.sensor_from_tcp, f_M)
    return np.concatenate([R_LM @ f_M, R_LM @ (tau_M + lever)])


def _wrench_inputs(rng):
    """A reading (the tool's weight alone, or of any size), a rotation
    and a payload (none, or of any mass and lever)."""
    R_LM = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R_LM *= np.sign(np.linalg.det(R_LM))
    payload = ToolPayload(
        float(rng.choice([0.0, rng.uniform(0.0, 5.0)])),
        rng.uniform(-0.2, 0.2, 3),
        np.zeros(3) if rng.random() < 0.2 else rng.uniform(-0.3, 0.3, 3))
    weight = payload.weight_map.dot(R_LM[2])
    reading = (weight if rng.random() < 0.2
               else 10.0 ** rng.uniform(-2, 3) * rng.normal(size=6))
    return reading, R_LM, payload


@fast_kernel(external_wrench, sample=_wrench_inputs)
def external_wrench_float(reading, R_LM, payload):
    """`external_wrench` of a float reading, as two constant linear maps
    and a rotation (the control tick):

        [f_M; tau_M + p_TM x f_M] = lever_map (reading - weight_map
        R_LM[2, :]),   F_ext = diag(R_LM, R_LM) [...].
    """
    in_M = payload.lever_map.dot(reading
                                 - payload.weight_map.dot(R_LM[2]))
    return in_M.reshape(2, 3).dot(R_LM.T).ravel()
