"""The box readers stay linear on adversarial files and name the exact bad line.

Hang guards run the reader in a subprocess with a timeout of tens of seconds where the correct run takes well
under one (the old backtracking regex took minutes on such files); the Hypothesis tests mutate one line of a
file at a random position and check the result against an independent per-line reference grammar.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.envs.data.boxes import MAX_COORD
from bboxtune.envs.data.number_grammar import parse_float, parse_int
from bboxtune.envs.data.otb import OTBDataset
from bboxtune.envs.data.otb_io import MAX_LINE_CHARS, parse_boxes
from tests.scripts import fuzz_files

REPO = Path(__file__).resolve().parents[3]
OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset (CI: OTB_ROOT=../shared/data/otb)")
N_LINES = 50_000
HANG_TIMEOUT_S = 60  # the correct run (interpreter start included) takes about a second

# --- an independent reference for one line (short input only; the tests never run it on a whole file) ------------
_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_COMMA_LINE = re.compile(rf"[ \t]*({_NUM})[ \t]*,[ \t]*({_NUM})[ \t]*,[ \t]*({_NUM})[ \t]*,[ \t]*({_NUM})[ \t]*")
_SPACE_LINE = re.compile(rf"[ \t]*({_NUM})[ \t]+({_NUM})[ \t]+({_NUM})[ \t]+({_NUM})[ \t]*")


def reference_box(line: str) -> list[float] | None:
    """The box a valid line holds (zero size → NaN), else None."""
    match = _COMMA_LINE.fullmatch(line) or _SPACE_LINE.fullmatch(line)
    if match is None or len(line) > MAX_LINE_CHARS or any(len(t) > 64 for t in match.groups()):
        return None
    box = [float(t) for t in match.groups()]
    if not np.isfinite(box).all() or min(box[2:]) < 0 or max(map(abs, box)) > MAX_COORD:
        return None
    return [np.nan] * 4 if min(box[2:]) == 0 else box


def box_lines(n: int, seed: int = 0) -> list[str]:
    """``n`` lines in the shape of OTB tracker outputs (integers, 2 decimals and full doubles)."""
    rng = np.random.default_rng(seed)
    xy, wh = rng.uniform(-5, 600, (n, 2)), rng.uniform(1, 300, (n, 2))
    styles = [lambda v: f"{v:.0f}", lambda v: f"{v:.2f}", repr]
    return [",".join(styles[i % 3](float(v)) for v in (*xy[i], *wh[i])) for i in range(n)]


@settings(max_examples=200, deadline=None)
@given(st.text("0123456789+-.eE_ \tnaifx\u0663\uff11", max_size=12) | st.from_regex(_NUM, fullmatch=True))
def test_parse_float_accepts_exactly_the_grammar(token):
    """Python's float() on the grammar's alphabet equals the reference regex (module docstring of the grammar)."""
    expected = float(token) if re.fullmatch(_NUM, token) and len(token) <= 64 else None
    if expected is not None and np.isfinite(expected):
        assert parse_float(token) == expected
    else:
        with pytest.raises(ValueError):
            parse_float(token)


@settings(max_examples=300, deadline=None)
@given(st.text("0123456789+-_ \u0663", max_size=22))
def test_parse_int_accepts_exactly_the_grammar(token):
    if re.fullmatch(r"[+-]?[0-9]{1,18}", token):
        assert parse_int(token) == int(token)
    else:
        with pytest.raises(ValueError):
            parse_int(token)


# --- hang guards ----------------------------------------------------------------------------------------------------
def read_in_subprocess(paths: list[Path]) -> list[dict]:
    """read_boxes on each path in one fresh interpreter: {"rows": T} or {"error": message} per path."""
    code = ("import json, sys\nfrom bboxtune.envs.data.otb_io import read_boxes\nfor path in sys.argv[1:]:\n"
            "    try:\n        print(json.dumps({'rows': len(read_boxes(path))}))\n"
            "    except ValueError as err:\n        print(json.dumps({'error': str(err)}))\n")
    run = subprocess.run([sys.executable, "-c", code, *map(str, paths)], cwd=REPO, capture_output=True, text=True,
                         timeout=HANG_TIMEOUT_S)
    assert run.returncode == 0, run.stderr
    return [json.loads(line) for line in run.stdout.splitlines()]


BAD_LINES = {
    "170,151,107": "expected 4 values x,y,w,h, got 3",  # the line that made the old regex backtrack
    "170,nan,107,187": "non-finite value 'nan'",
    "170,151,107,1_87": "'1_87' is not a number",
    "170,151,107,187,": "expected 4 values x,y,w,h, got 5",
}


def test_bad_line_at_start_middle_or_end_of_a_50000_line_file_is_named(tmp_path):
    cases, good = [], box_lines(N_LINES)
    for position in (0, N_LINES // 2, N_LINES - 1):
        for k, (bad, message) in enumerate(BAD_LINES.items()):
            lines = list(good)
            lines[position] = bad
            path = tmp_path / f"tracker_{position}_{k}.txt"
            path.write_text("\n".join(lines) + "\n")
            cases.append((path, position, message))
    for (path, position, message), result in zip(cases, read_in_subprocess([c[0] for c in cases]), strict=True):
        assert result.get("error", "").startswith(f"{path}:{position + 1}: ") and message in result["error"], result


def test_trailing_space_and_a_50_mb_line_of_digits(tmp_path):
    spaced, digits = tmp_path / "spaced.txt", tmp_path / "digits.txt"
    spaced.write_text("\n".join(box_lines(N_LINES)) + " \n")  # the last line ends with a space: valid
    digits.write_bytes(b"7" * 50_000_000 + b"\n")
    assert read_in_subprocess([spaced, digits]) == [
        {"rows": N_LINES},
        {"error": f"{digits}:1: line is 50000000 characters long; allowed at most {MAX_LINE_CHARS}"},
    ]


# --- one mutated line at a random position ---------------------------------------------------------------------
_ALPHABET = "0123456789,.,-+eE \t_nainfx\u0663\u00a0"
_edits = st.one_of(
    st.tuples(st.just("replace"), st.text(_ALPHABET, max_size=40)),
    st.tuples(st.just("insert"), st.sampled_from(_ALPHABET)),
    st.tuples(st.just("delete"), st.just("")),
    st.tuples(st.just("append"), st.text(_ALPHABET, min_size=1, max_size=200)),
)


def mutate(line: str, edit: tuple[str, str], at: int) -> str:
    kind, text = edit
    at %= len(line) + 1
    if kind == "replace":
        return text
    if kind == "insert":
        return line[:at] + text + line[at:]
    if kind == "delete":
        return line[:at] + line[at + 1:]
    return line + text


def check_one_mutation(lines: list[str], index: int, edit: tuple[str, str], at: int) -> None:
    """Parse ``lines`` with line ``index`` mutated: the result must equal the reference, an error must name it."""
    changed = list(lines)
    changed[index] = mutate(lines[index], edit, at)
    text = "\n".join(changed) + "\n"
    expected = reference_box(changed[index])
    dropped = index == len(lines) - 1 and not changed[index].strip(" \t")  # a blank last line ends the file
    try:
        boxes = parse_boxes(text, "f.txt")
    except ValueError as err:
        assert str(err).startswith(f"f.txt:{index + 1}: ") and expected is None and not dropped, (err, changed[index])
        return
    assert dropped or expected is not None, changed[index]
    original = parse_boxes("\n".join(lines) + "\n", "f.txt")
    if dropped:
        np.testing.assert_array_equal(boxes, original[:-1])
        return
    np.testing.assert_array_equal(np.delete(boxes, index, axis=0), np.delete(original, index, axis=0))
    np.testing.assert_array_equal(boxes[index], expected)


SYNTHETIC = box_lines(3000, seed=1)


@settings(max_examples=150, deadline=timedelta(seconds=5))  # the deadline only catches a (near-)hang
@given(index=st.integers(0, len(SYNTHETIC) - 1), edit=_edits, at=st.integers(0, 100))
def test_one_mutated_line_of_a_3000_line_file(index, edit, at):
    check_one_mutation(SYNTHETIC, index, edit, at)


@needs_otb
@pytest.mark.parametrize("file", ["groundtruth/Car4.txt", "trackers/SiamRPN++/Doll.txt", "trackers/STRUCK/ClifBar.txt"])
def test_one_mutated_line_of_a_real_otb_file(file):
    lines = Path(OTB_ROOT, file).read_text().rstrip("\n").split("\n")

    @settings(max_examples=100, deadline=timedelta(seconds=5))
    @given(index=st.integers(0, len(lines) - 1), edit=_edits, at=st.integers(0, 100))
    def check(index, edit, at):
        check_one_mutation(lines, index, edit, at)

    check()


@settings(max_examples=300, deadline=timedelta(seconds=5))
@given(lines=st.lists(st.text(_ALPHABET, max_size=30), min_size=1, max_size=6))
def test_short_files_follow_the_reference_grammar(lines):
    """Any short file: boxes equal to the per-line reference when every line is valid, else an error."""
    text = "\n".join(lines)
    rows = text.rstrip(" \t\n").split("\n") if text.strip() else []
    expected = [reference_box(r) for r in rows]
    if expected and all(b is not None for b in expected):
        np.testing.assert_array_equal(parse_boxes(text, "f"), np.array(expected, dtype=float))
    else:
        with pytest.raises(ValueError, match=r"^f:\d+: "):
            parse_boxes(text, "f")


@needs_otb
def test_one_mutated_line_of_the_real_sequences_csv(tmp_path_factory):
    """OTBDataset on the real groundtruth/ with one line of sequences.csv mutated: it loads, or a ValueError names
    sequences.csv and a line at or after the mutated one (a duplicate is reported at its second row)."""
    root = tmp_path_factory.mktemp("otb")
    (root / "groundtruth").symlink_to(Path(OTB_ROOT, "groundtruth"))
    lines = Path(OTB_ROOT, "sequences.csv").read_text().rstrip("\n").split("\n")
    table = root / "sequences.csv"

    @settings(max_examples=100, deadline=timedelta(seconds=5))
    @given(index=st.integers(0, len(lines) - 1), edit=_edits | st.tuples(st.just("replace"), st.sampled_from(lines)),
           at=st.integers(0, 100))
    def check(index, edit, at):
        changed = list(lines)
        changed[index] = mutate(lines[index], edit, at)
        table.write_text("\n".join(changed) + "\n")
        try:
            OTBDataset(root)
        except ValueError as err:
            match = re.match(rf"{re.escape(str(table))}:([0-9]+): ", str(err))
            assert match and int(match.group(1)) >= index + 1, (str(err), changed[index])

    check()


# --- the other files a user hands in: generated contents (tests/scripts/fuzz_files.py) -------------------------------
# Each reader returns, or raises ValueError (RunError is one) whose message starts with the file's path; bounded time.
def _generated(tmp: Path, name: str, data: bytes) -> Path:
    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path


def _refuses_naming(path: Path, read) -> None:
    try:
        read()
    except ValueError as err:
        assert str(err).startswith(str(path)), err


@settings(max_examples=150, deadline=timedelta(seconds=5))
@given(data=fuzz_files.contents() | fuzz_files.json_doc() | fuzz_files.config_yml())
def test_json_and_yaml_readers_name_the_file(data, tmp_path_factory):
    from bboxtune.agents.readers import read_json, read_yaml

    tmp = tmp_path_factory.mktemp("doc")
    path = _generated(tmp, "doc", data)
    _refuses_naming(path, lambda: read_json(path))
    _refuses_naming(path, lambda: read_yaml(path))


@settings(max_examples=100, deadline=timedelta(seconds=5))
@given(data=fuzz_files.config_yml() | fuzz_files.contents())
def test_a_run_folders_config_yml_is_checked(data, tmp_path_factory):
    """compare.py --model, track_video.py --tuned, train.py --resume: load_config's result has every key typed."""
    from bboxtune.agents.training.runs import MODEL_KEYS, load_config

    run = tmp_path_factory.mktemp("run")
    path = _generated(run, "config.yml", data)
    try:
        cfg = load_config(run)
    except ValueError as err:
        assert str(err).startswith(str(path)), err
        return
    assert all(isinstance(cfg[k], kind) for k, kind in MODEL_KEYS.items())


