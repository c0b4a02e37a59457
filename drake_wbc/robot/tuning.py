"""The tuning that depends on the robot: the joint-limit gain k_j of P_jnt,
the capability band C_m^l < C_m < C_m^u of eq. (transition) and the local
workspace of the intuitive pHRI mode.

Both were tuned for the shipped arm (drake_wbc.math.capability,
DEFAULT_JOINT_LIMIT_GAIN): C_m = m P_jnt has the units of the arm's
manipulability (m^3 for a 6 x n Jacobian) and P_jnt = 1 - exp(-k_j
prod_i f_i) scales with 4^-n, so neither carries over to another arm.
This module says what they mean on a given arm and proposes values that
mean there what the paper's mean on ours:

- k_j so that P_jnt is MID_RANGE_PENALTY with every joint mid-range
  (f_i = 1/4): k_j = -ln(1 - MID_RANGE_PENALTY) 4^n, 1.5e4 for six
  joints (our default) and 6.0e4 for seven (where 1.5e4 caps P_jnt at
  0.60);
- the band at the fractions BAND_OVER_HOME of C_m at the arm's home: on
  our arm the paper's 0.035 to 0.04 sit at 0.54 and 0.62 of the home's
  0.065 ("close to a constraint", where one joint nears its limit or the
  elbow or wrist nears a singularity, see DEFAULT_JOINT_LIMIT_GAIN);
- the local workspace's extents d^l, d^u at the fractions
  EXTENT_OVER_HOME of the tool's horizontal extent d at the arm's home
  (`home_extent`): on our arm the paper's 0.75 and 0.8 m sit just outside
  the home's 0.736 m, so that the intuitive pHRI mode starts with the arm
  alone and hands the motion to the base as the tool reaches out; the
  deflections phi^l, phi^u are angles, the paper's on any arm.

`survey_capability` samples the arm's C_m (at home and over random
configurations within its limits); `singular` tells a home where no
band can be proposed; `check_tuning` says, as sentences,
what is wrong with a band, a k_j and a local workspace on an arm (empty
when nothing is), which build_controller warns with and `drake-wbc demo
--robot FILE` prints beside the proposal.
"""

import math
from typing import NamedTuple

import numpy as np

from drake_wbc.math import capability
from drake_wbc.math.arm_control import DEFAULT_DAMPING_THRESHOLD
from drake_wbc.math.capability import CapabilityBand
from drake_wbc.math.joint_range import configuration_range
from drake_wbc.math.validation import positive, whole_number
from drake_wbc.math.workspace import LocalWorkspace, deflection, extent

MID_RANGE_PENALTY = 1.0 - math.exp(-capability.DEFAULT_JOINT_LIMIT_GAIN
                                   / 4.0 ** 6)
"""P_jnt with every joint mid-range under the default k_j on six joints
(0.974): what the proposed k_j gives on any arm."""

BAND_OVER_HOME = (0.035 / 0.0649, 0.04 / 0.0649)
"""The paper's band over C_m at the shipped arm's home (0.0649): (0.54,
0.62), the fractions of an arm's home C_m where the proposed band sits."""


SHIPPED_HOME_EXTENT = 0.7358
"""m: the horizontal extent d of the shipped arm's tool centre point at
its home, from the arm base's axis (drake_wbc.math.workspace.extent)."""

EXTENT_OVER_HOME = (LocalWorkspace.extent_lower / SHIPPED_HOME_EXTENT,
                    LocalWorkspace.extent_upper / SHIPPED_HOME_EXTENT)
"""The paper's d^l = 0.75 and d^u = 0.8 m over the shipped arm's home
extent: (1.019, 1.087), the fractions of an arm's home extent where the
proposed local workspace sits."""


class RobotTuningWarning(UserWarning):
    """A tuning (band, k_j) that does not suit the robot's arm."""


def proposed_joint_limit_gain(num_joints):
    """k_j that gives P_jnt = MID_RANGE_PENALTY with every one of the
    `num_joints` joints mid-range: -ln(1 - MID_RANGE_PENALTY) 4^n."""
    n = whole_number("num_joints", num_joints, 1)
    return -math.log(1.0 - MID_RANGE_PENALTY) * 4.0 ** n


