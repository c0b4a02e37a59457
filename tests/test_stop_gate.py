"""The StopGate: zeros during a stop, otherwise its input scaled as a
whole into its envelope (the closed form), in double and in AutoDiffXd."""

import numpy as np
from pydrake.autodiffutils import ExtractValue

from drake_wbc.stages import StopGate


def test_the_gate_zeros_on_a_stop_and_scales_into_its_envelope():
    limits = (0.5, 0.4, 0.9)
    double = StopGate(3, limits)
    autodiff = double.ToAutoDiffXd()
    rng = np.random.default_rng(13)
    contexts = [system.CreateDefaultContext()
                for system in (double, autodiff)]
    for _ in range(60):
        value = rng.normal(size=3) * rng.choice([0.1, 1.0])
        stop = float(rng.random() < 0.2)
        expected = 1.0 if stop else min(
            [1.0] + [lim / abs(v) for v, lim in zip(value, limits,
                                                     strict=True)
                     if abs(v) > lim])
        gated_expected = (np.zeros(3) if stop else
                          value if expected == 1.0 else expected * value)
        for system, context in zip((double, autodiff), contexts,
                                   strict=True):
            system.GetInputPort("value").FixValue(context, value)
            system.GetInputPort("stop").FixValue(context, [stop])
            gated, scale = (
                np.asarray(ExtractValue(np.asarray(v, dtype=object)),
                           dtype=float).ravel()
                for v in (system.GetOutputPort(name).Eval(context)
                          for name in ("gated", "scale")))
            np.testing.assert_allclose(scale, [expected], rtol=1e-15)
            np.testing.assert_allclose(gated, gated_expected, rtol=1e-15,
                                       atol=1e-300)
