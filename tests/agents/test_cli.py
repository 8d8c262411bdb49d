"""bboxtune.agents.cli: one-line parser errors, strict numbers, path checks that create nothing, JSON/YAML errors with
file:line, and linear-time checks of huge values."""

from __future__ import annotations

import argparse
import os

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bboxtune.agents import cli, readers


def rejects(parse, text: str) -> str:
    with pytest.raises(argparse.ArgumentTypeError) as info:
        parse(text)
    return str(info.value)


@pytest.mark.parametrize("text", ["0", "-1", "abc", "", " 1", "1 ", "1_0", "٣", "1.0", "1e3", "0x10", "+", "nan"])
def test_positive_int_rejects_everything_but_ascii_integers_from_1(text):
    assert "allowed: integers >= 1" in rejects(cli.positive_int, text)


@given(st.integers(min_value=-10**12, max_value=10**12))
def test_int_range_accepts_exactly_its_range(value):
    parse = cli.int_range(-5, 7)
    if -5 <= value <= 7:
        assert parse(str(value)) == value and parse(f"+{value}" if value >= 0 else str(value)) == value
    else:
        assert "allowed: integers -5..7" in rejects(parse, str(value))


@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "1e400", "0", "-0.0", "abc", "1_0.5", "٣.5", "1.5.2", "e3",
                                  ""])
def test_positive_float_rejects_non_finite_non_positive_and_non_ascii(text):
    assert "allowed: finite numbers > 0" in rejects(cli.positive_float, text)


@pytest.mark.parametrize(("text", "value"), [("1", 1.0), ("2.5", 2.5), (".5", 0.5), ("5.", 5.0), ("1e-3", 1e-3),
                                             ("+3E2", 300.0)])
def test_positive_float_reads_decimal_numbers(text, value):
    assert cli.positive_float(text) == value


def test_float_range_bounds_are_inclusive_unless_open():
    closed, half_open = cli.float_range(0.0, 1.0), cli.float_range(0.0, 1.0, low_open=True)
    assert closed("0") == 0.0 and closed("1") == 1.0 and half_open("1") == 1.0
    assert "finite numbers > 0 and <= 1" in rejects(half_open, "0")
    assert "finite numbers >= 0 and <= 1" in rejects(closed, "1.01")


@pytest.mark.parametrize("text", ["9" * 5_000_000, "1" * 5_000_000 + "x", "1." + "0" * 5_000_000 + "e"],
                         ids=["digits", "digits-then-letter", "long-fraction"])
def test_huge_values_are_rejected(text):
    """Over-long values are refused before any parsing (no int() of millions of digits, no regex over them)."""
    for parse, arg, allowed in ((cli.positive_int, text, "integers >= 1"),
                                (cli.positive_float, text, "finite numbers > 0"),
                                (cli.box_xywh, ",".join([text] * 4), "x,y,w,h")):
        message = rejects(parse, arg)
        assert f"allowed: {allowed}" in message and len(message) < 200  # the value is cut in the message


def test_existing_file_and_dir(tmp_path):
    file = tmp_path / "a.txt"
    file.write_text("x")
    assert cli.existing_file(str(file)) == file and cli.existing_dir(str(tmp_path)) == tmp_path
    assert "does not exist" in rejects(cli.existing_file, str(tmp_path / "missing"))
    assert "is a folder; expected a file" in rejects(cli.existing_file, str(tmp_path))
    assert "is not a folder" in rejects(cli.existing_dir, str(file))
    assert "does not exist" in rejects(cli.existing_dir, "")


