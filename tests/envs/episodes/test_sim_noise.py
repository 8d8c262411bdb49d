"""The sim source's episodes: what a noise seed draws, and sim_noise="box" (the simulator's truth measured as the "otb"
source measures OTB ground truth)."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.envs.data.boxes import cxcywh_to_xywh
from bboxtune.envs.data.otb import replay_synthetic
from bboxtune.envs.data.simulate import simulate
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import rule_nominal
from bboxtune.envs.episodes.features import box_scale
from bboxtune.envs.episodes.sources import SimSource


def test_box_noise_is_the_otb_replay_noise_on_the_simulated_truth() -> None:
    cfg = EnvConfig(sim_noise="box", motion="otb", track_length=200)
    absolute = SimSource(EnvConfig(motion="otb", track_length=200)).draw(None, 7)
    ep = SimSource(cfg).draw(None, 7)
    np.testing.assert_array_equal(ep.truth, absolute.truth)  # the same simulated motion
    rng = np.random.default_rng((7, 1))
    sigma_rel = float(np.exp(rng.uniform(np.log(0.01), np.log(0.1))))
    expected = replay_synthetic(cxcywh_to_xywh(ep.truth), psi=absolute.scenario["psi"], sigma_rel=sigma_rel, rng=rng,
                                tau=ep.tau)
    np.testing.assert_array_equal(ep.y, expected.y)
    assert ep.scenario["sigma_rel"] == sigma_rel and "sigma_xi" not in ep.scenario
    scale = box_scale(ep.y)
    assert ep.nominal == rule_nominal(cfg, cfg.otb_sigma_v_rel * scale, cfg.otb_sigma_w_rel * scale, ep.tau)
    batch = SimSource(cfg).draw_many([7, 8])
    np.testing.assert_array_equal(batch[0].y, ep.y)  # a block equals each episode drawn alone


@pytest.mark.parametrize("kwargs", [{}, {"track_length": 120}, {"motion": "otb", "track_length": 50}])
def test_an_episode_is_simulated_from_default_rng_of_its_noise_seed(kwargs: dict) -> None:
    """The documented definition (sources module docstring): scenario and noise from ``default_rng(noise_seed)``."""
    source = SimSource(EnvConfig(**kwargs))
    seeds = [0, 7, 2**62 - 1]
    for seed, ep in zip(seeds, source.draw_many(seeds), strict=True):
        rng = np.random.default_rng(seed)
        track = simulate(source.ranges.sample(rng), rng)
        np.testing.assert_array_equal(ep.y, track.y)


@pytest.mark.parametrize("kwargs, match", [
    ({"sim_noise": "relative"}, "sim_noise"),
    ({"sim_noise": "box", "source": "otb"}, "sim_noise='box' with source='otb'"),
    ({"sim_noise": "box", "scenario": "nonstationary"}, "scenario='nonstationary'"),
])
def test_bad_settings_are_refused(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        EnvConfig(**kwargs)
