"""scripts/otb_motion.py: the fit recovers a simulated model's parameters; on OTB it reproduces OTB_MOTION."""

from __future__ import annotations

import json
import os
from dataclasses import asdict

import pytest

from bboxtune.agents.commands import otb_motion
from bboxtune.envs.data.sim_motion import OTB_MOTION

OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset (CI: OTB_ROOT=../shared/data/otb)")


def test_fit_recovers_the_simulated_model():
    """Fitting 300 integer-rounded "otb" tracks (fixed seeds) gives back the parameters they were drawn with."""
    script = otb_motion
    fitted, extra = script.fit(script.simulated("otb", 300, seed=1000))
    assert fitted.switch_rate == pytest.approx(OTB_MOTION.switch_rate, rel=0.35)
    assert fitted.cruise_share == pytest.approx(OTB_MOTION.cruise_share, abs=0.12)
    assert fitted.jitter_time == pytest.approx(OTB_MOTION.jitter_time, rel=0.35)
    assert fitted.level_log_mean == pytest.approx(OTB_MOTION.level_log_mean, abs=0.15)
    assert fitted.level_log_std == pytest.approx(OTB_MOTION.level_log_std, abs=0.12)
    assert fitted.size_log_mean == pytest.approx(OTB_MOTION.size_log_mean, abs=0.15)
    assert fitted.size_log_std == pytest.approx(OTB_MOTION.size_log_std, abs=0.15)
    cv, _ = script.fit(script.simulated("cv", 100, seed=0))
    assert cv.level_log_mean < OTB_MOTION.level_log_mean - 1.0  # the "cv" default moves a decade less


@needs_otb
def test_script_on_otb_reproduces_the_shipped_constants(tmp_path):
    assert otb_motion.main(["--otb-root", OTB_ROOT, "--out", str(tmp_path), "--tracks", "40"]) == 0
    result = json.loads((tmp_path / "otb_motion.json").read_text())
    for name, value in asdict(OTB_MOTION).items():  # the constants are the fit, rounded to 3 digits
        assert result["fitted"][name] == pytest.approx(value, rel=5e-3), name
    assert result["stats"]["otb_train"]["n_tracks"] == 55 and result["stats"]["otb_test"]["n_tracks"] == 23
    assert "| `switch_rate` |" in (tmp_path / "otb_motion.md").read_text()


def test_bad_arguments_exit_2(tmp_path, capsys):
    """More misuse cases: tests/scripts/test_cli_misuse.py."""
    with pytest.raises(SystemExit) as err:
        otb_motion.main(["--out", str(tmp_path), "--tracks", "0"])
    assert err.value.code == 2 and "--tracks" in capsys.readouterr().err
    with pytest.raises(SystemExit) as err:
        otb_motion.main(["--otb-root", str(tmp_path / "missing"), "--out", str(tmp_path)])
    assert err.value.code == 2 and "--otb-root" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
