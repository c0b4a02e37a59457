"""The controller's parameters: `ControllerParameters` (each value once,
handed to the stages by build_controller), the checks that its parts
agree, and loading from YAML (diagrams/controller.yaml).

`load_controller_parameters` reads a YAML file or string into
`ControllerParameters` with Drake's `yaml_load_typed`: the document's keys
are the dataclasses' fields, nested as in ControllerParameters, and a key
left out keeps its default (the paper's value), so a file may hold only
what it changes::

    time_step: 0.005
    distributor: {null_space_gain: 0.1}
    workspace: {mode: intuitive-phri}

`yaml_load_typed` builds the defaults and then assigns the fields it reads
one by one, without the dataclasses' checks; the loader
(drake_wbc.math.loading.load_typed) therefore runs every check of
the whole tree afterwards (drake_wbc.math.validation.validate), and
screens the file beforehand against what could hurt it (size, encoding,
nesting, aliases, duplicate keys). Every problem, from the YAML syntax to
a value out of range, is raised as a ValueError naming the file (if any),
the field's dotted path (e.g. `arm_cdmp.S_m`), the value and what is
allowed.
"""

import dataclasses
from dataclasses import dataclass, field, fields

import numpy as np

from drake_wbc.math import cdmp
from drake_wbc.math.arm_control import ArmControllerParameters
from drake_wbc.math.capability import (
    ArmCapabilityParameters,
    CapabilityBand,
)
from drake_wbc.math.compensation import RobustCompensatorParameters
from drake_wbc.math.distribution import MotionDistributorParameters
from drake_wbc.math.dmp import check_sampled
from drake_wbc.math.filtering import (
    BaseFilterParameters,
    check_filter_period,
)
from drake_wbc.math.loading import load_typed
from drake_wbc.math.safety import (
    SafetyParameters,
    check_within_robot,
)
from drake_wbc.math.separation import (
    check_people_coverage,
    protective_timing,
)
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import positive
from drake_wbc.math.workspace import WorkspaceAdapterParameters
from drake_wbc.math.wrench import WrenchEstimatorParameters


