"""scripts/bench_env.py and scripts/bench_filters.py run end to end on tiny sizes (no assertion on speed); misuse
of bench_filters.py exits 2 with one line."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from bboxtune.agents.commands import bench_env, bench_filters, bench_train

from .tiny_run import REPO


def test_bench_env_prints_its_four_rates(capsys):
    bench_env.main(["--episodes", "4", "--calls", "1", "--candidates", "3", "--repeat", "2",
                    "--track-length", "60", "--n-envs", "4", "--vec-steps", "2", "--filterpy-tracks", "1"])
    out = capsys.readouterr().out
    for label in ("[1] gym.make + reset + step", "[2] batched score()", "[3] the filter alone", "[4] batched vec env"):
        line = next(s for s in out.splitlines() if s.startswith(label))
        assert re.search(r"[\d,]+ \([\d,]+\) (env steps|steps|episodes)/s|[\d,]+ runs/s", line), line


def test_bench_filters_prints_every_section(capsys):
    bench_filters.main(["--tracks", "6", "--frames", "60", "--repeat", "1", "--iter-tracks", "1",
                        "--horizon", "20", "--wide-tracks", "12", "--wide-frames", "40",
                        "--wide-horizon", "10", "--long-frames", "300", "--backends", "kf", "ofir"])
    out = capsys.readouterr().out
    assert re.search(r"\[1\] kf batched: [\d,]+ frame-updates/s.*ratio [\d,]+x", out)
    assert re.search(r"\[2\] ufir N=20 kernel: [\d,]+ points/s", out)
    assert all(re.search(rf"^    {name} +[\d,]+ ", out, re.MULTILINE) for name in ("kf", "ukf", "ofir"))
    number = r"[\d.]+ s \(cpu +[\d.]+ s\), peak RSS +\d+ MB"
    for name in ("kf", "ofir"):  # the case with gaps beside its gap-free peer, with the ratios
        assert re.search(rf"^    {name} +no gaps: +{number}", out, re.MULTILINE), out
    assert len(re.findall(rf"gaps: +{number} .* gaps/no gaps: time x[\d.]+ \(cpu x[\d.]+\), peak x[\d.]+", out)) == 2
    assert len(re.findall(rf"kf  +{number} .* ukf/kf: time x[\d.]+", out)) == 2  # without and with missing frames


@pytest.mark.parametrize("args", [["--tracks", "0"], ["--frames", "-3"], ["--wide-tracks", "1.5"],
                                  ["--long-frames", "abc"], ["--missing", "1.5"], ["--missing", "nan"],
                                  ["--wide-horizon", "1"], ["--horizon", "1"], ["--backends", "nope"],
                                  ["--sections", "everything"], ["--repeat", "0"], ["--bogus"]])
def test_bench_filters_misuse_exits_2_with_one_line(args):
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "bench_filters.py"), *args], capture_output=True,
                          text=True, timeout=120, cwd=REPO)
    assert done.returncode == 2, done.stderr
    assert done.stdout == "" and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "bench_filters.py: error:" in done.stderr


def test_bench_train_times_both_runs(capsys, tmp_path):
    bench_train.main(["--timesteps", "128", "--out", str(tmp_path / "run"), "--", "--hyperparams",
                      "n_steps:2", "--env-kwargs", "track_length=60"])
    out = capsys.readouterr().out
    assert re.search(r"\[1\] train.py, 128 steps: [\d.]+ s wall .* peak RSS [\d.]+ GB", out), out
    assert re.search(r"\[2\] SB3 PPO on CartPole-v1, 128 steps: [\d.]+ s wall", out), out
    assert re.search(r"train.py / CartPole: [\d.]+x", out) and (tmp_path / "run" / "model.zip").is_file()
