"""Bounds from memory (``bboxtune.envs.data.memory``): the available figure, the refusal at its exact edge, and the
estimates of the batched env and of ``score`` — at their edges against a pinned available figure, and within a
factor 2 above what tracemalloc measures."""

from __future__ import annotations

import os
import tracemalloc

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs
from bboxtune.envs.data import memory
from bboxtune.envs.data.memory import GIB, MemoryLimitError, check_fits
from bboxtune.envs.episodes.scoring import CANDIDATE_FRAME_BYTES_OTHER, SMALL_SCORING_BYTES, candidate_frame_bytes
from bboxtune.envs.vector import TUNE_ID, TuneBatch, batch_bytes

T = 50  # frames of the small episodes below


def pin_available(monkeypatch: pytest.MonkeyPatch, n_bytes: int | None) -> None:
    monkeypatch.setattr(memory, "available_bytes", lambda: n_bytes)


def test_available_bytes_reads_memavailable(tmp_path, monkeypatch):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       16384000 kB\nMemFree:          100000 kB\nMemAvailable:    2048000 kB\n")
    monkeypatch.setattr(memory, "MEMINFO", str(meminfo))
    assert memory.available_bytes() == 2048000 * 1024


def test_available_bytes_without_meminfo_falls_back_to_free_pages(tmp_path, monkeypatch):
    monkeypatch.setattr(memory, "MEMINFO", str(tmp_path / "missing"))
    assert memory.available_bytes() == os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def test_the_machine_reports_some_memory():
    available = memory.available_bytes()
    assert available is not None and 0 < available < 2**50


def test_check_fits_refuses_only_beyond_the_available_figure(monkeypatch):
    pin_available(monkeypatch, 3 * GIB)
    check_fits(3 * GIB, "n_envs=3")  # exactly what is available: accepted
    with pytest.raises(MemoryLimitError, match=r"^n_envs=4 needs ~3 GiB, this machine has 3 GiB available$"):
        check_fits(3 * GIB + 1, "n_envs=4")
    assert issubclass(MemoryLimitError, ValueError)
    pin_available(monkeypatch, None)  # unknown: nothing is refused
    check_fits(2**60, "n_envs=huge")


def test_make_vec_refuses_n_envs_beyond_memory_at_the_edge(monkeypatch):
    pin_available(monkeypatch, batch_bytes(4, T))
    venv = envs.make_vec(TUNE_ID, 4, backend="ufir_cmn", track_length=T)
    assert venv.reset(seed=0)[0].shape == (4, 20)
    with pytest.raises(MemoryLimitError, match=rf"^n_envs=5 \(episodes of up to {T} frames at once\) needs ~"):
        envs.make_vec(TUNE_ID, 5, backend="ufir_cmn", track_length=T)


def test_make_vec_of_ten_million_envs_is_refused_before_allocating():
    tracemalloc.start()
    try:
        with pytest.raises(MemoryLimitError, match=r"n_envs=10000000 .* GiB available"):
            envs.make_vec(TUNE_ID, 10**7, backend="ufir_cmn", track_length=200)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100 * 2**20  # the env's construction only, no episode


def edge_candidates(frames: int, per_frame: int) -> int:
    """The fewest candidates whose scoring estimate on ``frames`` frames exceeds SMALL_SCORING_BYTES (so it is checked)."""
    return SMALL_SCORING_BYTES // (frames * per_frame) + 1


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn", "ukf"])
def test_score_refuses_candidates_beyond_memory_at_the_edge(backend, monkeypatch):
    env = gym.make(TUNE_ID, backend=backend, track_length=T).unwrapped
    env.reset(seed=0)
    d = env.action_map.dim
    n = edge_candidates(T, candidate_frame_bytes(backend))
    pin_available(monkeypatch, n * T * candidate_frame_bytes(backend))
    assert env.score(np.zeros((n, d)))["reward"].shape == (n,)
    with pytest.raises(MemoryLimitError, match=rf"^actions: {n + 1} candidates × {T} frames needs ~"):
        env.score(np.zeros((n + 1, d)))


