"""Generated command lines of every command, run in-process against the misuse contract (:mod:`.cli_misuse`).

Shared by ``test_command_fuzz.py`` (pytest) and ``fuzz_tally.py`` (counts per command). :func:`cases` is a
Hypothesis strategy of :class:`Case`: for each flag of the command's parser (captured from its ``main``, whatever
builds it) a value drawn from valid-looking values, boundaries, huge, negative, non-finite, non-ASCII digits,
empty and long (10 kB) strings, and for file and folder flags paths to missing files, placeholder files of
:func:`.cli_misuse.make_misuse_paths` or files and folders with generated contents (:mod:`.fuzz_files`).

:func:`run_case` runs one case in a fresh temporary folder with the command's work stubbed (:data:`COMMANDS`:
the functions that start the work after validation raise :class:`ReachedWork`) and returns an :class:`Outcome`:

* ``refused`` — the contract of a refused command line: exit status 2, one stderr line naming a flag, a file
  or ``$OTB_ROOT`` / ``$MOT_ROOT``, no traceback, nothing created, changed or removed under the folder;
* ``reached`` — the work stub was reached and nothing but empty folders (the output folder) was created before;
* ``violation`` — anything else (an exception, another exit status, more stderr lines, files written, the run
  finishing without reaching a stub, more than :data:`CASE_SECONDS`), with a one-line ``category``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import inspect
import io
import os
import re
import shlex
import shutil
import signal
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from bboxtune.agents import cli

from .cli_misuse import make_misuse_paths, refusal_problem, snapshot
from .fuzz_files import JUNK, KV_KEYS, number, path_value

CASE_SECONDS = 5.0  # a case that takes longer is a violation (the tests' Hypothesis deadline too)
HARD_SECONDS = 30  # SIGALRM stops a (near-)hang
REAL = {"otb": os.environ.get("OTB_ROOT") or "/nonexistent/otb", "mot": os.environ.get("MOT_ROOT") or "/nonexistent/mot"}
ENV_VARS = ("OTB_ROOT", "MOT_ROOT")


@dataclass(frozen=True)
class Command:
    """A command module, the functions (dotted names in the module) where its work starts, and how its command
    lines are generated: ``fixed`` arguments first; ``base`` arguments first in the cases that are meant to be
    valid (but for at most one value), ``valid_skip`` flags not generated in those; ``skip`` flags never generated
    (internal ones); ``avoid`` (flag, value) pairs never generated (valid, but their validation takes > 5 s)."""

    module: str
    stubs: tuple[str, ...]
    fixed: tuple[str, ...] = ()
    base: tuple[str, ...] = ()
    valid_skip: tuple[str, ...] = ()
    skip: tuple[str, ...] = ()
    avoid: tuple[tuple[str, str], ...] = ()


_REPRO = ("run_shmaliy_cmn", "run_mo_fir", "run_otb")
_COMPARE = ("fit_baselines", "compare_retune")
_RETUNE_ONLY = ("--oneshot-model", "--anchor-margin", "--val-episodes")  # each needs another flag
# allowed, but the episode plan takes minutes and memory grows: test_command_fuzz.KNOWN (the memory bounds work)
_HUGE_EPISODES = tuple((flag, v) for flag in ("--episodes", "--val-episodes") for v in ("1000000000", "1000000", "10000"))
_REPRO_PART = tuple(f"reproduce.{s}" for s in _REPRO)
COMMANDS: dict[str, Command] = {
    "train": Command("train", ("claim_run_dir", "train"), base=("--out", "{out}"), avoid=(("--source", "video"),),  # 18 s
                     valid_skip=("--resume", "--trust-pickle", "--tensorboard")),
    "compare": Command("compare", _COMPARE, base=("--model", "{run}", "--out", "{out}"),
                       valid_skip=("--model", "--env", *_RETUNE_ONLY), avoid=_HUGE_EPISODES),
    "compare_retune": Command("compare", _COMPARE, fixed=("--env", "bboxtune/FilterRetune-v0"), base=("--out", "{out}"),
                              skip=("--env",), valid_skip=("--model", "--gate", *_RETUNE_ONLY), avoid=_HUGE_EPISODES),
    "sweep": Command("sweep", ("run_sweep",)),
    "smooth": Command("smooth", ("publish_folder",), base=("--results", "{tracks}", "--out", "{out}"),
                      valid_skip=("--results", "--format")),
    "reproduce": Command("reproduce", _REPRO),
    "reproduce_otb": Command("reproduce_otb", _REPRO_PART),
    "reproduce_mo_fir": Command("reproduce_mo_fir", _REPRO_PART),
    "reproduce_shmaliy_cmn": Command("reproduce_shmaliy_cmn", _REPRO_PART),
    "otb_eval": Command("otb_eval", ("evaluate",)),
    "otb_motion": Command("otb_motion", ("fit",)),
    "mot_eval": Command("mot_eval", ("mot_eval.score_method",)),
    "mot_loso": Command("mot_loso", ("trained",), base=("--runs", "{out}/runs", "--out", "{out}")),
    "mot_fit": Command("mot_fit", ("noise_stats",)),
    "track_video": Command("track_video", ("detect",), base=("--synthetic", "--n-frames", "20"),
                           avoid=(("--n-frames", "100000"),),  # valid; the synthetic trajectories take about 6 s
                           valid_skip=("--video", "--frames", "--sequence", "--otb-root")),
    "video_table": Command("video_table", ("episodes",)),
    "video_camera": Command("video_camera", ("compare",)),
    "bench_env": Command("bench_env", ("gym.make",)),
    "bench_filters": Command("bench_filters", ("speed_sections", "wide_section", "long_section"), skip=("--child",)),
    "bench_train": Command("bench_train", ("timed",)),
    "bench_video": Command("bench_video", ("synthetic_video",)),
    "bench_track": Command("bench_track", ("make_tracker",)),
    "track_mot": Command("track_mot", ("track",), base=("--det", "{mot}/KITTI-13/det/det.txt", "--out", "{out}"),
                         valid_skip=("--det",)),
    "eval_mot": Command("eval_mot", ("mot_metrics.score",)),
    "track_loso": Command("track_loso", ("scores",), base=("--out", "{out}.csv")),
}
RUN = Path(__file__).resolve().parents[2] / "agents" / "pretrained" / "sim_ufir_cmn"  # {run}: a copy of this run
TRACKS = {"Car4.txt": "".join(f"{70 + k},{51 + k},107,87\n" for k in range(20)),
          "Suv.txt": "".join(f"{140 - k:.2f},{80 + k / 3:.2f},40,30\n" for k in range(12))}  # {tracks}: valid results


@dataclass(frozen=True)
class Case:
    """One generated run: arguments (placeholders of :class:`.cli_misuse.MisusePaths`, ``{root}``, ``{otb}``,
    ``{mot}``), files to create under the temporary folder (relative path → bytes) and environment variables."""

    command: str
    args: tuple[str, ...]
    files: tuple[tuple[str, bytes], ...] = ()
    env: tuple[tuple[str, str], ...] = ()

    def __str__(self) -> str:
        env = " ".join(f"{k}={shlex.quote(short(v))}" for k, v in self.env)
        return " ".join([env, f"{self.command}.py", *(shlex.quote(short(a)) for a in self.args)]).strip()


def short(text: str, n: int = 60) -> str:
    return text if len(text) <= n else f"{text[:20]}...({len(text)} chars)"


def squeeze(text: str) -> str:
    """``text`` with each run of over 20 equal characters (a generated long name) shortened."""
    return re.sub(r"(.)\1{20,}", lambda m: f"{m.group(1) * 3}...({len(m.group(0))} chars)", text)


@dataclass
class Outcome:
    kind: str  # refused / reached / violation
    category: str = ""  # a violation's kind, one line
    detail: str = ""
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)


class ReachedWork(BaseException):  # noqa: N818  (not an error: the case reached its work)
    """Raised by a stubbed work function."""


class CaseTimeout(BaseException):  # noqa: N818
    """Raised by SIGALRM after :data:`HARD_SECONDS`."""


class _Captured(BaseException):  # noqa: N818
    pass


def main_of(name: str) -> Callable[[list[str]], object]:
    return importlib.import_module(f"bboxtune.agents.commands.{COMMANDS[name].module}").main


@cache
def parser_of(name: str) -> argparse.ArgumentParser:
    """The parser ``main`` builds (most commands build it inline; captured at its first parse)."""
    original = argparse.ArgumentParser.parse_known_args

    def grab(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> Any:
        raise _Captured(self)

    argparse.ArgumentParser.parse_known_args = grab  # type: ignore[method-assign]
    try:
        main_of(name)([])
    except _Captured as got:
        return got.args[0]
    finally:
        argparse.ArgumentParser.parse_known_args = original  # type: ignore[method-assign]
    raise AssertionError(f"{name}: main() parsed no command line")


def warm_up(name: str) -> None:
    """Import the command and run its base command line once: lazy imports and first-call costs (loading a model,
    the first env) stay out of the cases' time bound."""
    parser_of(name)
    run_case(Case(name, (*COMMANDS[name].fixed, *COMMANDS[name].base)))


