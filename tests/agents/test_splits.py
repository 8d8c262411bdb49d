"""Train / val / test noise-seed splits and the SplitSeeds wrapper."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune.agents.splits import RESERVED, SplitSeeds, eval_seeds, otb_episodes, split_of, split_seeds, train_seeds

from .conftest import ENV_ID, SHORT


def test_eval_splits_are_disjoint_and_outside_train() -> None:
    test, val = eval_seeds("test", 1000), eval_seeds("val", 1000)
    assert not set(test) & set(val)
    assert all(split_of(int(s)) == "test" for s in test) and all(split_of(int(s)) == "val" for s in val)
    assert np.all((test >= RESERVED[0]) & (test < RESERVED[1])) and np.all((val >= RESERVED[0]) & (val < RESERVED[1]))


def test_train_seeds_avoid_the_reserved_range() -> None:
    class Stubborn:
        """Returns a reserved seed first, then a free one: the redraw must happen."""

        def __init__(self) -> None:
            self.calls = 0

        def integers(self, high, size, dtype):
            self.calls += 1
            return np.full(size, RESERVED[0] if self.calls == 1 else 7, dtype=dtype)

    seeds = train_seeds(Stubborn(), 3)
    np.testing.assert_array_equal(seeds, [7, 7, 7])
    drawn = train_seeds(np.random.default_rng(0), 10_000)
    assert all(split_of(int(s)) == "train" for s in drawn)


@pytest.mark.parametrize("args", [("train", 3), ("val", -1), ("test", 10**9 + 1)])
def test_eval_seeds_bad_arguments(args: tuple[str, int]) -> None:
    with pytest.raises(ValueError, match="split|out of range"):
        eval_seeds(*args)


def test_wrapper_train_is_reproducible_and_val_cycles() -> None:
    env = SplitSeeds(gym.make(ENV_ID, **SHORT), split="train")
    _, a = env.reset(seed=3)
    _, b = env.reset(seed=3)
    _, c = env.reset()
    assert a["track"]["noise_seed"] == b["track"]["noise_seed"] != c["track"]["noise_seed"]
    assert split_of(c["track"]["noise_seed"]) == "train"
    val = SplitSeeds(gym.make(ENV_ID, **SHORT), split="val", cycle=2)
    seen = [val.reset(seed=0 if i == 0 else None)[1]["track"]["noise_seed"] for i in range(4)]
    assert seen == [*eval_seeds("val", 2), *eval_seeds("val", 2)]


def test_wrapper_passes_explicit_noise_seed() -> None:
    env = SplitSeeds(gym.make(ENV_ID, **SHORT), split="train")
    _, info = env.reset(options={"noise_seed": 42})
    assert info["track"]["noise_seed"] == 42


def test_split_seeds_seed_0_is_todays_set_and_other_seeds_other_reproducible_sets() -> None:
    np.testing.assert_array_equal(split_seeds("test", 50), eval_seeds("test", 50))
    a, b, c = split_seeds("test", 50, seed=1), split_seeds("test", 50, seed=1), split_seeds("test", 50, seed=2)
    np.testing.assert_array_equal(a, b)
    assert len(set(a)) == 50 and not set(a) & set(c) and not set(a) & set(eval_seeds("test", 50))
    assert all(split_of(int(s)) == "test" for s in a) and all(split_of(int(s)) == "val" for s in split_seeds("val", 9, 3))
    train = split_seeds("train", 40, seed=0)
    assert all(split_of(int(s)) == "train" for s in train) and len(set(train)) == 40
    assert not set(train) & set(train_seeds(np.random.default_rng(0), 1000))  # not the baselines' fitting episodes


def test_split_seeds_redraws_repeated_indices() -> None:
    first = np.random.default_rng((3, 1)).integers(10**9, size=40_000, dtype=np.int64)
    assert len(np.unique(first)) < 40_000  # seed 3's first draw repeats indices: the redraw must remove them
    seeds = split_seeds("val", 40_000, seed=3)
    assert len(np.unique(seeds)) == 40_000


@pytest.mark.parametrize("args", [("nope", 3, 0), ("test", -1, 0), ("test", 3, -1), ("val", 10**9 + 1, 1)])
def test_split_seeds_bad_arguments(args: tuple[str, int, int]) -> None:
    with pytest.raises(ValueError, match="split|n="):
        split_seeds(*args)


def test_otb_episodes_enumerate_sequences_seeds_and_trackers() -> None:
    eps = otb_episodes(("A", "B"), (), "test", seeds_per_sequence=3)
    assert [e.sequence for e in eps] == ["A"] * 3 + ["B"] * 3 and {e.tracker for e in eps} == {None}
    np.testing.assert_array_equal([e.noise_seed for e in eps], eval_seeds("test", 6))
    assert eps[0].options() == {"noise_seed": int(eval_seeds("test", 1)[0]), "sequence": "A"}
    other = otb_episodes(("A", "B"), (), "test", seeds_per_sequence=3, seed=4)
    assert [e.sequence for e in other] == [e.sequence for e in eps] and other[0].noise_seed != eps[0].noise_seed
    pairs = otb_episodes(("A", "B"), ("T1", "T2"), "val", has_output=lambda t, s: (t, s) != ("T2", "A"))
    assert [(e.sequence, e.tracker) for e in pairs] == [("A", "T1"), ("B", "T1"), ("B", "T2")]
    assert pairs[2].options()["tracker"] == "T2" and pairs[2].options()["sequence"] == "B"
    with pytest.raises(ValueError, match="seeds_per_sequence"):
        otb_episodes(("A",), ("T1",), "test", seeds_per_sequence=2)
