"""Command-line helpers of ``scripts/``: a parser whose errors are one line, and argparse ``type=`` checks.

Every script validates its whole command line before it does any work or writes anything:

* :class:`ArgumentParser` — ``error()`` prints exactly one line, ``<prog>: error: <message> (see --help)``,
  and exits 2 (argparse's default prints the usage block first); flags are never abbreviated
  (``allow_abbrev=False``); :class:`HelpFormatter` shows the module docstring as written and appends real
  defaults.
* ``type=`` functions (argparse puts ``argument --flag:`` before their message): :func:`int_range`
  (:data:`positive_int`, :data:`nonnegative_int`), :func:`float_range` (:data:`positive_float`) — numbers in
  the grammar of :mod:`bboxtune.envs.data.number_grammar` (ASCII decimals: no ``1_0``, no non-ASCII digits, no
  ``nan``/``inf``); :func:`existing_file`, :func:`existing_dir`, :func:`out_dir` (a folder that exists and is
  writable, or can be created; nothing is created here), :func:`new_file` (a file that does not exist yet, in a
  writable folder), :func:`json_file`, :func:`yaml_file` (parsed; errors name ``file:line:column``); a path with a
  name longer than 255 bytes is refused by each;
  :func:`box_xywh` (``x,y,w,h`` with w, h > 0, \\|x\\|, \\|y\\|, w, h <= 1e7 px).
* :func:`bboxtune.agents.readers.read_json`, :func:`~bboxtune.agents.readers.read_yaml` — the same readers for
  files a script finds itself (ValueError naming ``file:line:column``); :func:`argument_errors` turns the ValueError
  / OSError of a semantic check
  (constructing a config, opening a dataset) into a one-line error naming the flag.
* :func:`key_values` — ``KEY=VALUE`` / ``KEY:VALUE`` items (``--env-kwargs`` of train.py and compare.py,
  ``--hyperparams``) into a dict of YAML values.
* :func:`command` — every command's ``main`` (so both ``scripts/<name>.py`` and the ``bboxtune-<name>`` console
  scripts) is wrapped in it: Ctrl-C (SIGINT) or SIGTERM ends the command with one line on stderr,
  ``<name>.py: interrupted`` (``terminated``; a command may add what to do next: :class:`Interrupted`), exit
  status 130 (SIGTERM: 143), no traceback; SIGTERM is raised as an exception like Ctrl-C, so ``finally`` blocks
  and ``with tempfile.TemporaryDirectory()`` remove what the command had in progress.
"""

from __future__ import annotations

import argparse
import functools
import os
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, NoReturn, ParamSpec

import yaml

from bboxtune.agents.readers import read_json, read_yaml
from bboxtune.envs.data.boxes import COORD_RULE, MAX_COORD
from bboxtune.envs.data.number_grammar import parse_float, parse_int, shorten
from bboxtune.envs.data.otb import TRACKER_SPLIT


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser with one-line errors (``<prog>: error: <message> (see --help)``, exit status 2) and,
    by default, no abbreviated flags (``--ou`` is not ``--out``)."""

    def __init__(self, *args: Any, allow_abbrev: bool = False, **kwargs: Any) -> None:
        kwargs["allow_abbrev"] = allow_abbrev
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        line = " ".join(str(message).split())  # a message with newlines still gives one line
        self.exit(2, f"{self.prog}: error: {line} (see --help)\n")


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Shows the description as written and appends real defaults (not None/False/empty) to the help."""

    def _get_help_string(self, action: argparse.Action) -> str:
        default = action.default
        shown = not (default is None or default is False or default == [] or default == argparse.SUPPRESS)
        if action.help and shown and "%(default)" not in action.help:
            return action.help + " (default: %(default)s)"
        return action.help or ""


@contextmanager
def argument_errors(parser: argparse.ArgumentParser, flag: str) -> Iterator[None]:
    """Inside the block, a ValueError or OSError becomes ``parser.error("<flag>: <message>")`` (exit 2)."""
    try:
        yield
    except (ValueError, OSError) as exc:
        parser.error(f"{flag}: {exc}")


def int_range(low: int, high: int | None = None) -> Callable[[str], int]:
    """``type=`` for an integer in [low, high] (high None: no upper bound), ASCII digits with an optional sign."""
    allowed = f"integers >= {low}" if high is None else f"integers {low}..{high}"

    def parse(text: str) -> int:
        try:
            value = parse_int(text)
        except ValueError:
            value = None
        if value is None or value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"invalid value {shorten(text)}; allowed: {allowed}")
        return value

    return parse


def float_range(low: float | None = None, high: float | None = None, *,
                low_open: bool = False) -> Callable[[str], float]:
    """``type=`` for a finite decimal number (``1.5``, ``-2e3``) with low <= x (low < x if ``low_open``) <= high."""
    bounds = [f"{'>' if low_open else '>='} {low:g}"] if low is not None else []
    bounds += [f"<= {high:g}"] if high is not None else []
    allowed = " ".join(["finite numbers", " and ".join(bounds)]).strip()

    def parse(text: str) -> float:
        value = _finite(text)
        ok = value is not None and (low is None or (value > low if low_open else value >= low))
        if value is None or not ok or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"invalid value {shorten(text)}; allowed: {allowed}")
        return value

    return parse


