"""bboxtune/FilterTune-v0 and bboxtune/FilterRetune-v0: checkers, determinism, scoring, bad input."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from bboxtune import envs, filters
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.scoring import reward_label
from tests.envs.conftest import OTB_ROOT, needs_otb

SOURCES = ["sim", pytest.param("otb", marks=needs_otb), pytest.param("otb_tracker", marks=needs_otb)]
SHORT = {"track_length": 120}


def _make(env_id: str, backend: str, source: str, **kw) -> gym.Env:
    extra = ({"otb_root": OTB_ROOT} if source in ("otb", "otb_tracker")
             else {"otb_root": OTB_ROOT, **SHORT} if source == "mix" else dict(SHORT))
    return gym.make(env_id, backend=backend, source=source, **extra, **kw)


@pytest.mark.parametrize("source", SOURCES)
@pytest.mark.parametrize("backend", filters.NAMES)
@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_checkers_pass(env_id: str, backend: str, source: str) -> None:
    env = _make(env_id, backend, source, window=30) if "Retune" in env_id else _make(env_id, backend, source)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_same_seed_same_everything(env_id: str) -> None:
    runs = []
    for _ in range(2):
        env = _make(env_id, "ufir_cmn", "sim")
        obs, _ = env.reset(seed=123)
        env.action_space.seed(5)
        obs2, reward, *_, info = env.step(env.action_space.sample())
        runs.append((obs, obs2, reward, info["rmse"], info["rule_rmse"], info["params"]))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2:] == runs[1][2:]


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_episode_prepared_in_a_block_equals_the_same_episode_pinned(backend: str) -> None:
    env = _make("bboxtune/FilterTune-v0", backend, "sim")
    env.reset(seed=11)
    assert env.unwrapped.source.block > 1  # unpinned sim episodes come from prepared blocks
    action = np.full(env.action_space.shape, 0.3, np.float32)
    for _ in range(3):
        obs, info = env.reset()
        _, reward, *_, step_info = env.step(action)
        pinned, _ = env.reset(options={"noise_seed": info["track"]["noise_seed"]})
        _, pinned_reward, *_, pinned_info = env.step(action)
        np.testing.assert_array_equal(obs, pinned)  # bit-identical: episodes are pure functions of their seed
        assert (reward, step_info["rule_rmse"]) == (pinned_reward, pinned_info["rule_rmse"])


def test_episode_sequence_does_not_depend_on_blocks_and_reseeding_restarts_it() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    seeds = [env.reset(seed=8)[1]["track"]["noise_seed"]] + [env.reset()[1]["track"]["noise_seed"] for _ in range(5)]
    rng = np.random.default_rng(8)  # one draw per episode from np_random, as without blocks
    assert seeds == [int(rng.integers(2**62)) for _ in range(6)]
    env.reset(options={"noise_seed": 5})  # a pinned episode leaves the sequence alone
    assert env.reset()[1]["track"]["noise_seed"] == int(rng.integers(2**62))
    assert env.reset(seed=8)[1]["track"]["noise_seed"] == seeds[0]  # reseeding drops the prepared episodes
    env.reset(seed=3, options={"noise_seed": 5})  # a reseeded pinned reset restarts the sequence too
    assert env.reset()[1]["track"]["noise_seed"] == int(np.random.default_rng(3).integers(2**62))


def test_reseeding_with_consecutive_seeds_reads_ahead_and_scattered_seeds_prepare_one(monkeypatch: pytest.MonkeyPatch
                                                                                       ) -> None:
    """An evaluation loop reset(seed=i), i = 0, 1, …, gets its episodes prepared in blocks of 1, 2, 4, … up to
    ``source.block``; a loop over scattered seeds pays for one episode per reset, not a block of 64."""
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    base = env.unwrapped
    sizes: list[int] = []
    prepare = base.prepare
    monkeypatch.setattr(base, "prepare", lambda episodes: sizes.append(len(episodes)) or prepare(episodes))
    for i in range(16):
        env.reset(seed=i)
    assert sizes == [1, 2, 4, 8, 16] and base.source.block >= 16  # seeds 0, 1–2, 3–6, 7–14, 15–30
    del sizes[:]
    for seed in (100, 50, 7, 300):
        env.reset(seed=seed)
    first = env.reset()[1]["track"]["noise_seed"]  # the rest of seed 300's block, prepared together
    rng = np.random.default_rng(300)
    rng.integers(2**62)
    assert sizes == [1, 1, 1, 1, base.source.block - 1] and first == int(rng.integers(2**62))


def test_an_episode_read_ahead_is_handed_out_once() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    for seed in range(3):  # seed 2's episode is read ahead with seed 1's
        env.reset(seed=seed)
    env.unwrapped.episode.y[:] = 0.0  # a caller writing into the episode it got
    env.reset(seed=2)
    assert np.abs(env.unwrapped.episode.y).min() > 0  # prepared afresh, not the episode handed out before


@pytest.mark.parametrize(("backend", "source"), [*((b, "sim") for b in BACKENDS),
                                                  *(pytest.param(b, "mix", marks=needs_otb) for b in ("ufir_cmn", "kf_cmn"))])
def test_an_episode_read_ahead_equals_a_fresh_envs(backend: str, source: str) -> None:
    """reset(seed=s) gives the episode, observation, step and the following unseeded episodes of a fresh env's
    reset(seed=s), bit for bit, whatever came before (read ahead, prepared alone, or after other resets)."""
    env = _make("bboxtune/FilterTune-v0", backend, source)
    action = np.full(env.action_space.shape, -0.2, np.float32)

    def run(e: gym.Env, seed: int) -> list:
        obs, info = e.reset(seed=seed)
        _, reward, *_, step_info = e.step(action)
        return [obs, info, reward, step_info, e.reset()[0]]

    for seed in [*range(9), 4, 20, 21, 22, 2]:
        got, fresh = run(env, seed), run(_make("bboxtune/FilterTune-v0", backend, source), seed)
        np.testing.assert_array_equal(got[0], fresh[0])
        np.testing.assert_array_equal(got[4], fresh[4])
        assert got[1:4] == fresh[1:4]


OPS = st.lists(st.tuples(st.sampled_from(["seed", "next", "pinned", "seeded pinned"]), st.integers(0, 12)),
               min_size=1, max_size=12)


@settings(max_examples=25, deadline=None)
@given(ops=OPS)
def test_any_mix_of_resets_gives_the_episodes_of_fresh_envs(ops: list[tuple[str, int]]) -> None:
    """Whatever the order of reseeds (consecutive runs read ahead, repeats, jumps), unseeded and pinned resets, each
    episode is the one a fresh env gives: reset(seed=s) (pinned or not) and the unseeded resets after it are those of
    a fresh env reset so; a pinned episode is the fresh env's pinned episode (bit for bit, observation and info)."""
    make = lambda: _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")  # noqa: E731
    env, shadow = make(), None
    for op, value in ops:
        if op == "seed":
            got, shadow = env.reset(seed=value), make()
            want = shadow.reset(seed=value)
        elif op == "next":
            got = env.reset()
            if shadow is None:  # an unseeded env: only the shape of the sequence is checked elsewhere
                continue
            want = shadow.reset()
        elif op == "pinned":
            got, want = env.reset(options={"noise_seed": value}), make().reset(options={"noise_seed": value})
        else:  # a pinned episode that reseeds: the unseeded sequence restarts from the seed
            got, shadow = env.reset(seed=value, options={"noise_seed": 7}), make()
            want = shadow.reset(seed=value, options={"noise_seed": 7})
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1] == want[1]