def test_score_of_a_million_actions_is_refused():
    env = gym.make(TUNE_ID, backend="ufir_cmn", track_length=200).unwrapped
    env.reset(seed=0)
    with pytest.raises(MemoryLimitError, match=r"^actions: 1000000 candidates × 200 frames needs ~"):
        env.score(np.zeros((10**6, 2)))


def test_a_small_scoring_reads_no_memory_figure(monkeypatch):
    """At most SMALL_SCORING_BYTES (a step's one candidate) is accepted without reading the available memory; one
    candidate more is checked against it."""
    env = gym.make(TUNE_ID, backend="ufir_cmn", track_length=T).unwrapped
    env.reset(seed=0)
    n = edge_candidates(T, CANDIDATE_FRAME_BYTES_OTHER) - 1
    monkeypatch.setattr(memory, "available_bytes", lambda: pytest.fail("available_bytes read for a small scoring"))
    assert env.score(np.zeros((n, 2)))["reward"].shape == (n,)
    env.step(np.zeros(2, np.float32))
    pin_available(monkeypatch, 0)
    with pytest.raises(MemoryLimitError, match=rf"^actions: {n + 1} candidates × {T} frames needs ~"):
        env.score(np.zeros((n + 1, 2)))


@pytest.mark.parametrize("name", ["score_rest", "score"])
def test_retune_scores_refuse_candidates_beyond_memory(name, monkeypatch):
    env = gym.make("bboxtune/FilterRetune-v0", backend="ufir_cmn", track_length=200).unwrapped
    env.reset(seed=0)
    frames = 200 - env.config.window if name == "score_rest" else env.config.window  # from the first window on
    n = edge_candidates(frames, CANDIDATE_FRAME_BYTES_OTHER)
    pin_available(monkeypatch, n * frames * CANDIDATE_FRAME_BYTES_OTHER)
    getattr(env, name)(np.zeros((n, 2)))
    with pytest.raises(MemoryLimitError, match=rf"^actions: {n + 1} candidates × {frames} frames"):
        getattr(env, name)(np.zeros((n + 1, 2)))


def traced_peak(run) -> int:
    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize(("n", "frames"), [(256, 10), (128, 400)])
def test_the_batch_estimate_is_within_a_factor_2_above_the_measured_peak(n, frames):
    """A whole cycle (construction, reset, step, the next reset) of the back end with the most memory per frame."""

    def cycle() -> None:
        batch = TuneBatch(n, backend="kf_cmn", track_length=frames)
        batch.seed(0)
        batch.reset()
        batch.step(np.zeros((n, batch.env.action_map.dim)))
        batch.reset()

    measured = traced_peak(cycle)
    assert measured <= batch_bytes(n, frames) <= 2 * measured, (measured, batch_bytes(n, frames))


@pytest.mark.parametrize("backend", ["ukf", "kf_cmn", "ufir_cmn", "fir", "bytetrack_kf"])
def test_the_score_estimate_is_within_a_factor_2_above_the_measured_peak(backend):
    env = gym.make(TUNE_ID, backend=backend, track_length=200).unwrapped
    env.reset(seed=0)
    actions = np.zeros((200, env.action_map.dim))
    measured = traced_peak(lambda: env.score(actions))
    estimate = 200 * 200 * candidate_frame_bytes(backend)
    assert measured <= estimate <= 2 * measured, (measured, estimate)


@pytest.mark.skipif(not (os.environ.get("OTB_ROOT") and os.environ.get("MOT_ROOT")), reason="needs $OTB_ROOT and $MOT_ROOT")
def test_max_frames_is_the_longest_episode_each_source_draws():
    env = gym.make(TUNE_ID, source="mix", mix_weights=(1, 1, 1, 1), track_length=T, split="val").unwrapped
    parts = env.source.parts
    longest = {name: max(len(part.draw(s, 0).y) for s in part.sequences) for name, part in parts.items() if name != "sim"}
    assert {name: part.max_frames() for name, part in parts.items()} == {"sim": T, **longest}
    assert env.source.max_frames() == max(T, *longest.values())