def mid_range_penalty(k_j, num_joints):
    """P_jnt with every joint mid-range: 1 - exp(-k_j 4^-n)."""
    return 1.0 - math.exp(-positive("k_j", k_j) / 4.0 ** num_joints)


class CapabilitySurvey(NamedTuple):
    """The arm's C_m, at home and over random configurations.

    Attributes:
        k_j: the joint-limit gain it was computed with.
        home: C_m at the arm's home.
        samples: C_m at uniformly random configurations within the joint
            limits, sorted.
    """

    k_j: float
    home: float
    samples: np.ndarray

    def fraction_below(self, value):
        """The fraction of the samples with C_m below `value`."""
        return float(np.searchsorted(self.samples, value) / self.samples.size)

    def proposed_band(self):
        """The CapabilityBand at BAND_OVER_HOME of the home's C_m."""
        return CapabilityBand(BAND_OVER_HOME[0] * self.home,
                              BAND_OVER_HOME[1] * self.home)


def capability_at(arm, q, k_j):
    """C_m of `arm` (ArmKinematics) at joints `q` with gain `k_j`."""
    return capability.capability(arm.evaluate(q).J_a, q, arm.lower,
                                  arm.upper, k_j)


def survey_capability(arm, k_j=None, count=2000, seed=0):
    """C_m of `arm` (an ArmKinematics) at home and at `count` random
    configurations within its limits (numpy Generator `seed`; a
    continuous joint's within one turn,
    drake_wbc.math.joint_range.configuration_range), with gain `k_j` (the
    proposed one for the arm if None)."""
    k_j = (proposed_joint_limit_gain(arm.num_joints) if k_j is None
           else positive("k_j", k_j))
    rng = np.random.default_rng(seed)
    lower, upper = configuration_range(arm.lower, arm.upper)
    samples = np.sort([capability_at(arm, rng.uniform(lower, upper), k_j)
                       for _ in range(whole_number("count", count, 1))])
    return CapabilitySurvey(k_j, capability_at(arm, arm.home, k_j), samples)


def smallest_singular_value(arm, q=None):
    """s_min of `arm`'s (ArmKinematics) Jacobian J_a at joints `q` (its
    home if None): 0 where it has lost a rank (a stretched or folded
    arm)."""
    q = arm.home if q is None else q
    return float(np.linalg.svd(arm.evaluate(q).J_a, compute_uv=False)[-1])


def singular(arm, q=None, threshold=DEFAULT_DAMPING_THRESHOLD):
    """Whether `arm` (ArmKinematics) is at or near a singularity at
    joints `q` (its home if None): s_min of J_a below `threshold`, where
    the arm's damped least squares gives way (the arm controller's
    damping_threshold, drake_wbc.math.arm_control.damping_rule; C_m is
    small or 0 there). Its tool cannot follow every direction there,
    and at such a home no band can sit at fractions of the home's C_m."""
    return smallest_singular_value(arm, q) < positive("threshold",
                                                      threshold)


def home_extent(arm):
    """d: the horizontal extent of `arm`'s (ArmKinematics) tool centre
    point from the arm base's axis at its home, m."""
    return float(extent(arm.evaluate(arm.home).pose[:3, 3]))


def proposed_local_workspace(arm):
    """The LocalWorkspace with d^l, d^u at EXTENT_OVER_HOME of `arm`'s
    home extent and the paper's deflections: on the shipped arm the
    paper's own, to the rounding of SHIPPED_HOME_EXTENT."""
    d = home_extent(arm)
    return LocalWorkspace(extent_lower=EXTENT_OVER_HOME[0] * d,
                          extent_upper=EXTENT_OVER_HOME[1] * d)