def test_noise_seed_pins_the_episode() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    a, _ = env.reset(seed=1, options={"noise_seed": 77})
    b, _ = env.reset(seed=2, options={"noise_seed": 77})
    c, _ = env.reset(seed=1, options={"noise_seed": 78})
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@needs_otb
def test_sequence_option_pins_otb_episode() -> None:
    env = _make("bboxtune/FilterTune-v0", "kf_cmn", "otb")
    _, info = env.reset(seed=0, options={"sequence": "Car4", "noise_seed": 3})
    assert info["track"]["sequence"] == "Car4"
    with pytest.raises(ValueError, match="Nope"):
        env.reset(options={"sequence": "Nope"})


@pytest.mark.parametrize("backend", filters.NAMES)
def test_rule_action_reproduces_the_rule(backend: str) -> None:
    env = _make("bboxtune/FilterTune-v0", backend, "sim")
    env.reset(seed=4)
    u = env.unwrapped
    nominal = u.episode.nominal
    rule = {"psi": nominal.psi, "horizon": nominal.horizon, "sigma_w": nominal.sigma_w, "sigma_v": nominal.sigma_v}
    action = u.action_map.to_actions(rule, nominal)[0]
    _, reward, _, _, info = env.step(action.astype(np.float32))
    assert reward == pytest.approx(0.0, abs=1e-9)
    assert info["rmse"] == pytest.approx(info["rule_rmse"], rel=1e-9)


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn", "oufir"])
def test_score_equals_step(backend: str) -> None:
    env = _make("bboxtune/FilterTune-v0", backend, "sim")
    env.reset(seed=9)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (6, env.action_space.shape[0])).astype(np.float32)
    batch = env.unwrapped.score(actions)
    for i, a in enumerate(actions):
        env.reset(seed=9)
        _, reward, _, _, info = env.step(a)
        assert reward == pytest.approx(batch["reward"][i], rel=1e-10, abs=1e-12)
        assert info["rmse"] == pytest.approx(batch["rmse"][i], rel=1e-10)
        assert info["success_auc"] == pytest.approx(batch["success_auc"][i], abs=1e-12)


