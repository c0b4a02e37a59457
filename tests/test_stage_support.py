"""drake_wbc.stages.support.define_stage: a stage's scalar-converted
copies are built from the arguments of the original."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_

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