def _finite(text: str) -> float | None:
    """The finite number ``text`` writes (:func:`bboxtune.envs.data.number_grammar.parse_float`), else None."""
    try:
        return parse_float(text)
    except ValueError:
        return None


positive_int = int_range(1)
nonnegative_int = int_range(0)
positive_float = float_range(0.0, low_open=True)


NAME_MAX, PATH_MAX = 255, 4095  # bytes of one name in a path and of a whole path (Linux; other systems allow less)


def _path(text: str) -> Path:
    """``text`` as a path, refused (ArgumentTypeError) where a name in it or the whole path is longer than the
    system takes (:data:`NAME_MAX`, :data:`PATH_MAX` bytes): checked here, as ``exists()`` would raise OSError."""
    encoded = os.fsencode(text)
    if len(encoded) > PATH_MAX or any(len(part) > NAME_MAX for part in encoded.split(b"/")):
        raise argparse.ArgumentTypeError(f"{shorten(text)}: path too long (allowed: names of at most {NAME_MAX} bytes, "
                                         f"{PATH_MAX} bytes in all)")
    return Path(text)


def existing_file(text: str) -> Path:
    """``type=`` for a readable regular file."""
    path = _path(text)
    if not text or not path.exists():
        raise argparse.ArgumentTypeError(f"{text!r} does not exist")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; expected a file")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text} is not a regular file")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text} is not readable")
    return path


def existing_dir(text: str) -> Path:
    """``type=`` for a folder that exists and can be listed."""
    path = _path(text)
    if not text or not path.exists():
        raise argparse.ArgumentTypeError(f"{text!r} does not exist")
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder")
    if not os.access(path, os.R_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text} is not readable")
    return path


def out_dir(text: str) -> Path:
    """``type=`` for an output folder: an existing writable folder, or a path whose nearest existing ancestor is
    a writable folder (so the script can create it). Creates nothing; what the script does with files already in
    an existing folder is the script's to document."""
    if not text:
        raise argparse.ArgumentTypeError("empty path")
    path = _path(text)
    existing = next(p for p in (path, *path.parents) if os.path.lexists(p))  # "." / "/" always exist
    if not existing.is_dir():
        what = "exists and is not a folder" if existing == path else f"cannot be created: {existing} is not a folder"
        raise argparse.ArgumentTypeError(f"{text} {what}")
    if not os.access(existing, os.W_OK | os.X_OK):
        what = "is not writable" if existing == path else f"cannot be created: {existing} is not writable"
        raise argparse.ArgumentTypeError(f"{text} {what}")
    return path


def new_file(text: str) -> Path:
    """``type=`` for an output file: a path that does not exist yet, whose folder is an existing writable folder or
    can be created (:func:`out_dir`; the script creates it when it writes). Nothing is ever overwritten; nothing is
    created here."""
    if not text:
        raise argparse.ArgumentTypeError("empty path")
    path = _path(text)
    if os.path.lexists(path):
        raise argparse.ArgumentTypeError(f"{text} already exists; choose a new file (nothing is overwritten)")
    if path.name in ("", ".", ".."):
        raise argparse.ArgumentTypeError(f"{text} is not a file name")
    out_dir(str(path.parent))
    return path


def outputs_taken(out: Path, names: Sequence[str]) -> bool:
    """Whether the output folder ``out`` already holds any of the files ``names``; if so, a script that writes them
    refuses to overwrite them, and one error line naming them is printed to stderr."""
    taken = [name for name in names if (out / name).exists()]
    if taken:
        print(f"error: --out {out} already holds {', '.join(taken)}; choose another folder", file=sys.stderr)
    return bool(taken)


def command_line(script: str, argv: list[str] | None) -> str:
    """The command that ran ``scripts/<script>.py`` with ``argv`` (None: this process's arguments), shell-quoted."""
    return shlex.join(["python", f"scripts/{script}.py", *(sys.argv[1:] if argv is None else argv)])


def key_values(flag: str, items: list[str], separators: str = "=:") -> dict[str, Any]:
    """``KEY<sep>VALUE`` items as ``{KEY: yaml.safe_load(VALUE)}``: each item is split at its first character
    from ``separators`` (so ``otb_root=/a:b`` is ``otb_root`` → ``"/a:b"``, ``tune:[psi, horizon]`` a list);
    ValueError naming ``flag`` and the item for a missing key or separator, a key given twice, or a value that
    is not valid YAML. Whether the keys and values are allowed is the caller's check.

    >>> key_values("--env-kwargs", ["track_length=100", "psi_range:[0, 0.5]"])
    {'track_length': 100, 'psi_range': [0, 0.5]}
    """
    shapes = " or ".join(f"KEY{sep}VALUE" for sep in separators)
    out: dict[str, Any] = {}
    for item in items:
        cut = min((i for i in (item.find(sep) for sep in separators) if i >= 0), default=-1)
        key, value = (item[:cut], item[cut + 1:]) if cut >= 0 else (item, "")
        if cut < 0 or not key:
            raise ValueError(f"{flag} {shorten(item)}: expected {shapes}")
        if key in out:
            raise ValueError(f"{flag}: {key} given twice")
        try:
            out[key] = yaml.safe_load(value)
        except yaml.YAMLError as err:
            why = getattr(err, "problem", None) or " ".join(str(err).split())
            raise ValueError(f"{flag} {shorten(item)}: the value is not valid YAML ({why})") from None
    return out