def test_reward_is_log_rmse_ratio_and_info_keys() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    env.reset(seed=2)
    _, reward, terminated, truncated, info = env.step(np.array([0.5, 0.2], np.float32))
    assert terminated and not truncated
    assert reward == pytest.approx(np.log(info["rule_rmse"] / info["rmse"]))
    for key in ("rmse", "rule_rmse", "success_auc", "rule_success_auc", "n_frames", "params"):
        assert key in info
    assert set(info["params"]) == {"psi", "horizon"} and isinstance(info["params"]["horizon"], int)
    assert set(info["track"]) == {"sequence", "noise_seed", "tau"}
    assert info["scenario"] == env.unwrapped.episode.scenario and set(info["scenario"]) == {"psi", "sigma_w", "sigma_xi"}


@pytest.mark.parametrize("reward", ["iou_precision", "success_auc"])
def test_bounded_rewards_are_differences_to_the_rule(reward: str) -> None:
    env = _make("bboxtune/FilterTune-v0", "kf_cmn", "sim", reward=reward)
    env.reset(seed=3)
    _, r, *_, info = env.step(np.zeros(3, np.float32))
    assert r == pytest.approx(info[reward] - info[f"rule_{reward}"])


@pytest.mark.parametrize("reward", ["rmse", "success_auc"])
def test_a_raw_reward_baseline_measures_against_the_measurements_and_keeps_the_best_action(reward: str) -> None:
    rule_env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim", reward=reward)
    raw_env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim", reward=reward, reward_baseline="raw")
    actions = np.concatenate([-np.ones((1, 2)), np.random.default_rng(1).uniform(-1, 1, (6, 2))])
    for env in (rule_env, raw_env):
        env.reset(options={"noise_seed": 4})
    by_rule, by_raw = rule_env.unwrapped.score(actions), raw_env.unwrapped.score(actions)
    np.testing.assert_array_equal(by_raw[reward], by_rule[reward])  # the same estimates, other reference
    shift = by_raw["reward"] - by_rule["reward"]
    np.testing.assert_allclose(shift, shift[0], atol=1e-12)  # a constant per episode: the same best action
    assert abs(by_raw["reward"][0]) < 1e-9  # ψ = 0, N = 2 reproduces the measurements (ufir_cmn)
    rule_info = rule_env.step(actions[3].astype(np.float32))[-1]
    raw_env.reset(options={"noise_seed": 4})
    _, r, *_, info = raw_env.step(actions[3].astype(np.float32))
    assert r == pytest.approx(by_raw["reward"][3])
    assert info[f"rule_{reward}"] == rule_info[f"rule_{reward}"]  # the info still reports the rule's scores


