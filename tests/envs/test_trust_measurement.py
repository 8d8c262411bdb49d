""""Trust the measurement" is an action for every back end: there is an action in [-1, 1]^d whose estimates are
the raw measurements (exactly for the unbiased FIR family at N = 2) or within 0.1 % of the box scale.

The action: horizon N = 2 (a = -1), σ_w at the top (+1), σ_v at the bottom (-1), ψ = 0 for UFIR-CMN (-1: with
N = 2 a large ψ makes the position unobservable) and ψ = 0.99 for KF-CMN (+1: the coloured-noise model then
follows each measurement). KF / UKF reach the tolerance with ``sigma_decades=2.5`` (default 1.5: 5.5 % of the
box scale on simulated tracks), OFIR with σ_v tuned too and ``sigma_decades=2.5`` (default: 32 %) — the
documented opt-ins (``bboxtune.envs.tune_env.FilterTuneEnv``, Action Space).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import filters
from bboxtune.envs.episodes.features import box_scale

TOLERANCE = 1e-3  # max |estimate − y| / box scale over a track (0.05 px on a 50 px box)
EXACT = 1e-10  # float round-off only
TRUST = {"psi": -1.0, "horizon": -1.0, "sigma_w": 1.0, "sigma_v": -1.0}
# back end -> (env arguments beyond the defaults, tolerance)
CASES: dict[str, tuple[dict, float]] = {
    "ufir": ({}, EXACT),
    "ufir_cmn": ({}, EXACT),
    "oufir": ({}, EXACT),
    "fir": ({}, EXACT),
    "kf_cmn": ({}, TOLERANCE),
    "kf": ({"sigma_decades": 2.5}, TOLERANCE),
    "ukf": ({"sigma_decades": 2.5}, TOLERANCE),
    "ofir": ({"tune": ("horizon", "sigma_w", "sigma_v"), "sigma_decades": 2.5}, TOLERANCE),
}


def trust_action(backend: str, tune: tuple[str, ...]) -> np.ndarray:
    return np.array([1.0 if (name, backend) == ("psi", "kf_cmn") else TRUST[name] for name in tune], np.float32)


def test_every_back_end_has_a_case() -> None:
    assert set(CASES) == set(filters.NAMES)


@pytest.mark.parametrize("backend", filters.NAMES)
def test_an_action_trusts_the_measurement(backend: str) -> None:
    kwargs, tolerance = CASES[backend]
    worst, rule_gap = 0.0, np.inf
    # the default scenario, and its smallest τ (1/30 s: the least process noise per frame, the hardest case
    # for the Kalman family)
    for scenario in ({}, {"tau_range": (1 / 30, 1 / 30)}):
        env = gym.make("bboxtune/FilterTune-v0", backend=backend, track_length=300, **scenario, **kwargs)
        u = env.unwrapped
        action = trust_action(backend, u.config.tune)
        for seed in range(6):
            env.reset(options={"noise_seed": seed})  # one episode prepared, not a block
            ep = u.episode
            scored = u.score(np.stack([action, u.action_map.to_actions(u.rule_params(ep), ep.nominal)[0]]))
            deviation = np.abs(scored["estimates"] - ep.y) / box_scale(ep.y)  # (2, T, 4)
            worst = max(worst, float(deviation[0].max()))
            rule_gap = min(rule_gap, float(deviation[1].max()))
    assert worst <= tolerance
    assert rule_gap > 10 * tolerance  # the rule smooths (4 % of the box scale or more): the check tells them apart
