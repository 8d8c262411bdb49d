"""Issue 35: a stopped command ends cleanly and a resumed run keeps its evaluation schedule.

* train.py: Ctrl-C (SIGINT) gives exactly one stderr line naming the checkpoint step and the resume command, exit
  status 130, no traceback (the rich progress bar used to add an ImportError one); the resume then completes.
* smooth.py --otb-root stopped by SIGTERM or SIGINT while scoring leaves no ``smooth-*`` temporary folder.
* bboxtune.agents.cli.command: every command's ``main`` turns both signals into one line and 128 + the signal.
* A run interrupted more often than --eval-freq evaluates at the same steps as an uninterrupted one.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from bboxtune.agents.cli import command
from bboxtune.agents.training.checkpoints import CHECKPOINTS, LATEST, resume_hint

from .tiny_run import REPO, TINY

OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset (CI: OTB_ROOT=../shared/data/otb)")
# TINY's run with --eval-freq 48: rollouts of 2 envs x 16 steps, so checkpoints (every 32 steps) fall between evaluations
SCHEDULED = [*TINY[:TINY.index("--eval-freq")], "--eval-freq", "48", "--eval-episodes", "4", "--checkpoint-freq", "32"]


def start(script: str, argv: list[str], tmp_path: Path) -> subprocess.Popen:
    """scripts/<script> in a process of its own, SIGINT at its default (a shell's background job ignores it, and an
    ignored SIGINT is inherited), its temporary files in ``tmp_path/temp``."""
    temp = tmp_path / "temp"
    temp.mkdir(exist_ok=True)
    return subprocess.Popen([sys.executable, str(REPO / "scripts" / script), *argv], cwd=tmp_path,
                            env={**os.environ, "TMPDIR": str(temp)}, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def wait_for(proc: subprocess.Popen, ready, timeout: float = 240.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        assert proc.poll() is None, f"exited with {proc.returncode} first: {proc.stderr.read() if proc.stderr else ''}"
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def stop(proc: subprocess.Popen, signum: int) -> tuple[int, str]:
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def test_ctrl_c_stops_training_with_one_line_naming_the_resume_command(train: ModuleType, tmp_path: Path) -> None:
    run = tmp_path / "run"
    argv = [*TINY[:TINY.index("--timesteps")], "--timesteps", "100000", *TINY[TINY.index("--timesteps") + 2:]]
    proc = start("train.py", [*argv, "--out", str(run)], tmp_path)
    wait_for(proc, lambda: (run / CHECKPOINTS / LATEST).is_file())
    code, err = stop(proc, signal.SIGINT)
    step = max(int(p.name[5:]) for p in (run / CHECKPOINTS).glob("ckpt_*"))
    assert code == 130, err
    assert err.splitlines() == [f"train.py: interrupted at step {step}; resume with: python scripts/train.py --resume {run}"]
    train.run(["--resume", str(run), "--timesteps", str(step + 32)])
    assert (run / "model.zip").is_file() and (run / CHECKPOINTS / LATEST).read_text().strip() == f"ckpt_{step + 32:012d}"


def test_the_resume_hint_of_a_run_without_a_checkpoint(tmp_path: Path) -> None:
    assert resume_hint(tmp_path / "a b") == ("before its first checkpoint; resume with: python scripts/train.py --resume "
                                             f"'{tmp_path / 'a b'}' (it starts again from step 0)")


@needs_otb
@pytest.mark.parametrize(("signum", "code", "word"), [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_smooth_stopped_while_scoring_leaves_no_temporary_folder(signum: int, code: int, word: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = start("smooth.py", ["--results", f"{OTB_ROOT}/trackers/SiamFC", "--out", str(out), "--pretrained", "sim_ufir_cmn",
                               "--otb-root", str(OTB_ROOT)], tmp_path)
    folders = lambda: list((tmp_path / "temp").glob("smooth-*/smoothed/*.txt"))  # noqa: E731
    wait_for(proc, folders)  # the smoothed files are being written or scored
    status, err = stop(proc, signum)
    assert status == code and err.endswith(f"\nsmooth.py: {word}\n") and "Traceback" not in err, err  # after tqdm's bar
    assert list((tmp_path / "temp").iterdir()) == [] and not out.exists()


@pytest.mark.parametrize(("signum", "code", "line"), [(signal.SIGINT, 130, "test_interrupts.py: interrupted\n"),
                                                      (signal.SIGTERM, 143, "test_interrupts.py: terminated\n")])
def test_command_turns_a_signal_into_one_line_and_runs_cleanup(signum: int, code: int, line: str,
                                                                capsys: pytest.CaptureFixture) -> None:
    cleaned = []

    def main(argv: list[str] | None = None) -> int:  # the prog is named after the module: test_interrupts.py
        try:
            os.kill(os.getpid(), signum)
            time.sleep(10)  # the signal arrives here
            return 0
        finally:
            cleaned.append(True)

    before = signal.getsignal(signal.SIGTERM)
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's Ctrl-C, even where pytest ignores it
    try:
        assert command(main)([]) == code and cleaned == [True]
    finally:
        signal.signal(signal.SIGINT, saved)
    assert capsys.readouterr().err == line and signal.getsignal(signal.SIGTERM) is before


def eval_steps(run: Path) -> list[int]:
    with np.load(run / "evaluations.npz") as data:
        return data["timesteps"].tolist()


def test_a_run_resumed_after_each_checkpoint_evaluates_at_the_uninterrupted_steps(train: ModuleType, tmp_path: Path) -> None:
    """Stopped at every checkpoint (32 steps, less than --eval-freq 48: before, such a run was never evaluated)."""
    whole = train.run([*SCHEDULED, "--timesteps", "128", "--out", str(tmp_path / "whole")])
    assert eval_steps(whole) == [48, 96]
    run = train.run([*SCHEDULED, "--timesteps", "32", "--out", str(tmp_path / "stopped")])
    for total in (64, 96, 128):
        train.run(["--resume", str(run), "--timesteps", str(total)])
    assert eval_steps(run) == [48, 96]
    curve = (run / "eval_curve.csv").read_text().splitlines()
    assert [int(re.split(",", row)[0]) for row in curve[1:]] == [48, 96]