def test_reward_labels_name_the_metric_and_the_reference() -> None:
    assert reward_label("rmse") == "log(RMSE_rule/RMSE)" and reward_label("rmse", "raw") == "log(RMSE_raw/RMSE)"
    assert reward_label("success_auc", "raw") == "success_auc minus the raw's"


def test_a_raw_reward_baseline_is_refused_by_the_retune_env_and_others_everywhere() -> None:
    with pytest.raises(ValueError, match="reward_baseline='raw' with FilterRetune-v0; allowed: 'rule'"):
        gym.make("bboxtune/FilterRetune-v0", reward_baseline="raw")
    with pytest.raises(ValueError, match="reward_baseline"):
        gym.make("bboxtune/FilterTune-v0", reward_baseline="truth")


@pytest.mark.parametrize("source", ["sim", pytest.param("otb_tracker", marks=needs_otb)])
def test_the_msd_feature_set_appends_one_entry_and_changes_nothing_else(source: str) -> None:
    """``features="msd"``: the 21st entry is ``msd_feature`` of the episode's measurements; the 20 before it, the
    episode and the reward are those of the base env (a block's episode and a pinned one); the batched env's rows
    are the single env's; gym's and SB3's checkers pass."""
    from bboxtune.envs.episodes.features import box_scale, msd_feature
    base, msd = (_make("bboxtune/FilterTune-v0", "ufir_cmn", source, **kw) for kw in ({}, {"features": "msd"}))
    assert msd.observation_space.shape == (21,) and base.observation_space.shape == (20,)
    action = np.array([0.3, -0.2], np.float32)
    for options in ({}, {"noise_seed": 7}):
        obs_b, _ = base.reset(seed=3, options=options)
        obs_m, _ = msd.reset(seed=3, options=options)
        np.testing.assert_array_equal(obs_m[:20], obs_b)
        y = msd.unwrapped.episode.y[None]
        assert obs_m[20] == pytest.approx(msd_feature(y, np.log(box_scale(y)))[0], rel=1e-6)
        assert base.step(action)[1] == msd.step(action)[1]
    gym_check_env(msd.unwrapped, skip_render_check=True)
    sb3_check_env(msd.unwrapped, warn=True)
    venv = envs.make_vec("bboxtune/FilterTune-v0", 3, backend="ufir_cmn", source=source, features="msd",
                         **({"otb_root": OTB_ROOT} if source != "sim" else SHORT))
    obs, infos = venv.reset(seed=0)
    assert obs.shape == (3, 21)
    track = infos["track"]
    pinned, _ = msd.reset(options={"noise_seed": int(track["noise_seed"][1]),
                                   **({"sequence": track["sequence"][1]} if source != "sim" else {})})
    np.testing.assert_allclose(obs[1], pinned, rtol=1e-6)


@pytest.mark.parametrize(("value", "error"), [("extended", ValueError), (1, TypeError), (None, TypeError)])
def test_an_unknown_feature_set_is_refused_and_the_retune_env_refuses_msd(value: object, error: type[Exception]) -> None:
    with pytest.raises(error, match="features"):
        gym.make("bboxtune/FilterTune-v0", features=value)
    with pytest.raises(ValueError, match="features='msd' with FilterRetune-v0; allowed: 'base'"):
        gym.make("bboxtune/FilterRetune-v0", features="msd")


def test_observation_uses_measurements_only() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    obs, _ = env.reset(seed=5)
    u = env.unwrapped
    ep = u.episode
    from dataclasses import replace

    (_, _, again), = u.prepare([replace(ep, truth=ep.truth + 1000.0, scenario={"psi": 0.0, "sigma_w": 1e3, "sigma_xi": 1.0})])
    assert np.array_equal(again, obs)


@pytest.mark.parametrize("bad", [np.array([np.nan, 0.0]), np.array([0.0, np.inf]), np.array([2.0, 0.0]),
                                 np.array([-1.001, 0.0]), np.zeros((3, 2)), np.zeros((1, 2)), np.zeros((0, 2)),
                                 np.zeros((2, 1)), np.zeros(3), np.float32(0.0), [[0.0, 0.1], [0.2]]])
