"""train.py refuses a run that would not fit in memory before writing anything (config.yml, command.txt, train.lock):
one line naming --n-envs / --hyperparams, exit 2 (the contract is in ``cli_misuse.py``). compare.py's --episodes
cases are in ``test_compare_cli.py``."""

from __future__ import annotations

import pytest

from bboxtune.agents.commands import train
from bboxtune.envs.data import memory

from .cli_misuse import check_misuse, misuse

GIB = 2**30


@pytest.mark.parametrize("case", [
    misuse("--n-envs", "1000000", mentions="--n-envs / --hyperparams: n_envs=1000000 with n_steps=32 (ppo, vec_env "
                                           "batched) needs ~"),  # ~220 GiB: died of MemoryError after writing files
    misuse("--algo", "sac", "--hyperparams", "buffer_size:100000000000",
           mentions="--n-envs / --hyperparams: n_envs=1 with buffer_size=100000000000 (sac, vec_env dummy) needs ~"),
], ids=str)
def test_a_run_beyond_memory_is_refused_before_anything_is_written(case, misuse_paths, capsys, monkeypatch):
    monkeypatch.setattr(memory, "available_bytes", lambda: 64 * GIB)  # the same on every machine
    line = check_misuse(train.main, case, misuse_paths, capsys, monkeypatch)
    assert line.endswith("this machine has 64 GiB available (see --help)")


def test_the_machines_own_figure_refuses_a_million_envs(misuse_paths, capsys, monkeypatch):
    line = check_misuse(train.main, misuse("--n-envs", "1000000"), misuse_paths, capsys, monkeypatch)
    assert "GiB, this machine has" in line
