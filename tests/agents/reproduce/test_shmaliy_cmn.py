"""bboxtune.agents.reproduce.shmaliy_cmn ([Shmaliy-CMN], [Shmaliy-CMN]): the measured N_opt(ψ) and the paper's horizon rule."""

from __future__ import annotations

import numpy as np

from bboxtune.agents.reproduce import shmaliy_cmn
from bboxtune.agents.reproduce.common import make_settings


def test_measured_nopt_grows_with_psi():
    """Substance: the UFIR-CMN horizon minimising the RMSE grows from ~20 at ψ = 0 to well above it at 0.95."""
    res = shmaliy_cmn.run_nopt(make_settings(4, seed=1, quick=True))
    n0, n95 = res.n_opt(0), res.n_opt(len(res.psi) - 1)
    assert 14 <= n0 <= 28
    assert n95 > 2 * n0
    assert np.all(res.kf_cmn <= np.array([r.min() for r in res.rmse]) * 1.02)  # KF-CMN is the optimal filter


def test_paper_horizon_passes_through_the_anchors():
    assert shmaliy_cmn.paper_horizon(np.array([0.0, 0.6, 0.95])).tolist() == [20, 30, 100]
    assert np.all(np.diff(shmaliy_cmn.paper_horizon(np.linspace(0, 0.95, 40))) >= 0)