@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_bad_actions_raise_and_leave_the_episode_as_it_was(env_id: str, bad: np.ndarray) -> None:
    """Each entry of a step's action must be finite and within [-1, 1]; the action must have shape (d,):
    a batch (A, d) — before, FilterTune-v0 scored its row 0 — or an empty (0, d) is refused too."""
    env = _make(env_id, "ufir_cmn", "sim")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)
    good = np.array([0.3, -0.2], np.float32)
    _, reward, *_ = env.step(good)  # the same episode, still at its first decision
    env.reset(seed=0)
    assert env.step(good)[1] == reward


@pytest.mark.parametrize("bad, error", [(np.array(["a", "b"]), TypeError), (np.array([True, False]), TypeError),
                                        (np.array([0.5 + 1j, 0.0]), TypeError), (np.array([0.1, 2.0]), ValueError)])
def test_score_checks_its_batch(bad: np.ndarray, error: type) -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    env.reset(seed=0)
    with pytest.raises(error, match="action"):
        env.unwrapped.score(bad[None])
    with pytest.raises(ValueError, match="A >= 1"):
        env.unwrapped.score(np.zeros((0, 2)))
    assert env.unwrapped.score(np.zeros((3, 2)))["reward"].shape == (3,)


def test_out_of_range_action_is_not_clipped_beyond_float32_round_off() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir_cmn", "sim")
    env.reset(seed=0)
    edge = env.unwrapped.score(np.array([[1.0, -1.0], [1.0 + 5e-7, -1.0 - 5e-7]]))  # tolerance: clipped to ±1
    assert edge["reward"][0] == edge["reward"][1]
    with pytest.raises(ValueError, match="out of range"):
        env.unwrapped.score(np.array([[1.0 + 2e-6, 0.0]]))


def test_bad_arguments_fail_loudly() -> None:
    with pytest.raises(TypeError, match="bogus"):
        gym.make("bboxtune/FilterTune-v0", bogus=1)
    with pytest.raises(ValueError, match="backend"):
        gym.make("bboxtune/FilterTune-v0", backend="nope")
    with pytest.raises(ValueError, match="tune"):
        gym.make("bboxtune/FilterTune-v0", backend="ufir", tune=("psi",))
    with pytest.raises(ValueError, match="reset option"):
        env = gym.make("bboxtune/FilterTune-v0", **SHORT)
        env.reset(options={"noise": 1})
    with pytest.raises(TypeError, match="track_length"):  # before: accepted by int(), then failed elsewhere
        gym.make("bboxtune/FilterTune-v0", track_length="100")
    with pytest.raises(TypeError, match="psi_range"):
        gym.make("bboxtune/FilterTune-v0", psi_range=(0.0, 0.5, 0.9))
    with pytest.raises(ValueError, match=r"track_length=100001.*100000"):
        gym.make("bboxtune/FilterTune-v0", track_length=100_001)
    with pytest.raises(TypeError, match="noise_seed"):
        gym.make("bboxtune/FilterTune-v0", **SHORT).reset(options={"noise_seed": "abc"})


@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_a_rejected_first_reset_leaves_the_env_usable(env_id: str) -> None:
    """Before, through Gymnasium's passive checker, every later step failed with ``TypeError: cannot unpack
    non-iterable NoneType`` once the first reset had raised."""
    env = gym.make(env_id, **SHORT)
    for bad, error in (({"noise_seed": -1}, ValueError), ({"noise_seed": 1.5}, TypeError), ({"sequence": 3}, TypeError),
                       ({"noise_seed": True}, TypeError), ("noise_seed", TypeError), ({"seed": 1}, ValueError)):
        with pytest.raises(error, match="noise_seed|sequence|options|'seed'"):
            env.reset(options=bad)
    with pytest.raises(TypeError, match="seed"):
        env.reset(seed="abc")
    with pytest.raises(RuntimeError, match="reset"):  # no episode yet
        env.step(np.zeros(env.action_space.shape, np.float32))
    fresh = gym.make(env_id, **SHORT)
    action = np.full(env.action_space.shape, 0.2, np.float32)
    np.testing.assert_array_equal(env.reset(seed=4)[0], fresh.reset(seed=4)[0])
    assert env.step(action)[1] == fresh.step(action)[1]


