"""bboxtune.agents.tune / bboxtune.agents.smooth: the observation is the env's own (reset), the parameters are what
env.step applies
for the policy's action, the smoothed track is the env's estimate for it; inputs are checked, tuners resolved."""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import agents
from bboxtune.agents.policies.gate_file import Gate, LinearGain
from bboxtune.agents.smoothing import pretrained
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.agents.training.run_files import RunError
from bboxtune.envs.data.boxes import MAX_COORD, cxcywh_to_xywh

tune_module = sys.modules["bboxtune.agents.smoothing.tuner"]  # ``bboxtune.agents.tune`` is the function
Tuner = tune_module.Tuner
ENV_ID = "bboxtune/FilterTune-v0"
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


def _track(seed: int = 0, T: int = 60) -> np.ndarray:
    """A smooth xywh track with noise (px)."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    centre = np.stack([200 + 2.0 * t + 5 * np.sin(t / 9), 150 + np.cos(t / 7) * 20], axis=1) + rng.normal(0, 2, (T, 2))
    size = np.array([40.0, 60.0]) * np.exp(rng.normal(0, 0.02, (T, 2)))
    return np.concatenate([centre - size / 2, size], axis=1)


@pytest.mark.parametrize("name", ["sim_ufir_cmn", "sim_kf_cmn"])
def test_sim_episode_observation_params_and_estimate_are_the_envs(name):
    tuner = load_pretrained(name)
    env = gym.make(ENV_ID, **dataclasses.asdict(tuner.config) | {"track_length": 120}).unwrapped  # shorter tracks
    tuner = dataclasses.replace(tuner, config=env.config)
    for seed in (3, 11):
        obs, _ = env.reset(options={"noise_seed": seed})
        ep = env.episode
        boxes = cxcywh_to_xywh(ep.y)
        seen = tuner.observe(boxes, ep.tau)
        assert seen.nominal == ep.nominal
        np.testing.assert_allclose(seen.obs, obs, rtol=1e-5, atol=1e-6)  # xywh round trip: last-bit differences
        action = tuner.action(seen)
        np.testing.assert_allclose(action, tuner.policy.predict(obs[None])[0], atol=1e-4)
        params = tuner.tune(boxes, ep.tau)
        estimate = env.score(action[None])["estimates"][0]
        _, _, _, _, info = env.step(action)
        assert params == info["params"]
        np.testing.assert_allclose(tuner.smooth(boxes, ep.tau, params), cxcywh_to_xywh(estimate), rtol=1e-9, atol=1e-7)


def test_a_tuner_of_the_msd_feature_set_observes_what_its_env_does():
    """A run trained with ``features="msd"`` sees the 21-entry observation of its env (the observation alone: the
    pretrained policy here has 20 inputs); a bytetrack_kf tuner of that set skips the compiled 20-entry kernel."""
    env = gym.make(ENV_ID, backend="ufir_cmn", features="msd", track_length=120).unwrapped
    tuner = dataclasses.replace(load_pretrained("sim_ufir_cmn"), config=env.config)
    obs, _ = env.reset(options={"noise_seed": 5})
    seen = tuner.observe(cxcywh_to_xywh(env.episode.y), env.episode.tau)
    assert seen.obs.shape == (21,)
    np.testing.assert_allclose(seen.obs, obs, rtol=1e-5, atol=1e-6)  # xywh round trip: last-bit differences
    box_tuner = load_pretrained("mot15_det")
    assert box_tuner._compiled_rule is not None
    msd_tuner = dataclasses.replace(box_tuner, config=dataclasses.replace(box_tuner.config, features="msd"))
    assert msd_tuner._compiled_rule is None and msd_tuner.observe(_track(), 1 / 30).obs.shape == (21,)


@pytest.mark.skipif(not os.environ.get("OTB_ROOT"), reason="needs the OTB data (set OTB_ROOT)")
def test_otb_tracker_episode_from_the_result_file_is_the_envs_bit_for_bit():
    env = gym.make(ENV_ID, backend="ufir_cmn", source="otb_tracker", tracker="STRUCK", split="test").unwrapped
    tuner = dataclasses.replace(load_pretrained("sim_ufir_cmn"), config=env.config)  # same spaces, this env's rule
    dataset = env.source.dataset
    names = env.source.names[:3]
    for name in names:
        obs, _ = env.reset(options={"sequence": name, "noise_seed": 0})
        boxes = dataset.tracker_boxes("STRUCK", name)  # what a user has: the tracker's file, xywh
        seen = tuner.observe(boxes, env.config.otb_tau)
        assert seen.nominal == env.episode.nominal
        np.testing.assert_array_equal(seen.obs, obs)
        action = tuner.action(seen)
        params = tuner.tune(boxes, env.config.otb_tau)
        estimate = env.score(action[None])["estimates"][0]
        _, _, _, _, info = env.step(action)
        assert params == info["params"]
        np.testing.assert_array_equal(tuner.smooth(boxes, env.config.otb_tau, params), cxcywh_to_xywh(estimate))


def test_the_rule_nominal_of_the_otb_sources_scales_with_the_box():
    cfg = dataclasses.replace(load_pretrained("sim_ufir_cmn").config, source="otb_tracker")
    small, large = _track(1), _track(1) * 4
    a, b = tune_module.rule_nominal(cfg, small, 1 / 30), tune_module.rule_nominal(cfg, large, 1 / 30)
    assert b.sigma_v == pytest.approx(4 * a.sigma_v) and b.sigma_w == pytest.approx(4 * a.sigma_w)
    sim = dataclasses.replace(cfg, source="sim")
    assert tune_module.rule_nominal(sim, small, 1 / 30) == tune_module.rule_nominal(sim, large, 1 / 30)


@pytest.mark.parametrize("kwargs", [{"source": "sim", "sim_noise": "box"},
                                    {"source": "sim", "sim_noise": "box", "motion": "otb"},
                                    {"source": "mix", "mix_weights": (1, 0, 0), "sim_noise": "box"}, {"source": "sim"}])
def test_the_rule_nominal_is_the_one_the_env_trained_with(kwargs):
    """A tuner observes a track with the nominal σ its training episodes had (sim_noise="box": relative to the box)."""
    cfg = tune_module.EnvConfig(track_length=120, backend="kf_cmn", **kwargs)
    env = gym.make(ENV_ID, **dataclasses.asdict(cfg))
    for seed in range(4):
        env.reset(seed=seed)
        ep = env.unwrapped.episode
        assert tune_module.rule_nominal(cfg, ep.y, ep.tau) == ep.nominal


def test_the_package_functions_use_the_named_tuner_and_the_run_directory_alike():
    boxes, tau = _track(2), 1 / 30
    params = agents.tune(boxes, tau, pretrained="sim_ufir_cmn")
    assert set(params) == {"psi", "horizon"} and isinstance(params["horizon"], int)
    assert params == agents.tune(boxes, tau, model=os.path.join(REPO, "docs/results/ufir_cmn/run"))
    assert params == agents.tune(boxes, tau, backend="ufir_cmn", pretrained="sim_ufir_cmn")
    smoothed = agents.smooth(boxes, tau, pretrained="sim_ufir_cmn")
    np.testing.assert_array_equal(smoothed, load_pretrained("sim_ufir_cmn").smooth(boxes, tau, params))
    assert smoothed.shape == boxes.shape and np.abs(smoothed - boxes).max() > 0


def test_missing_frames_are_predicted_after_the_first_measurement():
    boxes = _track(4)
    boxes[:3] = np.nan
    boxes[20:26] = np.nan
    smoothed = agents.smooth(boxes, 1 / 30, pretrained="sim_kf_cmn")
    assert np.isnan(smoothed[:3]).all() and np.isfinite(smoothed[3:]).all()


def test_the_default_is_the_tracker_output_tuner(tmp_path, monkeypatch):
    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    with pytest.raises(ValueError, match=f"{tune_module.DEFAULT_PRETRAINED}' is not installed; available: none"):
        agents.tune(_track(), 1 / 30)
    shutil.copytree(os.path.join(REPO, "agents/pretrained/sim_kf_cmn"), tmp_path / tune_module.DEFAULT_PRETRAINED)
    shutil.copytree(os.path.join(REPO, "agents/pretrained/sim_ufir_cmn"), tmp_path / "otb_tracker_ufir_cmn")
    assert set(agents.tune(_track(), 1 / 30)) == {"psi", "sigma_w", "sigma_v"}
    assert set(agents.tune(_track(), 1 / 30, backend="ufir_cmn")) == {"psi", "horizon"}


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"model": "x", "pretrained": "sim_ufir_cmn"}, "not both"),
    ({"backend": "kf_cmn", "pretrained": "sim_ufir_cmn"}, "backend='kf_cmn'.*tunes 'ufir_cmn'"),
    ({"pretrained": "nope"}, "'nope' is not installed; available: .*sim_ufir_cmn"),
])
def test_tuner_choice_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        agents.tune(_track(), 1 / 30, **kwargs)


@pytest.mark.parametrize("kwargs", [
    {"backend": "kf_cmn", "source": "otb_tracker", "trackers": ["SiamFC", "ATOM"], "otb_root": "/nonexistent"},
    {"backend": "ufir_cmn", "source": "mix", "mix_weights": [0.0, 1.0, 2.0], "trackers": ["X"], "horizon_max": 100},
    {"backend": "ufir", "source": "video", "detector": "sift"},
])
def test_the_spaces_env_needs_no_data_set(kwargs, monkeypatch):
    monkeypatch.delenv("OTB_ROOT", raising=False)
    env = tune_module.spaces_venv({"env_id": ENV_ID, "env_kwargs": kwargs}, "config.yml").envs[0].unwrapped
    reference = gym.make(ENV_ID, backend=kwargs["backend"], horizon_max=kwargs.get("horizon_max", 400)).unwrapped
    assert env.action_map == reference.action_map and env.observation_space == reference.observation_space


def test_a_multi_step_run_is_refused(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(os.path.join(REPO, "docs/results/ufir_cmn/run"), run)
    config = run / "config.yml"
    config.write_text(config.read_text().replace("FilterTune-v0", "FilterRetune-v0"))
    with pytest.raises(RunError, match="config.yml: env_id bboxtune/FilterRetune-v0"):
        Tuner.from_run(run)


def _with(boxes: np.ndarray, row: int, values: list[float]) -> np.ndarray:
    out = boxes.copy()
    out[row] = values
    return out


GOOD = _track(5, T=20)
BAD_BOXES = [
    (GOOD[:, :3], ValueError, r"boxes has shape \(20, 3\)"),
    (GOOD.ravel(), ValueError, r"boxes has shape \(80,\)"),
    (GOOD[None], ValueError, r"boxes has shape \(1, 20, 4\)"),
    ([[1, 2, 3, 4], [1, 2, 3]], ValueError, "boxes is not an array of numbers"),
    (GOOD.astype(str), TypeError, "boxes has dtype"),
    (_with(GOOD, 4, [1, np.nan, 3, 4]), ValueError, r"boxes\[4\] .* partly NaN"),
    (_with(GOOD, 5, [1, np.inf, 3, 4]), ValueError, r"boxes\[5\] .* finite x, y and w, h > 0"),
    (_with(GOOD, 6, [1, 2, 0, 4]), ValueError, r"boxes\[6\] .* w, h > 0"),
    (_with(GOOD, 7, [1, 2, 3, -4]), ValueError, r"boxes\[7\] .* w, h > 0"),
    (_with(GOOD, 8, [1.0000001e7, 2, 3, 4]), ValueError, r"boxes\[8\] .* \|x\|, \|y\|, w, h <= 1e7 px"),
    (_with(GOOD, 9, [1, -1e300, 3, 4]), ValueError, r"boxes\[9\] .* <= 1e7 px"),  # once failed in a filter, naming y
    (_with(GOOD, 10, [1, 2, 3, 1.0000001e7]), ValueError, r"boxes\[10\] .* <= 1e7 px"),
    (GOOD[:7], ValueError, "boxes has 7 frames, 7 of them measured; a track needs at least 8 frames"),
    (np.where(np.arange(20)[:, None] == 3, GOOD, np.nan), ValueError, "boxes has 20 frames, 1 of them measured"),
]


@pytest.mark.parametrize(("boxes", "error", "match"), BAD_BOXES)
def test_bad_boxes_are_named(boxes, error, match):
    with pytest.raises(error, match=match):
        agents.tune(boxes, 1 / 30, pretrained="sim_ufir_cmn")


@pytest.mark.parametrize("name", ["sim_ufir_cmn", "sim_kf_cmn"])
def test_boxes_at_the_coordinate_bound_are_tuned_and_smoothed(name):
    """A track whose |x|, |y|, w, h reach MAX_COORD (1e7 px) exactly is accepted and smoothed to finite boxes."""
    edge = GOOD.copy()
    edge[:, 0] += -MAX_COORD - edge[:, 0].min()  # the leftmost x at -1e7
    edge[:, 1] += MAX_COORD - edge[:, 1].max()
    edge[:, 2:] *= MAX_COORD / edge[:, 2:].max()  # the largest size at 1e7: the track's scale
    assert np.abs(edge).max() == MAX_COORD
    params = agents.tune(edge, 1 / 30, pretrained=name)
    smoothed = agents.smooth(edge, 1 / 30, pretrained=name)
    assert all(np.isfinite(v) for v in params.values()) and np.isfinite(smoothed).all()


@pytest.mark.parametrize(("tau", "error"), [
    (0.0, ValueError), (-0.03, ValueError), (np.nan, ValueError), (np.inf, ValueError), (2.0, ValueError),
    (1e-4, ValueError), ("0.03", TypeError), (True, TypeError), (None, TypeError),
])
def test_bad_tau_is_named(tau, error):
    with pytest.raises(error, match=r"tau=.*allowed: a real number in \[0.001, 1\]"):
        agents.tune(GOOD, tau, pretrained="sim_ufir_cmn")
    with pytest.raises(error, match="tau="):
        agents.smooth(GOOD, tau, pretrained="sim_ufir_cmn")


def test_smooth_checks_given_params():
    tuner = load_pretrained("sim_ufir_cmn")
    with pytest.raises(ValueError, match=r"params has keys \['horizon'\]; back end ufir_cmn takes"):
        tuner.smooth(GOOD, 1 / 30, {"horizon": 5})


@pytest.mark.parametrize("gate_margin", [None, np.inf])
def test_smooth_checks_and_converts_the_track_once(gate_margin: float | None, monkeypatch: pytest.MonkeyPatch) -> None:
    """One check of the boxes and tau, and one xywh -> cxcywh conversion, on the smoothing path and on the path
    where the gate leaves the track alone (whose boxes come back exactly as given)."""
    tuner = load_pretrained("sim_ufir_cmn")
    if gate_margin is not None:
        n = tuner.policy.model.observation_space.shape[0]
        gain = LinearGain(mean=np.zeros(n), scale=np.ones(n), coef=np.zeros(n), intercept=0.0)
        tuner = dataclasses.replace(tuner, gate=Gate(gain, gate_margin))
    calls = {"check_boxes": 0, "check_tau": 0, "xywh_to_cxcywh": 0}
    for name in calls:
        original = getattr(tune_module, name)

        def counted(*args, _name=name, _original=original, **kwargs):
            calls[_name] += 1
            return _original(*args, **kwargs)

        monkeypatch.setattr(tune_module, name, counted)
    boxes = _track()
    out = tuner.smooth(boxes, 1 / 30)
    assert calls == {"check_boxes": 1, "check_tau": 1, "xywh_to_cxcywh": 1}
    if gate_margin is not None:
        np.testing.assert_array_equal(out, boxes)


def test_backend_params_change_only_the_gap_output_of_mot15_det():
    """mot15_det's config carries bytetrack_kf's gap policy: the policy's parameters and every measured frame are
    those of the tuner without it; inside the gap the size is held at its last estimate."""
    tuner = load_pretrained("mot15_det")
    assert tuner.backend_params == {"gap_velocity_decay": 0.7, "gap_size_decay": 0.0}
    without = tuner.with_backend_params({})
    boxes = _track(7)
    boxes[20:30] = np.nan
    assert tuner.tune(boxes, 0.1) == without.tune(boxes, 0.1)
    got, stock = tuner.smooth(boxes, 0.1), without.smooth(boxes, 0.1)
    measured = ~np.isnan(boxes[:, 0])
    np.testing.assert_array_equal(got[measured], stock[measured])
    assert np.abs(got[~measured] - stock[~measured]).max() > 0.1
    np.testing.assert_array_equal(got[20:30, 2:], np.repeat(got[19:20, 2:], 10, axis=0))


@pytest.mark.parametrize(("params", "error", "match"), [
    ("0.7", TypeError, "'0.7' is a str; allowed: a mapping"),
    ({"std_weight_position": 0.1}, ValueError, "'std_weight_position' is not a setting of back end bytetrack_kf "
                                               "outside the tuner's action; allowed: gap_size_decay, gap_velocity_decay"),
    ({"gap_size_decay": "0"}, TypeError, "gap_size_decay='0'; allowed: a number"),
    ({"gap_velocity_decay": 1.5}, ValueError, "gap_velocity_decay=1.5 is out of range"),
])
def test_bad_backend_params_are_named(params, error, match):
    with pytest.raises(error, match=match):
        load_pretrained("mot15_det").with_backend_params(params)


def test_bad_backend_params_in_a_config_name_the_file(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(pretrained.folder("mot15_det"), run)
    config = run / "config.yml"
    config.write_text(config.read_text().replace("gap_size_decay: 0.0", "gap_size_decay: -1.0"))
    with pytest.raises(RunError, match="config.yml: backend_params: gap_size_decay=-1.0 is out of range"):
        Tuner.from_run(run)


def test_tune_checked_is_tune_without_the_checks(monkeypatch: pytest.MonkeyPatch) -> None:
    """A tracker's histories are checked detections: tune_checked gives tune's parameters and checks nothing again."""
    tuner = load_pretrained("mot15_det")
    boxes = _track(4, T=40)
    boxes[[3, 17, 18]] = np.nan  # missed detections
    want = tuner.tune(boxes, 0.1)
    for name in ("check_boxes", "check_tau"):
        monkeypatch.setattr(tune_module, name, lambda *args, _name=name: pytest.fail(f"{_name} called"))
    assert tuner.tune_checked(boxes, 0.1) == want
    assert want != tuner.tune_checked(boxes[:20], 0.1)  # the parameters depend on the track
