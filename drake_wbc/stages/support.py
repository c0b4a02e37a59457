"""What the stages share in how they are built: their scalar types and
their definition as scalar-convertible templates (`define_stage`, which
the station's and the analyses' scalar-convertible systems use too), or,
where a stage is linear or a switch, as a small Diagram of Drake's C++
systems (`define_composite_stage`), a
vector computed once per change of its inputs in a cache entry and
sliced into named output ports, their named vector inputs and dependency
tickets, optional inputs, and the constants of the arm's
mounting (^bR_a and the arm base's origin in T_b) they read."""

import contextlib
import functools
import inspect
import sys

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common import cpp_template
from pydrake.common.cpp_template import TemplateClass
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import DiagramBuilder_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.math.capability import CapabilityBand
from drake_wbc.math.validation import checked_instance
from drake_wbc.robot.model import ArmKinematics

SCALARS = (float, AutoDiffXd)
"""The scalar types of every stage: double, and AutoDiffXd for `Linearize`
and `ToAutoDiffXd` of the whole controller (not symbolic: the stages
branch on values, as the paper's piecewise functions do)."""


def define_stage(name, scalars=SCALARS):
    """Defines a stage as a scalar-convertible template, like
    `TemplateSystem.define(name, T_list=scalars)`, for a function
    `instantiate(T)` that returns the stage's class for scalar type T
    (`scalars`: SCALARS unless a stage allows more, e.g. symbolic
    Expressions for one that never branches on values).

    The class defines `_construct(self, ..., converter=None)` only: its
    scalar-converted copies are constructed from the very arguments the
    original was (the parameters are not copied or checked again, and a
    copy shares them with its original), so that no stage writes a
    `_construct_copy` of its own. A class that needs another copy rule
    may still define `_construct_copy`.

    Every scalar type's class is made here, when the stage's module is
    imported, with pydrake's look-up of the caller's module made cheap
    (`_cheap_caller_lookup`): `name[None]` and `ToAutoDiffXd()` then
    find it made.
    """

    def decorate(instantiate):
        def instantiate_with_copy(T):
            cls = instantiate(T)
            if "_construct_copy" in cls.__dict__:
                return cls
            construct = cls.__dict__["_construct"]

            def _construct(self, *args, converter=None, **kwargs):
                self._construction = (args, kwargs)
                construct(self, *args, converter=converter, **kwargs)

            def _construct_copy(self, other, converter=None):
                args, kwargs = other._construction
                _construct(self, *args, converter=converter, **kwargs)

            _construct.__doc__ = construct.__doc__
            cls._construct = _construct
            cls._construct_copy = _construct_copy
            return cls

        with _cheap_caller_lookup():
            template = TemplateSystem.define(
                name, T_list=scalars, scope=inspect.getmodule(instantiate))(
                    instantiate_with_copy)
            for T in scalars:
                template[T]
        return template

    return decorate


_PYDRAKE_LOOKUP = getattr(cpp_template, "_get_module_from_stack", None)
"""pydrake's own look-up of a caller's module, which `_cheap_caller_lookup`
puts back (also when two threads define systems at once)."""


@contextlib.contextmanager
def _cheap_caller_lookup():
    """Within it, pydrake finds a caller's module by walking the frames
    rather than with `inspect.stack()`.

    When a TemplateSystem makes the class of a scalar type, it names that
    class's ToScalarType methods after the module that calls it, which
    pydrake finds as `inspect.getmodule(inspect.stack()[2][0])`.
    `inspect.stack()` reads the source of every frame of the stack, and
    for each frame of the import system (frozen modules, without a file)
    `inspect.getmodule` scans all of `sys.modules` (CPython issue 92041).
    A stage's module is imported some ten imports deep, with over a
    thousand modules loaded: each class cost about 60 ms, 2.4 s of the
    7 s of `drake-wbc run`. `sys._getframe(frame)` is the same frame as
    `inspect.stack()[frame][0]` (both count from the look-up's own), so
    the module found is the same. pydrake's look-up is restored on exit;
    where a pydrake has none of that name, nothing is changed.
    """
    if _PYDRAKE_LOOKUP is None:
        yield
        return
    cpp_template._get_module_from_stack = _caller_module
    try:
        yield
    finally:
        cpp_template._get_module_from_stack = _PYDRAKE_LOOKUP