@dataclass
class ControllerParameters:
    """Every stage's parameters, with the paper's values as defaults.

    Attributes:
        time_step: the control period h in s (the paper runs at 100 Hz),
            one for every stage that runs at it (the DMPs, the base
            filter, the base command's limiter, the arm controller, the
            input guard); base_filter.omega_f must stay below its Nyquist
            rate pi / time_step.
        capability_band: the limitation band C_m^l < C_m < C_m^u of eq.
            (transition), one for every stage that looks at C_m: alpha
            (capability), the adaptive weighting factors of the intuitive
            pHRI mode (workspace) and the switch-off of k_n
            (distributor). None (the default): the robot's, its
            description's tuning (the paper's 0.035 and 0.04 where it
            gives none), filled in when the controller is built
            (`for_robot`).
        phri_switch: the default pHRI switch S_hri, 0 or 1, of both DMPs
            that take it (whole_body_cdmp and arm_cdmp, eqs. (cdmp-wb),
            (cdmp-arm)), while the task's phri_switch input, which drives
            them together, is not given; 0 (the paper sets 1 for pHRI).
        arm_cdmp: stiffness on every axis by default (S_m = I): force
            control drives the tool towards a surface it has not yet
            touched, so it is the task's choice (the wiping scenario sets
            the paper's S_m = diag(0, 1, 1, 1, 1, 1)), not a default.
        safety: the run-time safety (hold time of the safe stop, the
            base's velocity and acceleration limits); the arm's limits are
            in arm_controller.
        wrench: the external wrench's estimate (the tool's weight alone,
            as the paper, by default; its inertial reaction too with
            wrench.inertia_compensation).

    Each value is held once, here, and `build_controller` hands it to the
    stages that need it. Besides each part's own checks, the parts must
    agree: base_filter within the Nyquist rate of time_step; and, when
    the controller is built, arm_controller's limits within the arm's own
    (`build_controller`).

    Read from YAML by drake_wbc.controller.parameters.load_controller_parameters
    (diagrams/controller.yaml lists every field). The parameters are
    checked where they enter (here, when loaded, and when the controller
    is built) and each stage reads what it needs from them when it is
    built, so changing them afterwards has no effect on a built
    controller; after assigning fields, drake_wbc.math.validation.validate
    checks the whole tree.
    """

    time_step: float = 0.01
    capability_band: CapabilityBand | None = None
    phri_switch: float = 0.0
    capability: ArmCapabilityParameters = field(
        default_factory=ArmCapabilityParameters)
    workspace: WorkspaceAdapterParameters = field(
        default_factory=WorkspaceAdapterParameters)
    distributor: MotionDistributorParameters = field(
        default_factory=MotionDistributorParameters)
    base_cdmp: cdmp.BaseCdmpParameters = field(
        default_factory=cdmp.BaseCdmpParameters)
    base_filter: BaseFilterParameters = field(
        default_factory=BaseFilterParameters)
    compensator: RobustCompensatorParameters = field(
        default_factory=RobustCompensatorParameters)
    whole_body_cdmp: cdmp.WholeBodyCdmpParameters = field(
        default_factory=cdmp.WholeBodyCdmpParameters)
    arm_cdmp: cdmp.ArmCdmpParameters = field(
        default_factory=lambda: cdmp.ArmCdmpParameters(S_m=np.ones(6)))
    arm_controller: ArmControllerParameters = field(
        default_factory=ArmControllerParameters)
    safety: SafetyParameters = field(default_factory=SafetyParameters)
    wrench: WrenchEstimatorParameters = field(
        default_factory=WrenchEstimatorParameters)

    def __post_init__(self):
        h = positive("time_step", self.time_step)
        self.phri_switch = TASK_INPUTS["phri_switch"].check_number(
            "phri_switch", self.phri_switch)
        for item in fields(self):
            if dataclasses.is_dataclass(item.type) and not isinstance(
                    getattr(self, item.name), item.type):
                raise ValueError(
                    f"{item.name} = {getattr(self, item.name)!r} is not "
                    f"allowed: must be a {item.type.__name__}")
        if self.capability_band is not None and not isinstance(
                self.capability_band, CapabilityBand):
            raise ValueError(
                f"capability_band = {self.capability_band!r} is not "
                "allowed: must be a CapabilityBand, or None (the robot's)")
        check_filter_period(self.base_filter, h, prefix="base_filter.")
        for name in ("base_cdmp", "whole_body_cdmp", "arm_cdmp"):
            check_sampled(getattr(self, name).dmp, h, f"{name}.dmp")


def check_arm_limits(params, arm):
    """Checks that arm_controller's joint, velocity and acceleration limits
    lie within the arm's own (the model's), which they may tighten but not
    widen; the acceleration limit may not be turned off.

    Args:
        params: ArmControllerParameters.
        arm: ArmKinematics.

    Raises:
        ValueError: naming the first limit beyond the arm's.
    """
    given = (("velocity_limits", params.velocity_limits,
              arm.velocity_limits, "at most"),
             ("lower", params.lower, arm.lower, "at least"),
             ("upper", params.upper, arm.upper, "at most"))
    for name, value, own, allowed in given:
        if value is None:
            continue
        value, own = np.asarray(value, dtype=float), np.asarray(own)
        if value.shape != own.shape:
            raise ValueError(
                f"arm_controller.{name} = {list(value)} is not allowed: "
                f"must give one value for each of the arm's "
                f"{own.size} joints")
        beyond = value > own if allowed == "at most" else value < own
        if np.any(beyond):
            i = int(np.flatnonzero(beyond)[0])
            raise ValueError(
                f"arm_controller.{name}[{i}] = {float(value[i])!r} is not "
                f"allowed: must be {allowed} the arm's own "
                f"{float(own[i])!r}")
    own = float(np.min(arm.acceleration_limits))
    if not params.use_acceleration_limit:
        raise ValueError(
            "arm_controller.use_acceleration_limit = False is not allowed: "
            f"the arm's own acceleration limit ({own!r} rad/s^2) holds; "
            "tighten acceleration_limit instead")
    if params.acceleration_limit is not None and (
            params.acceleration_limit > own):
        raise ValueError(
            f"arm_controller.acceleration_limit = "
            f"{params.acceleration_limit!r} is not allowed: must be at most "
            f"the arm's own {own!r} rad/s^2")