def tracker_set(text: str) -> tuple[str, ...]:
    """``--trackers``: ``train`` or ``test`` (the tracker split ``bboxtune.envs.data.otb.TRACKER_SPLIT``) or comma-separated
    tracker names (checked against the OTB data when the env is built).

    >>> tracker_set("SiamFC,STRUCK"), tracker_set("test")
    (('SiamFC', 'STRUCK'), ('SiamRPN++', 'CFNet', 'STRUCK', 'MDNet'))
    """
    if text in TRACKER_SPLIT:
        return TRACKER_SPLIT[text]
    names = tuple(name.strip() for name in text.split(","))
    if not all(names) or len(set(names)) < len(names):
        raise argparse.ArgumentTypeError(f"{shorten(text)}: expected 'train', 'test' or distinct comma-separated "
                                         "tracker names")
    return names


@dataclass(frozen=True)
class Document:
    """A parsed JSON / YAML file and where it came from (for later messages about its content)."""

    path: Path
    data: Any


def _document(reader: Callable[[Path], Any]) -> Callable[[str], Document]:
    def parse(text: str) -> Document:
        path = existing_file(text)
        try:
            return Document(path, reader(path))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


json_file = _document(read_json)
yaml_file = _document(read_yaml)


def box_xywh(text: str) -> tuple[float, float, float, float]:
    """``type=`` for a box ``x,y,w,h`` in px: four finite numbers, w > 0 and h > 0, none beyond ``MAX_COORD`` (1e7)."""
    parts = [p.strip() for p in text.split(",", 4)] if len(text) <= 400 else []
    values = [v for v in (_finite(p) for p in parts) if v is not None] if len(parts) == 4 else []  # 4: all finite
    if len(values) != 4 or values[2] <= 0 or values[3] <= 0 or max(map(abs, values)) > MAX_COORD:
        raise argparse.ArgumentTypeError(f"invalid box {shorten(text)}; allowed: x,y,w,h (px), finite, w > 0, h > 0, "
                                         f"{COORD_RULE}")
    x, y, w, h = values
    return x, y, w, h


P = ParamSpec("P")
STOP_WORDS: dict[int, str] = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}


class Interrupted(KeyboardInterrupt):
    """A stop by Ctrl-C (``signum`` SIGINT) or SIGTERM, with the ``detail`` a command adds to :func:`command`'s
    line (train.py: the step and how to resume)."""

    def __init__(self, signum: int = signal.SIGINT, detail: str = "") -> None:
        super().__init__(detail)
        self.signum, self.detail = int(signum), detail

    @classmethod
    def of(cls, stop: KeyboardInterrupt, detail: str) -> Interrupted:
        """``stop`` (Python's own KeyboardInterrupt is Ctrl-C) with ``detail``."""
        return cls(getattr(stop, "signum", signal.SIGINT), detail)

    def line(self, prog: str) -> str:
        return " ".join([f"{prog}: {STOP_WORDS.get(self.signum, 'stopped')}", self.detail]).strip()


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Interrupted(signum)


_in_command = threading.local()  # a command's main called by another's (reproduce_otb.py -> reproduce.py): one handler


def command(main: Callable[P, int]) -> Callable[P, int]:
    """A command's ``main`` (module ``bboxtune.agents.commands.<name>``) whose Ctrl-C and SIGTERM give one line on
    stderr, ``<name>.py: interrupted`` or ``<name>.py: terminated`` (and the :class:`Interrupted` detail, if the
    command raised one), and return 128 + the signal number (130, 143) instead of a traceback. While ``main`` runs
    (in the main thread) SIGTERM raises :class:`Interrupted` wherever the command is, as Ctrl-C raises
    KeyboardInterrupt, so cleanup code runs; the previous handler is put back afterwards."""
    prog = main.__module__.rsplit(".", 1)[-1] + ".py"

    @functools.wraps(main)
    def wrapped(*args: P.args, **kwargs: P.kwargs) -> int:
        if getattr(_in_command, "active", False) or threading.current_thread() is not threading.main_thread():
            return main(*args, **kwargs)
        _in_command.active = True
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            return main(*args, **kwargs)
        except KeyboardInterrupt as stop:
            stopped = stop if isinstance(stop, Interrupted) else Interrupted()
            print(stopped.line(prog), file=sys.stderr, flush=True)
            return 128 + stopped.signum
        finally:
            signal.signal(signal.SIGTERM, previous)
            _in_command.active = False

    return wrapped