def _caller_module(frame=2):
    """The module of the frame `frame` levels above this one."""
    return inspect.getmodule(sys._getframe(frame))


def define_composite_stage(name, scalars=SCALARS):
    """Defines a stage built of Drake's C++ systems, for a function
    `instantiate(T)` that returns the stage's class for scalar type T: a
    subclass of Diagram_[T] whose constructor calls
    `build_composite(self, T, build)` (below). `name[None]` is the double
    one.

    Such a stage is one system of the controller with the ports and the
    name of the Python stage it stands for, and no Python runs in its
    tick. Its scalar-converted copies (`ToAutoDiffXd()`, and
    `ToSymbolic()` where every part allows it) are Drake's own: a
    Diagram_[U] of the converted parts, with the same ports, names,
    matrices and expressions, but not an instance of the class (the
    class's attributes and methods belong to the stage it was built as;
    `name[U](...)` builds one in U directly).
    """

    def decorate(instantiate):
        return TemplateClass.define(
            name, param_list=[(T,) for T in scalars],
            scope=inspect.getmodule(instantiate))(instantiate)

    return decorate


def build_composite(diagram, T, build):
    """Builds `diagram` (a Diagram_[T] being constructed) from
    `build(builder)`, which adds its parts to a DiagramBuilder_[T] and
    exports their ports under the stage's names."""
    builder = DiagramBuilder_[T]()
    build(builder)
    builder.BuildInto(diagram)


@functools.cache
def shared_arm_kinematics():
    """One ArmKinematics of the shipped robot, for stages built without
    one that read only its constants (R_ba, the arm base's position)."""
    return ArmKinematics()


def band_of(band, arm):
    """The CapabilityBand a stage uses: `band`, or where it is None the
    band of `arm`'s robot (its description's tuning,
    drake_wbc.robot.description.RobotTuning)."""
    return checked_instance("band", band, CapabilityBand,
                            lambda: arm.model.description.tuning
                            .capability_band)


def arm_mounting(arm):
    """(R_ba, p_a): the rotation ^bR_a and the arm base's origin in T_b
    (m), constants of the nominal kinematics of `arm` (ArmKinematics)."""
    values = arm.evaluate(np.zeros(arm.num_joints))
    R_ba = np.array(arm.R_ba, dtype=float)
    return R_ba, values.p_ee_in_base - R_ba @ values.X_AE.translation()


def declare_cached_vector(system, description, calc, prerequisites):
    """Declares a cache entry holding the vector `calc(context)` (float or
    AutoDiffXd), computed once per change of `prerequisites` and read by
    every output of `system` that needs it."""

    def produce(context, value):
        value.set_value(calc(context))

    return system.DeclareCacheEntry(
        description,
        ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(0)),
                      calc=produce),
        prerequisites,
    )


def declare_slices(system, entry, slices):
    """Declares one vector output port per (name, slice) of the vector in
    cache `entry`."""
    for name, part in slices:
        def calc(context, output, part=part):
            output.SetFromVector(entry.Eval(context)[part])

        size = part.stop - part.start
        system.DeclareVectorOutputPort(
            name, size, calc, prerequisites_of_calc={entry.ticket()})


def declare_inputs(system, sizes):
    """Declares the vector input ports (name, size) of `system`; returns
    them by name."""
    return {name: system.DeclareVectorInputPort(name, size)
            for name, size in sizes}


def tickets(ports):
    """The dependency tickets of `ports`."""
    return {port.ticket() for port in ports}


def optional_input(port, context, default):
    """The value of input `port` (vector or abstract), or `default` if it
    is neither connected nor fixed.

    HasValue then Eval, as optional_scalar: HasValue evaluates the
    upstream output, so Eval reads it from the cache; the other ways to
    read an optional port in one call (Eval inside try, which raises on
    an unconnected port, or System.EvalVectorInput) cost more per tick.
    """
    if port.HasValue(context):
        return port.Eval(context)
    return default


def optional_scalar(port, context, default):
    """The value of a one-element input `port`, or `default` if it is
    neither connected nor fixed."""
    if port.HasValue(context):
        return port.Eval(context)[0]
    return default