def test_out_dir_checks_without_creating_anything(tmp_path):
    file = tmp_path / "a.txt"
    file.write_text("x")
    assert cli.out_dir(str(tmp_path / "new" / "deeper")) == tmp_path / "new" / "deeper"
    assert cli.out_dir(str(tmp_path)) == tmp_path
    assert f"cannot be created: {file} is not a folder" in rejects(cli.out_dir, str(file / "sub" / "out"))
    assert "exists and is not a folder" in rejects(cli.out_dir, str(file))
    assert "empty path" in rejects(cli.out_dir, "")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    assert "exists and is not a folder" in rejects(cli.out_dir, str(tmp_path / "dangling"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "dangling"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_out_dir_rejects_a_read_only_parent(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    assert f"cannot be created: {locked} is not writable" in rejects(cli.out_dir, str(locked / "out"))


@pytest.mark.parametrize(("text", "where"), [('{"a": 1,\n "b": }\n', ":2:7: invalid JSON"),
                                             ("[1, 2", ":1:6: invalid JSON"),
                                             ('{"a": NaN}', ": invalid JSON: non-standard JSON constant NaN"),
                                             ("[" * 100_000, ": invalid JSON")])
def test_read_json_names_file_and_line(tmp_path, text, where):
    path = tmp_path / "t.json"
    path.write_text(text)
    with pytest.raises(ValueError, match="^" + str(path) + where):
        readers.read_json(path)
    assert where in rejects(cli.json_file, str(path))


@pytest.mark.parametrize(("text", "where"), [("a: 1\nb: [1, 2\n", ":3:1: invalid YAML"),
                                             ("a: 1\n  b: 2\n", ":2:4: invalid YAML"),
                                             ("a: !!python/object:os.system x\n", ":1:4: invalid YAML")])
def test_read_yaml_names_file_and_line(tmp_path, text, where):
    path = tmp_path / "t.yml"
    path.write_text(text)
    with pytest.raises(ValueError, match="^" + str(path) + where):
        readers.read_yaml(path)


def test_readers_name_folders_and_bad_encodings(tmp_path):
    with pytest.raises(ValueError, match="is a directory, expected a file"):
        readers.read_yaml(tmp_path)
    path = tmp_path / "t.json"
    path.write_bytes(b'{"a":\n "\xff"}')
    with pytest.raises(ValueError, match=r"t\.json:2: not UTF-8 text"):
        readers.read_json(path)


def test_json_and_yaml_files_give_their_path_and_data(tmp_path):
    (tmp_path / "t.json").write_text('{"a": [1, 2.5]}')
    (tmp_path / "t.yml").write_text("a: [1, 2.5]\n")
    for parse, name in ((cli.json_file, "t.json"), (cli.yaml_file, "t.yml")):
        doc = parse(str(tmp_path / name))
        assert doc == cli.Document(tmp_path / name, {"a": [1, 2.5]})


@pytest.mark.parametrize("text", ["1,2,3", "1,2,3,4,5", "1,2,0,4", "1,2,3,-4", "a,2,3,4", "1,nan,3,4", "1,2,inf,4", "",
                                  "1.0000001e7,2,3,4", "1,-10000001,3,4", "1,2,1e300,4", "1,2,3,10000000.1"])
def test_box_xywh_rejects_malformed_boxes(text):
    assert "allowed: x,y,w,h" in rejects(cli.box_xywh, text)


def test_box_xywh_states_the_coordinate_bound():
    assert "|x|, |y|, w, h <= 1e7 px" in rejects(cli.box_xywh, "1,2,3,1e8")
    assert cli.box_xywh("-1e7,1e7,1e7,10000000") == (-1e7, 1e7, 1e7, 1e7)  # at the bound: accepted


def test_box_xywh_reads_four_numbers():
    assert cli.box_xywh("120, 80.5,40,6e1") == (120.0, 80.5, 40.0, 60.0)


def test_parser_errors_are_one_line_with_exit_status_2(capsys):
    parser = cli.ArgumentParser(prog="tool.py")
    parser.add_argument("--n", type=cli.positive_int, required=True)
    for argv in ([], ["--n", "0"], ["--n", "1", "--bogus"], ["--n"], ["--n", "1", "--nn", "2"]):
        with pytest.raises(SystemExit) as info:
            parser.parse_args(argv)
        err = capsys.readouterr().err
        assert info.value.code == 2 and len(err.splitlines()) == 1 and err.startswith("tool.py: error: ")
    with pytest.raises(SystemExit):
        with cli.argument_errors(parser, "--n"):
            raise ValueError("first line\nsecond line")
    assert capsys.readouterr().err == "tool.py: error: --n: first line second line (see --help)\n"


def test_flags_are_not_abbreviated(capsys):
    parser = cli.ArgumentParser(prog="tool.py")
    parser.add_argument("--output", default="x")
    with pytest.raises(SystemExit):
        parser.parse_args(["--out", "y"])
    assert "unrecognized arguments: --out y" in capsys.readouterr().err


def test_help_formatter_appends_real_defaults_only():
    parser = cli.ArgumentParser(prog="tool.py", description="Title.\n\n    kept   as written",
                                formatter_class=cli.HelpFormatter)
    parser.add_argument("--n", type=int, default=3, help="count")
    parser.add_argument("--out", default=None, help="folder")
    text = parser.format_help()
    assert "    kept   as written" in text and "count (default: 3)" in text and "folder\n" in text


def test_key_values_split_at_the_first_separator_and_read_yaml():
    got = cli.key_values("--env-kwargs", ["track_length=100", "otb_root=/a:b", "tune:[psi, horizon]", "psi_range=[0, 0.5]"])
    assert got == {"track_length": 100, "otb_root": "/a:b", "tune": ["psi", "horizon"], "psi_range": [0, 0.5]}
    assert cli.key_values("--hyperparams", ["policy_kwargs:dict(a=1)"], separators=":") == {"policy_kwargs": "dict(a=1)"}


@pytest.mark.parametrize(("items", "message"), [(["track_length"], "expected KEY=VALUE or KEY:VALUE"),
                                                (["=3"], "expected"), (["a=1", "a:2"], "a given twice"),
                                                (["a=[1"], "not valid YAML")])
def test_key_values_errors_name_the_flag(items, message):
    with pytest.raises(ValueError, match=message) as err:
        cli.key_values("--env-kwargs", items)
    assert str(err.value).startswith("--env-kwargs")
