"""AdmittanceFilter: the whole body's admittance lag on F_ext, the virtual
mass of eq. (cdmp-wb)'s admittance, as a Drake system (its math:
drake_wbc.math.cdmp.admittance_filter_model)."""

from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.framework import Diagram_
from pydrake.systems.primitives import LinearSystem_

from drake_wbc.math.cdmp import admittance_filter_model
from drake_wbc.stages.support import build_composite, define_composite_stage

WRENCH_AXES = 6
"""The wrench's components [f; tau]."""

MODEL_NAME = "admittance_lag"
"""The name of the stage's LinearSystem inside it."""


@define_composite_stage("AdmittanceFilter_",
                        scalars=(float, AutoDiffXd, Expression))
def AdmittanceFilter_(T):
    class Impl(Diagram_[T]):
        """The first-order lag T_hri F_bar_dot = F_ext - F_bar on each of
        the wrench's six components, between the wrench estimator and the
        whole-body CDMP (math.cdmp.admittance_filter_model: with k_hri it
        makes the admittance M V_dot + V / k_hri = F_ext of virtual mass
        M = T_hri / k_hri).

        ::

                           ┌──────────────────┐
            wrench ───────►│ AdmittanceFilter ├──► filtered_wrench
                           └──────────────────┘

        - wrench: F_ext (6), [f; tau] in T_b.
        - filtered_wrench: F_bar (6), the same frame; in discrete time
          F_bar_k = F_bar_(k-1) + (1 - exp(-h / T_hri)) (F_ext_k -
          F_bar_(k-1)), with direct feedthrough (no tick of delay).

        Linear, so the stage is Drake's C++ `LinearSystem` (named
        MODEL_NAME) of those matrices: no Python runs in its tick, and it
        converts to AutoDiffXd and symbolic (stages.support.
        define_composite_stage). Its state starts at zero (no wrench):
        the estimator's F_ext is zero at rest, the tool's weight removed.

        Args:
            time_constant: T_hri in s, > 0
                (WholeBodyCdmpParameters.hri_time_constant, checked
                there; the controller leaves the stage out at 0).
            time_step: the control period h in s, default 0.01; 0 for
                the continuous lag.
        """

        def __init__(self, time_constant=0.1, time_step=0.01):
            Diagram_[T].__init__(self)
            A, B, C, D = admittance_filter_model(time_constant, time_step,
                                                 WRENCH_AXES)
            h = float(time_step)

            def build(builder):
                model = builder.AddNamedSystem(MODEL_NAME, LinearSystem_[T](
                    A, B, C, D, h))
                builder.ExportInput(model.get_input_port(), "wrench")
                builder.ExportOutput(model.get_output_port(),
                                     "filtered_wrench")

            build_composite(self, T, build)

    return Impl


AdmittanceFilter = AdmittanceFilter_[None]
"""AdmittanceFilter_ for double; `ToAutoDiffXd()` gives Drake's AutoDiffXd
copy of it."""