# --- values -------------------------------------------------------------------------------------------------------
def flag_kind(action: argparse.Action) -> str:
    kind = action.type
    qual = getattr(kind, "__qualname__", "")
    if kind in (cli.existing_file, cli.json_file, cli.yaml_file):
        return "file"
    if kind is cli.existing_dir:
        return "dir"
    if kind is cli.out_dir:
        return "out"
    if qual.startswith("int_range") or kind is int:
        return "int"
    if qual.startswith("float_range") or kind is float:
        return "float"
    if kind is cli.box_xywh:
        return "box"
    dest = action.dest
    if qual == "existing_path" or any(w in dest for w in ("root", "results", "tuned", "model", "gate", "cache")):
        return "any"
    if dest in ("hyperparams", "env_kwargs"):
        return "kv"
    return "text"


def _bounds(kind: Any) -> dict[str, Any]:
    """``low`` / ``high`` of an :func:`bboxtune.agents.cli.int_range` / ``float_range`` check (its closure)."""
    return inspect.getclosurevars(kind).nonlocals if callable(kind) and getattr(kind, "__closure__", None) else {}


EXTRA = ("--nope", "positional", "--out=", "-x")  # arguments no parser knows
VALID_TEXT = ("train", "test", "SiamFC,STRUCK", "auto", "Car4", "ppo", "ufir_cmn")
VALID_KV = {"hyperparams": ("learning_rate:0.001", "n_steps:64", "batch_size:32", "gamma:0.9", "n_envs:2"),
            "env_kwargs": ("track_length=100", "track_length:8", "psi_range=[0, 0.5]", "trackers=[SiamFC]")}


