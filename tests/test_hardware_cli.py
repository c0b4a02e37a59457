"""`drake-wbc robot-sim` and `deploy` check their arguments before they
touch LCM: a real-time rate must be a positive finite number (with 0 the
Simulator ran unpaced, and the joints moved at 2 rad/s of wall time)."""

import pytest

from drake_wbc.cli.main import main
from drake_wbc.deployment.deploy import deploy
from drake_wbc.experiments.scenario import find_scenario, load_scenario


@pytest.mark.parametrize("program", ["robot-sim", "deploy"])
@pytest.mark.parametrize("rate", ["0", "-1", "nan", "inf"])
def test_the_realtime_rate_must_be_positive_and_finite(program, rate,
                                                        capsys):
    assert main([program, "hardware", "--realtime-rate", rate]) == 2
    error = capsys.readouterr().err
    assert f"--realtime-rate = {float(rate)!r} is not allowed" in error
    assert "positive finite number" in error


def test_deploy_checks_its_rate_too():
    scenario = load_scenario(find_scenario("hardware"))
    with pytest.raises(ValueError, match="realtime_rate = 0.0 is not "
                                         "allowed"):
        deploy(scenario, realtime_rate=0.0)
