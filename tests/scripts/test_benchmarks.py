"""scripts/bench_env.py runs end to end on tiny sizes (no assertion on speed)."""

from __future__ import annotations

import re

from .tiny_run import load_script


def test_bench_env_prints_its_three_rates(capsys):
    load_script("bench_env").main(["--episodes", "4", "--calls", "1", "--candidates", "3", "--repeat", "2",
                                   "--track-length", "60"])
    out = capsys.readouterr().out
    for label in ("[1] gym.make + reset + step", "[2] batched score()", "[3] the filter alone"):
        line = next(l for l in out.splitlines() if l.startswith(label))
        assert re.search(r"[\d,]+ \([\d,]+\) (steps|episodes)/s|[\d,]+ runs/s", line), line