def one_value(action: argparse.Action, junk: bool) -> st.SearchStrategy[tuple[str, tuple]]:
    """A value for ``action``: a valid-looking one, or (``junk``) one of the values of the module docstring."""
    kind = flag_kind(action)
    bounds = _bounds(action.type)
    low, high = bounds.get("low"), bounds.get("high")
    if kind in ("file", "dir", "out", "any"):
        return path_value(kind, junk)
    if junk:
        if kind in ("int", "float"):
            base = number(kind)
        elif kind == "box":
            base = st.lists(number("float"), min_size=3, max_size=5).map(",".join) | st.sampled_from(["1e7,0,1,1", "0,0,0,1"])
        elif kind == "kv":
            base = st.tuples(st.sampled_from(KV_KEYS), st.sampled_from(":="), number("float") | st.sampled_from(
                ["[0, 0.5]", "{a: 1}", "[", "null", "'x'", "[SiamFC]"]) | st.text(max_size=8)).map("".join)
        else:
            base = st.text(max_size=12)
        return (base | st.sampled_from(JUNK)).map(lambda v: (v, ()))
    if action.choices is not None:
        base = st.sampled_from(sorted(map(str, action.choices)))
    elif kind == "int":
        low = 0 if low is None else low
        base = st.integers(low, min(high if high is not None else low + 20, low + 20)).map(str) | st.sampled_from(
            [str(v) for v in (low, high) if v is not None])
    elif kind == "float":
        low = 0.0 if low is None else low
        hi = min(high if high is not None else low + 100, low + 100)
        base = st.floats(low, hi, exclude_min=bool(bounds.get("low_open"))).map(repr)
    elif kind == "box":
        base = st.sampled_from(["10,10,20,20", "0,0,5.5,3", "-3,4,100,50"])
    elif kind == "kv":
        base = st.sampled_from(VALID_KV.get(action.dest, ("x:1",)))
    else:
        base = st.sampled_from(VALID_TEXT)
    return base.map(lambda v: (v, ()))