def check_tuning(arm, band, k_j, local_workspace=None, start=None,
                 damping_threshold=DEFAULT_DAMPING_THRESHOLD):
    """What is wrong with the capability `band` (CapabilityBand), the
    joint-limit gain `k_j` and, if given, the `local_workspace`
    (LocalWorkspace, of the intuitive pHRI mode) on `arm` (ArmKinematics),
    as sentences that say what to change; empty when nothing is. Cheap
    (one evaluation at home): it checks that P_jnt can come near 1, that
    the arm's home is not at or near a singularity (`singular`), that
    the band is not active there (alpha > 0) and that the tool there is
    inside d^l and phi^l (else the base moves from the start). Where it
    proposes another k_j, it checks the band, and proposes one, at that
    k_j (the band `drake-wbc demo` proposes beside it), and says so.

    Args:
        arm, band, k_j, local_workspace: as above.
        start: None, or the arm's joint positions where a run starts (a
            scenario's station.initial_arm_positions, other than the
            home): the home's checks at that start instead, said of it,
            their proposals at the start's own C_m and extent (and not
            k_j's, which no place changes).
        damping_threshold: the arm controller's threshold on s_min of
            J_a (`singular`).
    """
    problems = []
    n = arm.num_joints
    best = mid_range_penalty(k_j, n)
    at_k_j = ""
    if best < 0.9 and start is None:
        problems.append(
            f"capability.joint_limit_gain = {k_j!r} caps P_jnt at "
            f"{best:.2f} on this arm's {n} joints (even with every joint "
            f"mid-range): give about {proposed_joint_limit_gain(n):.3g} "
            "(in the controller's parameters, or for every controller of "
            "this robot in its description's tuning)")
        # The band means something at the k_j the arm is to have.
        k_j = proposed_joint_limit_gain(n)
        at_k_j = f" with the proposed k_j = {k_j:.3g}"
    at_home = start is None
    q = np.asarray(arm.home if at_home else start, dtype=float)
    if at_home:
        name, place = "arm.home", "the robot's home"
        bend = "give a home with the elbow and the wrist bent in the " \
               "robot's description"
        change = "give {what} {side} it, e.g. "
    else:
        name = "station.initial_arm_positions"
        place = f"the start ({name})"
        bend = "start with the elbow and the wrist bent"
        change = "start nearer the home, or give {what} {side} it, e.g. "
    value = capability_at(arm, q, k_j)
    s_min = smallest_singular_value(arm, q)
    if singular(arm, q, damping_threshold):
        problems.append(
            f"{name} = {q.tolist()} is at or near a singularity (the "
            f"smallest singular value of J_a is {s_min:.3g}, below the "
            f"arm controller's damping threshold {damping_threshold:g}, "
            f"where its damped least squares gives way; C_m = "
            f"{value:.3g}{at_k_j}): the tool cannot follow every direction "
            "there"
            + (", and no capability band can be proposed at fractions of "
               "the home's C_m" if at_home else "") + f"; {bend}")
    elif value <= band.upper:
        problems.append(
            f"capability_band = ({band.lower!r}, {band.upper!r}) is active "
            f"at {place}, where C_m = {value:.4g}{at_k_j}: the "
            "compensation would give way and k_n switch off from the "
            "start; " + change.format(what="a band", side="below")
            + f"({BAND_OVER_HOME[0] * value:.3g}, "
            f"{BAND_OVER_HOME[1] * value:.3g}) in the controller's "
            "parameters or the robot description's tuning (drake-wbc "
            "demo --robot FILE surveys the arm)")
    if local_workspace is not None:
        p = arm.evaluate(q).pose[:3, 3]
        d = float(extent(p))
        if d >= local_workspace.extent_lower:
            problems.append(
                f"workspace.workspace.extent_lower = "
                f"{local_workspace.extent_lower!r} m is within the tool's "
                f"extent at {place}, d = {d:.4g} m: in the intuitive pHRI "
                "mode the base would take the motion from the start; "
                + change.format(what="extents", side="beyond")
                + f"({EXTENT_OVER_HOME[0] * d:.3g}, "
                f"{EXTENT_OVER_HOME[1] * d:.3g}) in the controller's "
                "parameters or the robot description's tuning "
                "(local_workspace)")
        phi = float(deflection(p))
        if phi >= local_workspace.deflection_lower:
            problems.append(
                f"workspace.workspace.deflection_lower = "
                f"{math.degrees(local_workspace.deflection_lower):.4g} deg "
                f"is within the tool's deflection at {place}, phi = "
                f"{math.degrees(phi):.4g} deg from the x axis of T_a "
                f"(arm.base_frame = {arm.model.description.arm.base_frame!r}"
                "): in the intuitive pHRI mode the base would take the "
                "motion from the start; "
                + ("" if at_home else "start nearer the home, or ")
                + "give as arm.base_frame a frame on the base whose x axis "
                "points towards the tool at the robot's home (the local "
                "workspace is the sector about that axis)")
    return problems