@settings(max_examples=150, deadline=timedelta(seconds=5))
@given(data=fuzz_files.seqinfo() | fuzz_files.contents())
def test_seqinfo_ini_gives_a_frame_rate_in_range_or_names_the_file(data, tmp_path_factory):
    from bboxtune.agents.smoothing.mot_smooth import FPS_RANGE, read_seqinfo_fps

    path = _generated(tmp_path_factory.mktemp("seq"), "seqinfo.ini", data)
    try:
        fps = read_seqinfo_fps(path)
    except ValueError as err:
        assert str(err).startswith(str(path)), err
        return
    assert FPS_RANGE[0] <= fps <= FPS_RANGE[1]


@settings(max_examples=150, deadline=timedelta(seconds=5))
@given(data=fuzz_files.sequences_csv("mot") | fuzz_files.contents())
def test_mot_sequences_csv_rows_or_a_named_line(data, tmp_path_factory):
    from bboxtune.envs.data.mot_io import read_sequences_csv

    root = tmp_path_factory.mktemp("mot")
    path = _generated(root, "sequences.csv", data)
    try:
        rows = read_sequences_csv(root)
    except ValueError as err:
        assert str(err).startswith(str(path)), err
        return
    assert all(r.fps >= 1 and r.frames >= 1 for r in rows.values())


@settings(max_examples=200, deadline=timedelta(seconds=5))
@given(items=st.lists(st.text(max_size=12) | st.tuples(st.sampled_from(["lr", "n_steps", "x"]), st.sampled_from(":="),
                                                       fuzz_files.token()).map("".join), max_size=4))
def test_key_values_of_hyperparams_give_a_dict_or_name_the_flag(items):
    """--hyperparams / --env-kwargs KEY:VALUE items (YAML values): how hyperparameter YAML enters train.py."""
    from bboxtune.agents.cli import key_values

    try:
        out = key_values("--hyperparams", items, separators=":")
    except ValueError as err:
        assert str(err).startswith("--hyperparams"), err
        return
    assert len(out) == len(items)


def test_a_yaml_integer_of_10000_digits_is_named(tmp_path):
    """yaml.safe_load's int() refuses over 4300 digits with a plain ValueError: it escaped unnamed."""
    from bboxtune.agents.readers import read_yaml

    path = tmp_path / "config.yml"
    path.write_text("seed: " + "7" * 10_000 + "\n")
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: invalid YAML: Exceeds the limit"):
        read_yaml(path)