def for_robot(params, robot):
    """The ControllerParameters the controller runs on a robot: `params`
    with the robot's own values where they give none (None), each given
    one checked to tighten the robot's own, never to widen it.

    - safety.base_velocity_limits and base_acceleration_limits: the
      base's own where None; a given one at most the base's
      (drake_wbc.math.safety.check_within_robot); safety.base_lag: the
      base's velocity_lag where None, a given one at least it.
    - capability_band, capability.joint_limit_gain and
      workspace.workspace (the local workspace of the intuitive pHRI
      mode): the robot's tuning (its description's RobotTuning, the
      paper's where it gives none) where None.
    - safety.people: its tracking must cover a walker at the base's
      speed (drake_wbc.math.separation.check_people_coverage:
      tracked_range and gate).
    - base_cdmp.repulsion.half_sizes, the footprint the repulsive field
      and the separation keep clear: the base's own where None; a given
      one at least the base's along each axis (a footprint smaller than
      the base would let its corners reach what the field keeps off).

    Args:
        params: ControllerParameters.
        robot: the robot's RobotDescription (drake_wbc.robot.description:
            its base's velocity_limits, acceleration_limits and
            footprint_half_sizes, and its tuning).

    Returns:
        A copy of `params` with no None among these fields.

    Raises:
        ValueError: naming the field, its value and the robot's own.
    """
    base, tuning = robot.base, robot.tuning
    safety, repulsion = params.safety, params.base_cdmp.repulsion
    check_within_robot(safety, velocity_limits=base.velocity_limits,
                       acceleration_limits=base.acceleration_limits,
                       velocity_lag=base.velocity_lag)
    own = tuple(float(a) for a in base.footprint_half_sizes)
    if repulsion.half_sizes is not None:
        for i, (value, limit) in enumerate(zip(repulsion.half_sizes, own,
                                               strict=True)):
            if value < limit:
                raise ValueError(
                    f"base_cdmp.repulsion.half_sizes[{i}] = {value!r} is not "
                    f"allowed: must be at least the robot's own {limit!r} m "
                    "(a footprint may grow the robot's, not shrink it)")
    velocity = safety.base_velocity_limits or tuple(
        float(v) for v in base.velocity_limits)
    acceleration = safety.base_acceleration_limits or tuple(
        float(a) for a in base.acceleration_limits)
    lag = base.velocity_lag if safety.base_lag is None else safety.base_lag
    check_people_coverage(
        safety.people, protective_timing(safety.people, params.time_step,
                                         acceleration, lag),
        max(velocity[0], velocity[1]))
    k_j = params.capability.joint_limit_gain
    return dataclasses.replace(
        params,
        capability_band=params.capability_band or tuning.capability_band,
        capability=dataclasses.replace(
            params.capability,
            joint_limit_gain=tuning.joint_limit_gain if k_j is None else k_j),
        workspace=dataclasses.replace(
            params.workspace,
            workspace=params.workspace.workspace or tuning.local_workspace),
        safety=dataclasses.replace(
            safety, base_velocity_limits=velocity,
            base_acceleration_limits=acceleration,
            base_lag=lag),
        base_cdmp=dataclasses.replace(
            params.base_cdmp, repulsion=dataclasses.replace(
                repulsion, half_sizes=repulsion.half_sizes or own)))


def load_controller_parameters(path=None, text=None):
    """ControllerParameters from a YAML file or string, validated
    (drake_wbc.math.loading.load_typed, safe against hostile files).

    Args:
        path: a YAML file (str or path-like); or
        text: YAML text. Give exactly one. An empty document (or one of
            comments only) gives the defaults.

    Returns:
        ControllerParameters.

    Raises:
        ValueError: naming the file (when loading one), the field's
            dotted path, its value and what is allowed; for an unknown
            key, the key's path and the keys allowed there.
        OSError: if the file cannot be read.
    """
    return load_typed(ControllerParameters, path=path, text=text)