def test_step_after_episode_end_raises() -> None:
    env = _make("bboxtune/FilterTune-v0", "ufir", "sim")
    env.reset(seed=0)
    env.step(np.zeros(1, np.float32))
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(1, np.float32))


@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_render_rgb_array(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", **SHORT)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    img = env.render()
    assert img.dtype == np.uint8 and img.shape == (480, 960, 3)
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 4  # background + three colours


def test_sb3_vector_wrappers() -> None:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    venv = VecNormalize(make_vec_env("bboxtune/FilterTune-v0", n_envs=2, seed=0, env_kwargs=SHORT),
                        norm_obs=True, norm_reward=False)
    obs = venv.reset()
    for _ in range(3):
        obs, rewards, dones, infos = venv.step(np.zeros((2, 2), np.float32))
        assert obs.shape == (2, 20) and dones.all() and "episode" in infos[0]  # Monitor's episode summary


def test_fused_scores_equal_the_metric_functions() -> None:
    from bboxtune.envs.data import metrics
    from bboxtune.envs.data.boxes import cxcywh_to_xywh
    from bboxtune.envs.episodes.scoring import score_estimates

    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.uniform(50, 60, (80, 2)), rng.uniform(10, 20, (80, 2))])
    truth[[3, 40]] = np.nan
    est = truth[None] + rng.normal(0, 4, (3, 80, 4))
    est[:, 10] = np.nan  # no estimate yet: an IoU failure, not a detection, and not in the RMSE
    got = score_estimates(est, truth)
    p, g = cxcywh_to_xywh(est), cxcywh_to_xywh(truth)
    np.testing.assert_allclose(got["success_auc"], metrics.success_auc(p, g), rtol=1e-12)
    np.testing.assert_allclose(got["precision20"], metrics.precision_score(p, g), rtol=1e-12)
    np.testing.assert_allclose(got["iou_precision"], metrics.iou_precision(p, g).mean(axis=-1), rtol=1e-12)
    ok = np.isfinite(truth).all(axis=1)
    with_est = ok & np.isfinite(est[0]).all(axis=1)
    np.testing.assert_allclose(got["rmse"], metrics.rmse_total(est[:, with_est], truth[with_est]), rtol=1e-12)
    np.testing.assert_allclose(got["iou_mean"], np.nan_to_num(metrics.iou(p, g)[:, ok]).mean(axis=1), rtol=1e-12)


def test_scores_with_one_truth_per_row_equal_separate_calls() -> None:
    from bboxtune.envs.episodes.scoring import score_estimates

    rng = np.random.default_rng(3)
    truth = np.column_stack([rng.uniform(50, 60, (3, 60, 2)).reshape(-1, 2), rng.uniform(10, 20, (180, 2))]).reshape(3, 60, 4)
    truth[1, [4, 9]] = np.nan  # no ground truth on two frames of one row
    est = truth + rng.normal(0, 3, truth.shape)
    est[2, :5] = np.nan  # no estimate yet
    est[1, 4] = truth[0, 4]  # an estimate where there is no truth: not scored
    rows = score_estimates(est, truth)
    for b in range(3):
        alone = score_estimates(est[b:b + 1], truth[b])
        for key, value in alone.items():
            np.testing.assert_allclose(rows[key][b], value[0], rtol=1e-14)


@pytest.mark.parametrize("backend", ["ufir_cmn", "oufir", "kf_cmn"])
def test_run_tracks_equals_each_track_alone(backend: str) -> None:
    from bboxtune.envs.data.scenario_ranges import ScenarioRanges
    from bboxtune.envs.data.simulate import simulate
    from bboxtune.envs.episodes.scoring import run_positions, run_tracks

    rng = np.random.default_rng(2)
    tracks = [simulate(ScenarioRanges(n_frames=(T, T)).sample(rng), rng) for T in (90, 90, 70, 90)]
    params = {"psi": np.array([0.0, 0.5, 0.3, 0.8]), "horizon": np.array([10, 25, 40, 3]),
              "sigma_w": np.array([5.0, 20.0, 1.0, 50.0]), "sigma_v": np.array([1.0, 2.0, 0.5, 3.0])}
    ys = [t.y for t in tracks]
    ys[3][10:14] = np.nan
    together = run_tracks(backend, ys, [t.tau for t in tracks], params)
    for b, t in enumerate(tracks):
        alone = run_positions(backend, ys[b], t.tau, {k: v[b:b + 1] for k, v in params.items()})[0]
        np.testing.assert_allclose(together[b], alone, rtol=1e-12, atol=1e-9)


