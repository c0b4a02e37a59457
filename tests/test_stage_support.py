"""drake_wbc.stages.support.define_stage: a stage's scalar-converted
copies are built from the arguments of the original."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common import cpp_template
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.stages.support import SCALARS, define_stage


@define_stage("ScaledCopy_")
def ScaledCopy_(T):
    class Impl(LeafSystem_[T]):
        def _construct(self, gain, size=2, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.gain = gain
            self.DeclareVectorInputPort("u", size)
            self.DeclareVectorOutputPort(
                "y", size, lambda context, out: out.SetFromVector(
                    self.gain[0] * self.get_input_port().Eval(context)))

    return Impl


def test_copies_are_constructed_from_the_originals_arguments():
    parameters = [3.0]
    system = ScaledCopy_[float](parameters, size=3)
    copy = system.ToAutoDiffXd()
    assert isinstance(copy, ScaledCopy_[AutoDiffXd])
    assert copy.gain is parameters  # shared, neither copied nor re-checked
    assert copy.get_input_port().size() == 3
    context = copy.CreateDefaultContext()
    copy.get_input_port().FixValue(context, np.array(
        [AutoDiffXd(1.0), AutoDiffXd(2.0), AutoDiffXd(3.0)], dtype=object))
    assert ScaledCopy_.param_list == [(T,) for T in SCALARS]
    back = copy.ToScalarType[float]()
    assert back.gain is parameters


@TemplateSystem.define("PlainScaledCopy_", T_list=SCALARS)
def PlainScaledCopy_(T):
    """A system defined by pydrake alone (its own look-up of the caller's
    module, inspect.stack())."""
    class Impl(LeafSystem_[T]):
        def _construct(self, converter=None):
            LeafSystem_[T].__init__(self, converter)

        def _construct_copy(self, other, converter=None):
            LeafSystem_[T].__init__(self, converter)

    return Impl


def test_every_scalar_type_is_made_with_pydrakes_names_and_lookup_restored():
    """define_stage makes the class of every scalar type when the stage is
    defined, with pydrake's look-up of the caller's module swapped for a
    walk of the frames: the conversion methods get the names pydrake's
    own look-up gives them, and the look-up is pydrake's again after."""
    lookup = cpp_template._get_module_from_stack

    @define_stage("Defined_")
    def Defined_(T):
        class Impl(LeafSystem_[T]):
            def _construct(self, converter=None):
                LeafSystem_[T].__init__(self, converter)

        return Impl

    assert cpp_template._get_module_from_stack is lookup
    for T in SCALARS:
        made = Defined_._instantiation_map[(T,)]
        assert isinstance(made, type), f"{T} was not made at definition"
        ours = Defined_[T].ToScalarType
        theirs = PlainScaledCopy_[T].ToScalarType
        for U in SCALARS:
            assert ours[U].__module__ == theirs[U].__module__
        assert ours._scope is theirs._scope