@st.composite
def flag_args(draw: st.DrawFn, action: argparse.Action, junk: bool, avoid: frozenset[str] = frozenset()
              ) -> tuple[list[str], tuple]:
    flag = draw(st.sampled_from(action.option_strings))
    if action.nargs == 0:
        return [flag], ()
    n = 1 if action.nargs in (None, "?") else draw(st.integers(0 if action.nargs == "*" else 1, 3))
    if junk and action.nargs is None and draw(st.integers(0, 30)) == 0:
        n = 0  # the value missing
    values = [draw(one_value(action, junk).filter(lambda v: v[0] not in avoid)) for _ in range(n)]
    return [flag, *(v for v, _ in values)], tuple(f for _, files in values for f in files)


@st.composite
def cases(draw: st.DrawFn, name: str) -> Case:
    """A generated command line of command ``name`` (module docstring): all values valid-looking, one flag with a
    bad value, or any values (a third of the cases each)."""
    command = COMMANDS[name]
    actions = [a for a in parser_of(name)._actions if a.option_strings and a.help != argparse.SUPPRESS
               and not {"-h", *command.skip} & set(a.option_strings)]
    mode = draw(st.sampled_from(["valid", "one_bad", "wild"]))
    if mode != "wild":
        actions = [a for a in actions if not set(command.valid_skip) & set(a.option_strings)]
    chosen = [a for a in draw(st.permutations(actions))
              if draw(st.integers(0, 9)) < (9 if a.required else 1 if mode != "wild" else 3)]
    bad = draw(st.integers(0, max(len(chosen) - 1, 0)))
    args, files = [*command.fixed, *(command.base if mode != "wild" else ())], []
    for i, action in enumerate(chosen):
        junk = mode == "wild" and draw(st.booleans()) or mode == "one_bad" and i == bad
        avoid = frozenset(v for f, v in command.avoid if f in action.option_strings)
        more, made = draw(flag_args(action, junk, avoid))
        args += [a.replace("{root}/gen", f"{{root}}/gen{i}") for a in more]  # each flag's files in a folder of its own
        files += [(f"gen{i}/{p[4:]}", data) for p, data in made]
    if mode != "valid" and draw(st.integers(0, 40)) == 0:
        args.append(draw(st.sampled_from(EXTRA)))
    env = {var: draw(st.sampled_from(["{otb}", "{mot}", "{missing}", "{dir}", "{file}", ""]))
           for var in ENV_VARS if draw(st.integers(0, 3)) == 0}
    env = env if mode != "valid" else {var: "{" + var[:3].lower() + "}" for var in ENV_VARS if draw(st.booleans())}
    unique = dict(files)  # a later file of the same path wins
    return Case(name, tuple(args), tuple(sorted(unique.items())), tuple(sorted(env.items())))


# --- running one case ---------------------------------------------------------------------------------------------
def _resolve(module: Any, dotted: str) -> tuple[Any, str]:
    *path, attr = dotted.split(".")
    for part in path:
        module = getattr(module, part)
    return module, attr


def stub_reached(*args: Any, **kwargs: Any) -> Any:
    raise ReachedWork


def _alarm(signum: int, frame: Any) -> None:
    raise CaseTimeout