def test_fused_scores_on_threshold_boundaries() -> None:
    from bboxtune.envs.data import metrics
    from bboxtune.envs.data.boxes import cxcywh_to_xywh
    from bboxtune.envs.episodes.scoring import score_estimates

    truth = np.tile([10.0, 10.0, 4.0, 4.0], (3, 1))
    est = np.stack([truth, truth + [2.0, 0, 0, 0], truth + [4.0 / 3, 0, 0, 0]])  # IoU 1, 1/3, exactly 0.5
    got = score_estimates(est, truth)
    p, g = cxcywh_to_xywh(est), cxcywh_to_xywh(truth)
    np.testing.assert_allclose(got["success_auc"], metrics.success_auc(p, g), rtol=1e-12)
    np.testing.assert_allclose(got["iou_precision"], metrics.iou_precision(p, g).mean(axis=-1), rtol=1e-12)
    assert got["success_auc"][0] == pytest.approx(20 / 21) and got["iou_precision"][0] == 1.0


TRUTH_KEYS = {"psi", "sigma_w", "sigma_xi", "sigma_rel"}
VIDEO = {"source": "video", "detector": "regions", "video_pool": 2, "video_size": (128, 96), "track_length": 60}


def _numbers(value) -> list[float]:
    """Every real number inside ``value`` (nested dicts, tuples, lists)."""
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    if isinstance(value, (list, tuple)):
        return [x for v in value for x in _numbers(v)]
    return [float(value)] if isinstance(value, (int, float, np.number)) and not isinstance(value, bool) else []


def _derived(scenario: dict, tau: float) -> list[float]:
    """The true values and what follows from them alone: their logs and, for sim, the true N_opt and its log."""
    values = [float(v) for v in scenario.values()]
    if "sigma_xi" in scenario:
        values.append(float(filters.n_opt(scenario["sigma_xi"], scenario["sigma_w"], tau)))
    return values + [float(np.log(v)) for v in values if v > 0]


@pytest.mark.parametrize("source", ["sim", pytest.param("otb", marks=needs_otb),
                                    pytest.param("otb_tracker", marks=needs_otb), "video", pytest.param("mix", marks=needs_otb)])
@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_truth_only_after_the_decision(env_id: str, source: str) -> None:
    """Reset's info and the observations never hold a true scenario value (ψ, σ_w, σ_ξ, the relative CMN
    level) or anything derived from it; the step after the decision does — FilterTune-v0's one step,
    FilterRetune-v0's last one only."""
    kwargs = VIDEO if source == "video" else {"source": source, "otb_root": OTB_ROOT} if source != "sim" else dict(SHORT)
    if source == "mix":
        kwargs.update(SHORT, mix_weights=(1.0, 1.0, 2.0))
    env = gym.make(env_id, backend="kf_cmn", window=20, **kwargs)
    for noise_seed in range(4 if source == "mix" else 3):  # mix: seeds 0-3 draw each part
        obs, info = env.reset(options={"noise_seed": noise_seed})
        ep = env.unwrapped.episode
        assert bool(ep.scenario) == (ep.meta.get("source", source) in ("sim", "otb"))  # otb_tracker, video: no synthetic noise
        secret = _derived(ep.scenario, ep.tau)
        assert not TRUTH_KEYS & set(info["track"]) and set(info) == {"track"}
        shown = [obs]
        while True:
            assert not any(np.isclose(x, v, rtol=1e-6, atol=0) for x in _numbers(info) for v in secret), info
            obs, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
            shown.append(obs)
            if terminated:
                break
            assert "scenario" not in info
        assert info["scenario"] == ep.scenario
        values = np.concatenate(shown).astype(np.float64)
        for v in secret:
            assert not np.isclose(values, np.float32(v), rtol=1e-6, atol=0).any(), (v, values)
