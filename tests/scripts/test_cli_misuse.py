"""Misuse of the scripts' command lines: exit 2, one line naming the flag or file, no traceback, nothing written
(the contract and the placeholders are in ``cli_misuse.py``); and ``--help`` works for every script."""

from __future__ import annotations

import functools
import importlib
import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

from .cli_misuse import check_misuse, misuse, run_script

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"
COUNT = ("0", "-1", "abc", "1_0", "2.5")  # not integers >= 1 ("1_0" is 10 to int())

# The reproduction scripts share reproduce.py's parser; the parts take no --otb-root except reproduce_otb.
REPRODUCE_COMMON = [
    misuse(mentions="--out"),  # --out is required
    misuse("--quick", mentions="--out"),
    misuse("--quick", "--out", "{under_file}"),  # an output folder below a regular file
    misuse("--quick", "--out", "{file}"),  # a file where the output folder should be
    misuse("--quick", "--out", ""),
    *[misuse("--out", "{out}", "--mc", v) for v in ("0", "1", "-1", "abc", "1_0", "٣", "2.0", "10001")],
    misuse("--out", "{out}", "--mc"),  # the value is missing
    *[misuse("--out", "{out}", "--seed", v) for v in ("-1", "abc", "nan")],
    misuse("--out", "{out}", "--quick", "--unknown"),
    misuse("--ou", "{out}", "--quick", mentions="--ou"),  # flags are not abbreviated
]
OTB_ROOT_CASES = [
    misuse("--out", "{out}", "--quick", "--otb-root", "{missing}"),
    misuse("--out", "{out}", "--quick", "--otb-root", "{dir}"),  # no OTB layout in it
    misuse("--out", "{out}", "--quick", "--otb-root", "{file}"),  # not an OTB100.json
    misuse("--out", "{out}", "--quick", "--otb-root", "{bad_json}", mentions="{bad_json}:2"),  # malformed JSON
    misuse("--out", "{out}", "--quick", env={"OTB_ROOT": "{missing}"}, mentions="$OTB_ROOT"),
    misuse("--out", "{out}", "--quick", env={"OTB_ROOT": "{dir}"}, mentions="$OTB_ROOT"),
]
CASES: dict[str, list] = {
    "reproduce": REPRODUCE_COMMON + OTB_ROOT_CASES,
    "reproduce_shmaliy_cmn": REPRODUCE_COMMON + [misuse("--out", "{out}", "--otb-root", "{dir}")],
    "reproduce_mo_fir": REPRODUCE_COMMON + [misuse("--out", "{out}", "--otb-root", "{dir}")],
    "reproduce_otb": REPRODUCE_COMMON + OTB_ROOT_CASES + [misuse("--out", "{out}", "--quick", mentions="--otb-root")],
    "bench_env": [
        *[misuse(flag, v) for flag in ("--episodes", "--candidates", "--calls", "--repeat") for v in COUNT],
        *[misuse("--track-length", v) for v in ("3", "abc", "0")],  # the env needs >= 8 frames
        misuse("--seed", "-1"), misuse("--backend", "nope"), misuse("--episodes"), misuse("--epi", "3"),
        *[misuse(flag, v) for flag in ("--n-envs", "--vec-steps", "--filterpy-tracks") for v in COUNT],
    ],
    "sweep": [
        misuse("--out", "{file}", "--smoke", mentions="--out"), misuse("--smoke", mentions="--out"),
        misuse("--out", "{out}", "--seeds", "-1", mentions="--seeds"),
        misuse("--out", "{out}", "--seeds", "1", "1"), misuse("--out", "{out}", "--algos", "nope"),
        misuse("--out", "{out}", "--hyperparams", "learning_rate"), misuse("--out", "{out}", "--hyperparams", "lr:1,,2"),
        misuse("--out", "{dir}", "--resume", "--smoke", mentions="sweep.json"),
        misuse("--out", "{out}", "--cpus-per-trial", "0"),
        # checked before Ray starts: the hyperparameters (train.py's checks, per setting), CPUs, the address
        misuse("--out", "{out}", "--hyperparams", "bogus:1,2"), misuse("--out", "{out}", "--hyperparams", "learning_rate:nan"),
        misuse("--out", "{out}", "--hyperparams", "learning_rate:.inf"), misuse("--out", "{out}", "--hyperparams", "lr:1,1.0"),
        misuse("--out", "{out}", "--hyperparams", "learning_rate:lin_x"),
        misuse("--out", "{out}", "--hyperparams", "batch_size:1"),  # PPO's constructor refuses it
        misuse("--out", "{out}", "--hyperparams", "d:2020-01-01"),  # not a JSON value
        misuse("--out", "{out}", "--cpus-per-trial", "100"), misuse("--out", "{out}", "--cpus", "2", "--cpus-per-trial", "3"),
        misuse("--out", "{out}", "--smoke", "--seeds", "3"), misuse("--out", "{out}", "--trust-pickle"),
        misuse("--out", "{out}", "--address", "localhost:6379"), misuse("--out", "{out}", "--address", "ray://host"),
        misuse("--out", "{out}", "--address", "auto", "--cpus", "2", mentions="--cpus"),
        misuse("--out", "{out}", "--address", "auto", env={"RAY_TMPDIR": "{dir}"}),  # no cluster running: one line
        *([misuse("--out", "{out}", "--address", "ray://127.0.0.1:1", mentions="ray[client]")]
          if importlib.util.find_spec("grpc") is None else []),  # Ray Client not installed
    ],
    "bench_track": [*[misuse("--repeat", v) for v in COUNT], misuse("--filters", "nope"),
                    misuse("--mot-root", "{missing}"), misuse("--mot-root", "{dir}")],
    "bench_train": [*[misuse("--timesteps", v) for v in COUNT], misuse("--out", "{file}"), misuse("--out", "{under_file}")],
    "bench_video": [
        *[misuse(flag, v) for flag in ("--videos", "--frames") for v in COUNT],
        misuse("--frames", "2000000"), misuse("--frames", "100001"),  # beyond the envs' longest track
    ],
    "otb_motion": [
        misuse(mentions="--out"), misuse("--out", "{under_file}"), misuse("--out", "{file}"),
        misuse("--out", "{out}", mentions="--otb-root"),  # $OTB_ROOT unset
        misuse("--out", "{out}", "--otb-root", "{missing}"), misuse("--out", "{out}", "--otb-root", "{file}"),
        misuse("--out", "{out}", "--otb-root", "{dir}", mentions="--otb-root"),
        *[misuse("--out", "{out}", "--tracks", v) for v in COUNT], misuse("--out", "{out}", "--seed", "-1"),
    ],
    "eval_mot": [  # the cases that need results and ground truth are in test_eval_mot.py
        misuse(mentions="--results"), misuse("--results", "{missing}"), misuse("--results", "{file}"),
        misuse("--results", "{dir}", "--gt-root", "{missing}"), misuse("--results", "{dir}", "--gt-root", "{file}"),
        misuse("--results", "{dir}", "--gt-root", "{dir}"),  # no <SEQUENCE>/gt/gt.txt in it
        misuse("--results", "{dir}", "--gt-root", "{dir}", "--out", "{file}"),
        misuse("--resu", "{dir}", mentions="--resu"),  # flags are not abbreviated
    ],
    "track_loso": [  # the cases that need the MOT15 data are in test_track_loso.py
        misuse(mentions="--out"), misuse("--out", "{out}"),  # not a .csv name
        misuse("--out", "{file}"), misuse("--out", "{under_file}/loso.csv"),
        *[misuse("--out", "{out}.csv", "--boot", v) for v in ("99", "0", "-1", "abc", "nan", "1e9")],
        *[misuse("--out", "{out}.csv", "--seed", v) for v in ("-1", "abc", "2147483648")],
        misuse("--out", "{out}.csv", "--mot-root", "{missing}"), misuse("--out", "{out}.csv", "--mot-root", "{file}"),
        misuse("--out", "{out}.csv", "--mot-root", "{dir}", mentions="--mot-root"),  # no sequences.csv in it
    ],
    "video_camera": [
        *[misuse("--n-videos", v) for v in COUNT],
        *[misuse("--frames", v) for v in ("3", "0", "abc")],  # the env needs >= 8 frames
        *[misuse("--smoothing", v) for v in ("0", "-1", "nan", "inf", "abc")],
        misuse("--smoothing", "1", "-3"), misuse("--smoothing"),
        *[misuse(flag, v) for flag in ("--sigma-c", "--sigma-u", "--example-smoothing") for v in ("0", "-2", "inf")],
        misuse("--seed", "-1"), misuse("--detector", "surf"),
        misuse("--out", "{under_file}"), misuse("--out", "{file}"),
    ],
}
PARAMS = [pytest.param(name, case, id=f"{name}: {case}") for name, cases in CASES.items() for case in cases]
HELP = sorted(p.stem for p in SCRIPTS.glob("*.py"))  # every script is a command: bboxtune.agents.commands.<name>


