"""The station's simulated wrist force/torque sensor (Robotiq FT-300).

The true wrench comes from the plant: the tool hangs on the weld
`ft300_sensing` at the sensor's measurement frame (drake_wbc.robot.model),
and `WeldWrench` turns that weld's reaction into the wrench [f; tau] the
tool exerts on the sensor. `measure` models what the sensor makes of it
(noise, saturation, quantisation), and `WristForceTorqueSensor` samples it
at the sensor's rate, like the real one. Sampling at t = 0 follows the
same rules as the LIDAR's (see drake_wbc.station.lidar). The station's
plant has unsampled output ports (`use_sampled_output_ports` False), so
its reaction forces are those of the context's state from the start: the
reading stored at `Simulator.Initialize()` already holds the initial
state's forces (the tool's weight at rest). On a plant with sampled
outputs (Drake's default; checked on drake 1.51.1) they are zero until
its first step, which Drake runs in an unrestricted update before the
discrete updates due at the same time: there the reading taken at
Initialize is zero, and the one taken at t = 0 holds the initial forces.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce_
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import LeafSystem, LeafSystem_

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    non_negative,
    positive,
    whole_number,
)
from drake_wbc.robot.description import shipped_robot
from drake_wbc.stages.support import define_stage
from drake_wbc.station.sampling import SampledReading

WRENCH_SIZE = 6
"""[fx, fy, fz, tx, ty, tz]: force first, N, then torque, N m."""


@dataclass
class ForceTorqueSensorParameters:
    """Parameters of the wrist F/T sensor; the defaults are the FT-300's,
    its range the robot's own.

    Attributes:
        rate: readings a second, Hz, > 0 (100).
        force_noise_std: N, >= 0, of a Gaussian error on each force
            component (0.1: the data sheet's RMS bound, taken as the RMS).
        torque_noise_std: N m, >= 0, the same for torques (0.005).
        force_resolution: N, >= 0 and below force_range; forces are
            rounded to the nearest multiple (0.01); 0: no quantisation.
        torque_resolution: N m, >= 0 and below torque_range, the same
            for torques (0.001).
        force_range: N, > 0; each force component saturates at +-range;
            None (the default): the robot's own sensor's range, its
            description's tool.ft_sensor_range (300 on the shipped
            robot).
        torque_range: N m, > 0 or None, the same for torques (30 on the
            shipped robot).
        seed: a whole number >= 0. The noise of reading k is drawn from
            np.random.default_rng([seed, k]): it never depends on what was
            computed before.
    """

    rate: float = 100.0
    force_noise_std: float = 0.1
    torque_noise_std: float = 0.005
    force_resolution: float = 0.01
    torque_resolution: float = 0.001
    force_range: float | None = None
    torque_range: float | None = None
    seed: int = 0

    def __post_init__(self):
        self.rate = positive("rate", self.rate)
        for name in ("force_noise_std", "torque_noise_std",
                     "force_resolution", "torque_resolution"):
            setattr(self, name, non_negative(name, getattr(self, name)))
        for kind in ("force", "torque"):
            name = f"{kind}_range"
            if getattr(self, name) is None:
                continue
            setattr(self, name, positive(name, getattr(self, name)))
            resolution = getattr(self, f"{kind}_resolution")
            limit = getattr(self, name)
            if resolution >= limit:
                raise ValueError(
                    f"{kind}_resolution = {resolution!r} is not allowed with "
                    f"{kind}_range = {limit!r}: must be below the range (a "
                    "step as large as the range rounds every reading within "
                    "it to 0 or the range itself)")
        self.seed = whole_number("seed", self.seed)

    @classmethod
    def ideal(cls, **overrides):
        """An ideal sensor for tests: no noise, no quantisation (the rate
        stays the FT-300's and the ranges the robot's unless
        overridden)."""
        fields = dict(force_noise_std=0.0, torque_noise_std=0.0,
                      force_resolution=0.0, torque_resolution=0.0)
        fields.update(overrides)
        return cls(**fields)


def _per_axis(force_value, torque_value):
    """(6,) the force value thrice, then the torque value thrice."""
    return np.repeat([float(force_value), float(torque_value)], 3)


def sensor_limits(params, sensor_range=None):
    """(6,) the saturation of each component of a reading: the robot's own
    sensor's range `sensor_range` ((6,) > 0, its description's
    tool.ft_sensor_range; the shipped robot's if None), where `params`
    gives no force_range or torque_range of its own.

    Raises:
        ValueError: naming sensor_range, or a resolution of `params` not
            below the range it is taken with.
    """
    own = shipped_robot().tool.ft_sensor_range if sensor_range is None \
        else sensor_range
    limits = as_vector("sensor_range", own, WRENCH_SIZE).copy()
    for i, value in enumerate(limits):
        positive(f"sensor_range[{i}]", value)
    for part, kind in ((slice(0, 3), "force"), (slice(3, 6), "torque")):
        given = getattr(params, f"{kind}_range")
        if given is not None:
            limits[part] = given
        resolution = getattr(params, f"{kind}_resolution")
        if resolution >= limits[part].min():
            raise ValueError(
                f"{kind}_resolution = {resolution!r} is not allowed with "
                f"the sensor's {kind} range {float(limits[part].min())!r}: "
                "must be below it (a step as large as the range rounds every "
                "reading within it to 0 or the range itself)")
    return limits


def measure(wrench, params, tick, sensor_range=None):
    """What the sensor reads for a true wrench.

    Gaussian noise first, then saturation at +-range, then rounding to the
    nearest multiple of the resolution (where it is > 0), per component.

    Args:
        wrench: (6,) the true [f; tau], N and N m.
        params: ForceTorqueSensorParameters (FT-300 defaults if None).
        tick: the reading's index, a whole number >= 0; with `params.seed`
            it fixes the noise.
        sensor_range: (6,) the robot's own sensor's range (`sensor_limits`;
            the shipped robot's if None).

    Returns:
        (6,) the reading [f; tau].
    """
    params = checked_instance("params", params, ForceTorqueSensorParameters,
                              ForceTorqueSensorParameters)
    reading = as_vector("wrench", wrench, WRENCH_SIZE)
    tick = whole_number("tick", tick)
    return _Measurement(params, sensor_limits(params, sensor_range))(
        reading, tick)


class _Measurement:
    """`measure` for fixed parameters, checked once: the per-axis arrays
    are built here, and a call takes a (6,) float wrench and a whole
    number tick as they are.

    A call works in place on one new array: the noise (drawn as
    `measure` draws it), the saturation, then the rounding with np.rint,
    which is what np.round does for zero decimals (half to even), so the
    readings are `measure`'s, bit for bit.
    """

    def __init__(self, params, limit):
        self.seed = params.seed
        self.std = _per_axis(params.force_noise_std, params.torque_noise_std)
        self.noisy = bool(np.any(self.std > 0.0))
        self.limit = limit
        self.negative_limit = -self.limit
        resolution = _per_axis(params.force_resolution,
                               params.torque_resolution)
        self.quantised = resolution > 0.0
        self.all_quantised = bool(np.all(self.quantised))
        self.any_quantised = bool(np.any(self.quantised))
        self.step = np.where(self.quantised, resolution, 1.0)

    def __call__(self, reading, tick):
        if self.noisy:
            rng = np.random.default_rng([self.seed, int(tick)])
            noise = rng.standard_normal(WRENCH_SIZE)
            noise *= self.std
            reading = np.add(reading, noise, out=noise)
        else:
            reading = np.array(reading, dtype=float)
        np.maximum(reading, self.negative_limit, out=reading)
        np.minimum(reading, self.limit, out=reading)
        if not self.any_quantised:
            return reading
        rounded = np.divide(reading, self.step)
        np.rint(rounded, out=rounded)
        rounded *= self.step
        if self.all_quantised:
            return rounded
        return np.where(self.quantised, rounded, reading)


class WristForceTorqueSensor(SampledReading, LeafSystem):
    """The wrist F/T sensor, sampled.

    ::

                     ┌────────────────────────┐
            wrench ─►│ WristForceTorqueSensor ├──► wrench_measured
                     └────────────────────────┘

    - wrench: (6) the true [f; tau] the tool exerts on the sensor, at and
      in its measurement frame (e.g. from `WeldWrench`).
    - wrench_measured: (6) the last reading (`measure`), the station's
      `wrist.wrench_measured`.

    A plain double `LeafSystem`. A periodic discrete update at 1 / rate,
    offset 0, stores the reading and a reading counter (the noise's
    tick); the output comes from that state alone, so it holds between
    readings, with no direct feedthrough (the plant, the controller and
    the sensor form a loop). The default reading is zero, counter 0. An
    initialization event (see the module notes) and `initialize_reading`
    store the reading of the current input without advancing the
    counter: the update at t = 0 then stores it again (with the reading
    of the plant's first step, for a discrete plant).

    Args:
        params: ForceTorqueSensorParameters (FT-300 defaults if None).
        sensor_range: (6,) the robot's own sensor's range, its
            description's tool.ft_sensor_range (the shipped robot's if
            None), where `params` gives none (`sensor_limits`).
    """

    def __init__(self, params=None, sensor_range=None):
        super().__init__()
        self.params = checked_instance("params", params,
                                       ForceTorqueSensorParameters,
                                       ForceTorqueSensorParameters)
        self.limits = sensor_limits(self.params, sensor_range)
        self._measure = _Measurement(self.params, self.limits)
        self._wrench = self.DeclareVectorInputPort("wrench", WRENCH_SIZE)
        reading = self._declare_sampling(np.zeros(WRENCH_SIZE),
                                         self.params.rate)
        self.DeclareVectorOutputPort(
            "wrench_measured", WRENCH_SIZE,
            lambda context, output: output.SetFromVector(
                self._stored_reading(context)),
            prerequisites_of_calc=reading)

    def _read(self, context, tick):
        return self._measure(self._wrench.Eval(context), tick)


@define_stage("WeldWrench_")
def WeldWrench_(T):
    class Impl(LeafSystem_[T]):
        """The true sensor wrench from the reaction forces of a weld.

        ::

                                  ┌────────────┐
                reaction_forces ─►│ WeldWrench ├──► wrench
                                  └────────────┘

        - reaction_forces: abstract, the list of SpatialForce that
          `plant.get_reaction_forces_output_port()` gives, indexed by
          int(joint.index()); each is the force on the joint's child body
          at the joint's child frame, expressed in that frame.
        - wrench: (6) -[f; tau] of the weld's reaction: the wrench the
          child (the tool) exerts on the parent (the sensor), at and in
          `frame` (the weld's child frame if None; the measurement frame
          is that frame for `ft300_sensing`).

        Scalar-generic (double and AutoDiffXd, so that a plant's reading
        can be linearised, drake_wbc.analysis.admittance_loop).

        Args:
            plant: the MultibodyPlant (double) holding the weld.
            weld_joint: the weld, e.g. plant.GetJointByName(
                "ft300_sensing", model.tool).
            frame: the sensor's measurement frame (RobotModel.
                ft_measurement_frame), on a body welded to the weld's
                child; None: the weld's child frame.
        """

        def _construct(self, plant, weld_joint, frame=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not isinstance(plant, MultibodyPlant):
                raise ValueError(f"plant = {plant!r} is not allowed: must be "
                                 "a MultibodyPlant (double)")
            index = getattr(weld_joint, "index", None)
            if (index is None or int(index()) >= plant.num_joints()
                    or plant.get_joint(index()) is not weld_joint):
                raise ValueError(f"weld_joint = {weld_joint!r} is not "
                                 "allowed: must be a joint of plant")
            if weld_joint.num_velocities() != 0:
                raise ValueError(
                    f"weld_joint = {weld_joint!r} is not allowed: must be a "
                    f"weld (it has {weld_joint.num_velocities()} velocities)")
            self._declare(int(index()), _to_frame(plant, weld_joint, frame))

        def _construct_copy(self, other, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._declare(other.joint_index, other.to_frame)

        def _declare(self, joint_index, to_frame):
            self.joint_index = joint_index
            self.to_frame = to_frame
            self._reactions = self.DeclareAbstractInputPort(
                "reaction_forces",
                AbstractValue.Make([SpatialForce_[T](np.zeros(3),
                                                     np.zeros(3))]))
            self.DeclareVectorOutputPort("wrench", WRENCH_SIZE, self._output)

        def _output(self, context, output):
            reactions = self._reactions.Eval(context)
            if len(reactions) <= self.joint_index:
                raise ValueError(
                    f"reaction_forces has {len(reactions)} entries, which is "
                    "not allowed: must have one per joint of the plant (the "
                    f"weld's index is {self.joint_index})")
            reaction = reactions[self.joint_index]
            wrench = -np.concatenate(
                [reaction.translational(), reaction.rotational()])
            output.SetFromVector(wrench if self.to_frame is None
                                 else self.to_frame @ wrench)

    return Impl


def _to_frame(plant, weld_joint, frame):
    """(6, 6) the map of a wrench [f; tau] at and in the weld's child
    frame J to the same wrench at and in `frame` M: f_M = R_MJ f_J,
    tau_M = R_MJ (tau_J - p_JM x f_J); None where M is J (to rounding)
    or `frame` is None."""
    if frame is None:
        return None
    if (not isinstance(frame, Frame)
            or int(frame.index()) >= plant.num_frames()
            or plant.get_frame(frame.index()) is not frame):
        raise ValueError(f"frame = {frame!r} is not allowed: must be a "
                         "frame of plant")
    child = weld_joint.child_body()
    if frame.body().index() not in [b.index() for b in
                                    plant.GetBodiesWeldedTo(child)]:
        raise ValueError(
            f"frame = {frame.scoped_name()} is not allowed: must be on a "
            f"body welded to the weld's child {child.scoped_name()} (the "
            "sensor's measurement frame)")
    X_JM = frame.CalcPose(plant.CreateDefaultContext(),
                          weld_joint.frame_on_child())
    if np.allclose(X_JM.GetAsMatrix4(), np.eye(4), rtol=0, atol=1e-12):
        return None
    R_MJ = X_JM.rotation().matrix().T
    p = X_JM.translation()
    p_cross = np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]],
                        [-p[1], p[0], 0.0]])
    return np.block([[R_MJ, np.zeros((3, 3))], [-R_MJ @ p_cross, R_MJ]])


WeldWrench = WeldWrench_[None]
"""The double WeldWrench_ (its docstring)."""