def _where(exc: BaseException) -> str:
    """``file:line`` of the innermost frame of the project (not of a library) in ``exc``'s traceback."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "/.venv/" not in f.filename
              and "site-packages" not in f.filename and "/lib/python" not in f.filename]
    last = frames[-1] if frames else traceback.extract_tb(exc.__traceback__)[-1]
    return f"{Path(last.filename).name}:{last.lineno}"


def run_case(case: Case) -> Outcome:
    """Run ``case`` (module docstring) in a fresh temporary folder; restores the working folder and environment."""
    command = COMMANDS[case.command]
    main = main_of(case.command)
    module = importlib.import_module(f"bboxtune.agents.commands.{command.module}")
    saved_env = {k: os.environ.get(k) for k in ENV_VARS}
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="fuzz") as tmp:
        paths = make_misuse_paths(Path(tmp))
        names = {**paths.names, "root": tmp, **REAL}
        if any("{run}" in a for a in case.args):
            shutil.copytree(RUN, Path(tmp, "run"))
        Path(tmp, "tracks").mkdir()
        for rel, text in TRACKS.items():
            Path(tmp, "tracks", rel).write_text(text)
        names.update(run=str(Path(tmp, "run")), tracks=str(Path(tmp, "tracks")))
        for rel, data in case.files:
            target = Path(tmp, rel)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        argv = [_format(a, names) for a in case.args]
        patches = [(*_resolve(module, s), None) for s in command.stubs]
        patches = [(obj, attr, getattr(obj, attr)) for obj, attr, _ in patches]
        out, err = io.StringIO(), io.StringIO()
        before = snapshot(Path(tmp))
        result, code = None, None
        old_handler = signal.signal(signal.SIGALRM, _alarm)
        start = time.perf_counter()
        try:
            os.chdir(paths.work)
            for k in ENV_VARS:
                os.environ.pop(k, None)
            os.environ.update({k: _format(v, names) for k, v in case.env})
            for obj, attr, _ in patches:
                setattr(obj, attr, stub_reached)
            signal.alarm(HARD_SECONDS)
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = main(argv)
        except SystemExit as exc:
            code = exc.code
        except ReachedWork:
            result = "reached"
        except CaseTimeout:
            result = Outcome("violation", f"no result within {HARD_SECONDS} s (hang)")
        except BaseException as exc:  # noqa: BLE001  (any exception is the finding)
            result = Outcome("violation", f"{type(exc).__name__} at {_where(exc)}", squeeze(
                f"{type(exc).__name__}: {exc}\n" + "".join(traceback.format_exception(exc)))[-3000:])
        finally:
            signal.alarm(0)
            signal.signal(signal.SIGALRM, old_handler)
            seconds = time.perf_counter() - start
            for obj, attr, original in patches:
                setattr(obj, attr, original)
            os.chdir(cwd)
            for k, v in saved_env.items():
                os.environ.pop(k, None) if v is None else os.environ.__setitem__(k, v)
        after = snapshot(Path(tmp))
        outcome = classify(case, result, code, err.getvalue(), before, after, argv, tmp)
    outcome.seconds = seconds
    if outcome.kind != "violation" and seconds > CASE_SECONDS:
        outcome = Outcome("violation", f"took {seconds:.1f} s (> {CASE_SECONDS:g} s)", outcome.kind, seconds)
    return outcome


def _format(text: str, names: dict[str, str]) -> str:
    for key, value in names.items():
        text = text.replace("{" + key + "}", value)
    return text


def classify(case: Case, result: Any, code: object, err: str, before: dict, after: dict, argv: list[str],
             root: str) -> Outcome:
    if isinstance(result, Outcome):
        return result
    if result == "reached":
        new = {p for p, v in after.items() if before.get(p) != v}
        if any(not after[p][0] for p in new) or set(before) - set(after):
            return Outcome("violation", "files written before the work started", str(sorted(new)[:5]))
        return Outcome("reached")
    if code in (0, None):
        return Outcome("violation", "finished without reaching the work stub", err[-300:])
    actions = {s: a for a in parser_of(case.command)._actions for s in a.option_strings if s not in ("-h", "--help")}
    paths = [v[:20] for k, v in zip(argv, argv[1:], strict=False) if k in actions and v
             and flag_kind(actions[k]) in ("file", "dir", "out", "any")]  # a long one may be shortened in the message
    unknown = [a.split("=")[0] for a in argv if a in EXTRA or a.startswith("-") and a not in actions]
    mentions = [*actions, root, "OTB_ROOT", "MOT_ROOT", *REAL.values(), *paths, *unknown]
    problem = refusal_problem(code, err, before, after, mentions)
    if problem is None:
        return Outcome("refused", detail=err.strip().replace(root, "{root}"))
    problem = problem.replace(root, "{root}")
    category = problem.split(":")[0] if not problem.startswith("exit status") else f"exit status {code!r}"
    if problem.startswith("traceback"):
        category = "traceback on stderr: " + err.strip().splitlines()[-1][:120]
    elif problem.startswith("none of"):
        category = "error line names no flag or file"
    return Outcome("violation", category, squeeze(f"{problem}\nstderr: {err.replace(root, '{root}')}")[-3000:])