def command(name: str) -> ModuleType:
    """The command module of ``scripts/<name>.py``."""
    return importlib.import_module(f"bboxtune.agents.commands.{name}")


def no_ray_running(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ray's ``address="auto"`` joins any Ray it finds among the machine's processes — such as the one
    tests/scripts/test_sweep.py starts on another xdist worker, whose shutdown then kills this one: the sweep cases
    see none (the cases' premise)."""
    if importlib.util.find_spec("ray") is not None:
        services = importlib.import_module("ray._private.services")
        monkeypatch.setattr(services, "find_gcs_addresses", functools.cache(lambda: []))  # Ray clears its cache


@pytest.mark.parametrize(("name", "case"), PARAMS)
def test_misuse_exits_2_with_one_line_and_writes_nothing(name, case, misuse_paths, capsys, monkeypatch):
    if name == "sweep":
        no_ray_running(monkeypatch)
    check_misuse(command(name).main, case, misuse_paths, capsys, monkeypatch)


@pytest.mark.parametrize("name", HELP)
def test_help_prints_usage_and_exits_0(name, capsys):
    with pytest.raises(SystemExit) as info:
        command(name).main(["--help"])
    out = capsys.readouterr().out
    assert info.value.code == 0
    assert out.startswith("usage: ") and "--help" in out  # in-process, prog is the script name only if it sets prog=


def test_every_script_is_covered():
    """A new script gets misuse cases here (or in its own test module, named in ELSEWHERE)."""
    elsewhere = {"train", "compare", "track_video", "otb_eval", "bench_filters", "video_table", "smooth", "mot_eval",
                 "mot_fit", "track_mot", "mot_loso"}  # their helpers' tests
    assert set(HELP) == set(CASES) | elsewhere


def test_reproduce_part_help_from_the_command_line(misuse_paths):
    """The issue's case: ``reproduce_shmaliy_cmn.py --help`` printed nothing (the other parts are wired the same)."""
    done = run_script("reproduce_shmaliy_cmn", "--help", cwd=misuse_paths.work)
    assert done.returncode == 0 and done.stdout.startswith("usage: reproduce_shmaliy_cmn.py [-h] --out DIR"), done.stderr


@pytest.mark.parametrize(("name", "args"), [
    ("reproduce", ("--out", "{under_file}", "--quick")),
    ("video_camera", ("--n-videos", "0")),
])
def test_misuse_from_the_command_line(name, args, misuse_paths):
    done = run_script(name, *(misuse_paths.format(a) for a in args), cwd=misuse_paths.work)
    assert done.returncode == 2 and done.stdout == ""
    (line,) = done.stderr.splitlines()
    assert line.startswith(f"{name}.py: error: argument {args[0]}") and "Traceback" not in done.stderr
    assert not any(misuse_paths.work.iterdir()) and not (misuse_paths.root / "out").exists()
