"""Train / val / test noise-seed splits and the SplitSeeds wrapper."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from agents.splits import RESERVED, SplitSeeds, eval_seeds, split_of, train_seeds

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
