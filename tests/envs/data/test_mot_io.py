"""The MOT15 readers: accepted layouts, one ValueError naming file:line per malformed case, fuzzing against an
independent per-line reference grammar (bounded time), and the real MOT15 copy against its sequences.csv."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from bboxtune.envs.data.boxes import MAX_COORD
from bboxtune.envs.data.mot_io import (
    MAX_INDEX,
    MAX_LINE_CHARS,
    SequenceInfo,
    read_detections,
    read_ground_truth,
    read_results,
    read_sequences_csv,
)

REPO = Path(__file__).resolve().parents[3]
READERS = {"det": read_detections, "gt": read_ground_truth, "results": read_results}
HANG_TIMEOUT_S = 60  # the correct run (interpreter start included) takes about a second

GT = "1,1,10,20,30,40,1,-1,-1,-1\n1,2,5,6,7,8,0,-1,-1,-1\n2,1,11,21,31,41,1,-1,-1,-1\n"
DET = "1,-1,10,20,30,40,67.5,-1,-1,-1\n2,-1,11.5,21,31,41,-0.29,3.5,11.7,0.65\n"


def write(path: Path, content: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


# --- accepted text --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", [
    GT,
    GT.rstrip("\n"),  # no final newline
    GT + "\n",  # a blank last line (ETH-Pedcross2's det.txt)
    GT + "\n \n\t\n",  # blank lines, also of spaces and tabs, only at the end
    GT.replace("\n", "\r\n"),  # CRLF
    "\ufeff" + GT,  # UTF-8 byte-order mark
    GT.replace(",", ", "),  # spaces after the commas (the line-by-line path)
    "1.0,1,10,20,30,40,1,-1,-1,-1\n1,2.0,5,6,7,8,0,-1,-1,-1\n2e0,1,1.1e1,21,31,41,1,-1,-1,-1\n",  # integer values
])
def test_ground_truth_variants_read_identically(tmp_path, text):
    gt = read_ground_truth(write(tmp_path / "gt.txt", text))
    assert gt.frame.tolist() == [1, 1, 2] and gt.id.tolist() == [1, 2, 1] and gt.flag.tolist() == [True, False, True]
    np.testing.assert_array_equal(gt.box, [[10, 20, 30, 40], [5, 6, 7, 8], [11, 21, 31, 41]])
    assert gt.frame.dtype == gt.id.dtype == np.int64 and len(gt) == 3


def test_detections_and_results(tmp_path):
    det = read_detections(write(tmp_path / "det.txt", DET + "\n"))
    assert det.frame.tolist() == [1, 2] and det.score.tolist() == [67.5, -0.29]
    np.testing.assert_array_equal(det.box, [[10, 20, 30, 40], [11.5, 21, 31, 41]])
    res = read_results(write(tmp_path / "res.txt", "3,7,1,2,3,4,0.9,-1,-1,-1\n3,8,1,2,3,4,1,-1,-1,-1\n"))
    assert res.frame.tolist() == [3, 3] and res.id.tolist() == [7, 8] and res.score.tolist() == [0.9, 1]
    assert len(read_detections(write(tmp_path / "empty.txt", "\n"))) == 0  # no detections at all is valid
    assert len(read_results(write(tmp_path / "empty2.txt", ""))) == 0


def test_a_bad_line_after_the_first_block_takes_the_line_by_line_path(tmp_path):
    lines = [f"{f},-1,1,2,3,4,0.5,-1,-1,-1" for f in range(1, 2501)]
    lines[1500] = lines[1500].replace(",", " , ")  # valid, but not the fast path's form
    assert len(read_detections(write(tmp_path / "ok.txt", "\n".join(lines)))) == 2500
    lines[2200] = "2201,-1,1,2,3,4,0.5,-1,-1"
    with pytest.raises(ValueError, match=r"bad.txt:2201: expected 10 comma-separated values"):
        read_detections(write(tmp_path / "bad.txt", "\n".join(lines)))


# --- malformed text: a ValueError naming the file and line ----------------------------------------------------
ROW = "1,1,10,20,30,40,1,-1,-1,-1"
BAD = [
    ("gt", "", 1, "empty ground-truth file"),
    ("gt", ROW + "\n1,2,10,20,30,40,1,-1,-1\n", 2, "expected 10 comma-separated values"),
    ("gt", ROW + ",5\n", 1, "expected 10 comma-separated values"),
    ("gt", "1,1,10,20,30,40,1,-1,-1,-1,\n", 1, "got 11"),
    ("gt", "1 1 10 20 30 40 1 -1 -1 -1\n", 1, "got 1"),  # whitespace separators: not MOT
    ("gt", ROW + "\n2,1,10,x,30,40,1,-1,-1,-1\n", 2, "'x' is not a number"),
    ("gt", ROW + "\n2,1,10,nan,30,40,1,-1,-1,-1\n", 2, "non-finite value 'nan'"),
    ("gt", ROW + "\n2,1,10,20,inf,40,1,-1,-1,-1\n", 2, "non-finite value 'inf'"),
    ("gt", ROW + "\n2,1,10,20,30,1e999,1,-1,-1,-1\n", 2, "overflows"),
    ("gt", ROW + "\n2,1,10,20,0,40,1,-1,-1,-1\n", 2, r"box size w=0, h=40; allowed w, h > 0"),
    ("gt", ROW + "\n2,1,10,20,30,-4,1,-1,-1,-1\n", 2, r"box size w=30, h=-4"),
    ("gt", ROW + "\n0,2,10,20,30,40,1,-1,-1,-1\n", 2, r"frame 0; allowed integers 1 <= frame"),
    ("gt", ROW + "\n-3,2,10,20,30,40,1,-1,-1,-1\n", 2, r"frame -3; allowed"),
    ("gt", ROW + "\n1.5,2,10,20,30,40,1,-1,-1,-1\n", 2, r"frame 1.5; allowed"),
    ("gt", ROW + "\n2e9,2,10,20,30,40,1,-1,-1,-1\n", 2,
     rf"frame 2000000000; allowed integers 1 <= frame <= {MAX_INDEX}"),
    ("gt", ROW + "\n2,2.5,10,20,30,40,1,-1,-1,-1\n", 2, r"id 2.5; allowed integers"),
    ("gt", ROW + "\n2,1,10,20,30,40,2,-1,-1,-1\n", 2, r"flag 2; allowed 0 or 1"),
    ("gt", ROW + "\n2,1,10,20,30,40,0.5,-1,-1,-1\n", 2, r"flag 0.5; allowed 0 or 1"),
    ("gt", ROW + "\n2,1,10,20,30,40,1,-1,-1,-1\n1,1,5,5,5,5,0,-1,-1,-1\n", 3,
     r"repeats frame 1, id 1 of line 1; allowed one row per \(frame, id\)"),
    ("gt", ROW + "\n\n" + ROW.replace("1,1", "2,1", 1) + "\n", 2, "blank line inside the file"),
    ("gt", ROW + "\n" + ROW.replace(",", " " * 120 + ",") + "\n", 2, f"allowed at most {MAX_LINE_CHARS}"),
    ("gt", ROW + "\n" + "7" * 5000 + "\n", 2, "line is 5000 characters long"),
    ("gt", ROW + "\n2,1,10,20,30,40,1,-1,-1,\u0663\n", 2, "is not a number"),  # Arabic-Indic 3: float() reads it
    ("gt", ROW + "\n2,1,1_0,20,30,40,1,-1,-1,-1\n", 2, "'1_0' is not a number"),
    ("gt", ROW.encode() + b"\n2,1,\xff0,20,30,40,1,-1,-1,-1\n", 2, "not UTF-8"),
    ("det", DET + "3,4,1,2,3,4,0.5,-1,-1,-1\n", 3, r"id 4; allowed -1 \(detections have no identity\)"),
    ("det", DET + "3,-1,1,2,3,4,nan,-1,-1,-1\n", 3, "non-finite value 'nan'"),
    ("det", DET + "0,-1,1,2,3,4,0.5,-1,-1,-1\n", 3, "frame 0"),
    ("det", DET + "3,-1,1,2,3,0,0.5,-1,-1,-1\n", 3, "box size w=3, h=0"),
    ("det", DET + "3,-1,1,-1.0000001e7,3,4,0.5,-1,-1,-1\n", 3, r"box \[1.0, -10000001.0, 3.0, 4.0\] is too large; "
     r"allowed \|x\|, \|y\|, w, h <= 1e7 px"),
    ("gt", ROW + "\n2,1,10,20,1e300,40,1,-1,-1,-1\n", 2, r"box \[10.0, 20.0, 1e\+300, 40.0\] is too large"),
    ("results", "1,1,1,2,3,1.0000001e7,1,-1,-1,-1\n", 1, "is too large"),
    ("results", "1,1,1,2,3,4,1,-1,-1,-1\n1,2,1,2,3,4,1,-1,-1,-1\n1,2,5,6,7,8,1,-1,-1,-1\n", 3,
     "repeats frame 1, id 2 of line 2"),
]


@pytest.mark.parametrize("kind, content, line, message", BAD)
def test_malformed_input_names_file_and_line(tmp_path, kind, content, line, message):
    path = write(tmp_path / f"{kind}.txt", content)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}:{line}: .*{message}") as err:
        READERS[kind](path)
    assert "\n" not in str(err.value)


def test_boxes_at_the_coordinate_bound_are_read(tmp_path):
    """|x|, |y|, w, h = MAX_COORD (1e7 px) is accepted, bit for bit; 1.0000001e7 is refused (BAD above)."""
    res = read_results(write(tmp_path / "res.txt", "1,1,-1e7,1e7,1e7,10000000.0,1,-1,-1,-1\n"))
    np.testing.assert_array_equal(res.box, [[-MAX_COORD, MAX_COORD, MAX_COORD, MAX_COORD]])


def test_the_first_of_several_bad_rows_is_named(tmp_path):
    path = write(tmp_path / "gt.txt", ROW + "\n2,1,1,2,3,4,3,-1,-1,-1\n0,1,1,2,3,4,1,-1,-1,-1\n")
    with pytest.raises(ValueError, match=r"gt.txt:2: flag 3"):  # line 2's flag before line 3's frame
        read_ground_truth(path)


def test_a_directory_or_missing_file_is_named(tmp_path):
    with pytest.raises(ValueError, match=rf"^{re.escape(str(tmp_path))}: is a directory"):
        read_ground_truth(tmp_path)
    with pytest.raises(ValueError, match="missing.txt: cannot read the file"):
        read_detections(tmp_path / "missing.txt")


# --- sequences.csv --------------------------------------------------------------------------------------------
def test_sequences_csv(tmp_path):
    write(tmp_path / "sequences.csv", "sequence,fps,frames,gt_rows\nA-1,30,525,9\nB,14,10,0\n")
    assert read_sequences_csv(tmp_path) == {"A-1": SequenceInfo("A-1", 30, 525, gt_rows=9),
                                            "B": SequenceInfo("B", 14, 10, gt_rows=0)}
    for table, message in [
        ("sequence,fps,frames\nA,30,5\nA,30,5\n", r"sequences.csv:3: duplicate row for sequence 'A' \(first at line 2"),
        ("sequence,frames\nA,5\n", r"sequences.csv:1: header .* lacks column\(s\) \['fps'\]"),
        ("sequence,fps,frames\nA,0,5\n", r"sequences.csv:2: fps=0 is out of range: allowed >= 1"),
        ("sequence,fps,frames\nA,29.97,5\n", r"sequences.csv:2: fps="),
        ("sequence,fps,frames,detections\nA,30,5,\n", r"sequences.csv:2: detections="),
    ]:
        write(tmp_path / "sequences.csv", table)
        with pytest.raises(ValueError, match=message):
            read_sequences_csv(tmp_path)


# --- fuzzing against an independent reference -----------------------------------------------------------------
_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_LINE = re.compile(rf"[ \t]*({_NUM})" + rf"[ \t]*,[ \t]*({_NUM})" * 9 + r"[ \t]*")


def reference(text: str, kind: str) -> np.ndarray | None:
    """(N, 10) rows of a valid file of ``kind``, else None (regex per line; short input only)."""
    text = text.lstrip("\ufeff").replace("\r\n", "\n").replace("\r", "\n")
    lines = text.rstrip(" \t\n").split("\n") if text.strip(" \t\n") else []
    matches = [_LINE.fullmatch(line) for line in lines]
    if any(m is None or len(line) > MAX_LINE_CHARS or max(map(len, m.groups())) > 64
           for m, line in zip(matches, lines, strict=True)):
        return None
    rows = np.array([[float(t) for t in m.groups()] for m in matches]).reshape(-1, 10)
    frame, ident = rows[:, 0], rows[:, 1]
    ok = np.isfinite(rows).all() and (kind != "gt" or len(rows) > 0)
    ok = ok and all((frame == np.floor(frame)) & (frame >= 1) & (frame <= MAX_INDEX))
    ok = ok and all(rows[:, 4:6].ravel() > 0) and bool((np.abs(rows[:, 2:6]) <= MAX_COORD).all())
    if kind == "det":
        return rows if ok and all(ident == -1) else None
    ok = ok and all((ident == np.floor(ident)) & (np.abs(ident) <= MAX_INDEX))
    ok = ok and (kind != "gt" or set(rows[:, 6]) <= {0, 1})
    return rows if ok and len({(f, i) for f, i in rows[:, :2].tolist()}) == len(rows) else None


def check_against_reference(path: Path, text: str, kind: str) -> str | None:
    """Read ``text`` as ``kind``: the rows must equal the reference's; an error (returned) must name a line."""
    write(path, text)
    expected = reference(text, kind)
    try:
        got = READERS[kind](path)
    except ValueError as err:
        assert expected is None, (err, text)
        assert re.match(rf"{re.escape(str(path))}:[0-9]+: ", str(err)) and "\n" not in str(err), err
        event("error")
        return str(err)
    assert expected is not None, text
    event(f"{len(expected)} rows read")
    np.testing.assert_array_equal(got.frame, expected[:, 0])
    np.testing.assert_array_equal(got.box, expected[:, 2:6])
    if kind == "gt":
        np.testing.assert_array_equal(got.flag, expected[:, 6] == 1)
    else:
        np.testing.assert_array_equal(got.score, expected[:, 6])
    return None


_token = st.sampled_from(["1", "2", "0", "-1", "1.5", "3e1", ".5", "2.0", "nan", "1e999", "x", "", "1_0", " 4 "])
_number = st.sampled_from(["1", "-2.5", "3e1", ".5", "+7."])
_noise = st.lists(_token, min_size=9, max_size=11).map(",".join) | st.text("0123456789,.-+eE \t", max_size=40)


def plausible_line(kind: str) -> st.SearchStrategy[str]:
    """Mostly valid rows of ``kind``, some with a semantic error (frame 0 or 2.5, w = 0, flag 2, a det id)."""
    ids = st.sampled_from(["-1"] * 6 + ["3"]) if kind == "det" else st.integers(-1, 99).map(str)
    col7 = st.sampled_from(["0", "1"] * 3 + ["2"]) if kind == "gt" else _number
    row = st.tuples(st.sampled_from([str(f) for f in range(1, 31)] + ["2.0", "0", "2.5"]), ids, _number, _number,
                    st.sampled_from(["1", "2.5"] * 4 + ["0"]), st.sampled_from(["1", "3e1"]), col7,
                    _number, _number, _number)
    return st.tuples(row, st.sampled_from([",", ", ", " ,\t"])).map(lambda r: r[1].join(r[0]))


@st.composite
def mot_files(draw: st.DrawFn) -> tuple[str, str]:
    """(kind, text): a few plausible lines of the kind, sometimes one noise line among them."""
    kind = draw(st.sampled_from(sorted(READERS)))
    lines = draw(st.lists(plausible_line(kind), max_size=5))
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), draw(_noise))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return kind, end.join(lines) + draw(st.sampled_from([end, "", end + " " + end]))


@settings(max_examples=300, deadline=timedelta(seconds=5))  # the deadline only catches a (near-)hang
@given(file=mot_files())
def test_random_short_files_parse_as_the_reference_or_raise(tmp_path_factory, file):
    kind, text = file
    check_against_reference(tmp_path_factory.getbasetemp() / "fuzz.txt", text, kind)


DET_LINES = [f"{1 + i // 7},-1,{i % 600}.5,{i % 300},{20 + i % 50}.25,{60 + i % 90},{(i % 97) / 3:.4f},-1,-1,-1"
             for i in range(3000)]
_edits = st.tuples(st.sampled_from(["replace", "insert", "delete"]), st.text("0123456789,.-+eE \tn_", max_size=20))


DET_ROWS = reference("\n".join(DET_LINES), "det")


@settings(max_examples=150, deadline=timedelta(seconds=5))
@given(index=st.integers(0, len(DET_LINES) - 1), edit=_edits, at=st.integers(0, 60))
def test_one_mutated_line_of_a_3000_line_det_file(tmp_path_factory, index, edit, at):
    """The reader's rows equal the valid file's with the mutated line's reference row, or it names that line."""
    kind, text = edit
    line, at = DET_LINES[index], at % (len(DET_LINES[index]) + 1)
    changed = list(DET_LINES)
    changed[index] = text if kind == "replace" else line[:at] + text + line[at + (kind == "delete"):]
    path = write(tmp_path_factory.getbasetemp() / "det.txt", "\n".join(changed) + "\n")
    blank = not changed[index].strip(" \t")
    dropped = blank and index == len(changed) - 1  # a blank last line ends the file; elsewhere it is an error
    expected = DET_ROWS[:-1] if dropped else None if blank else reference(changed[index], "det")
    try:
        det = read_detections(path)
    except ValueError as err:
        assert expected is None and str(err).startswith(f"{path}:{index + 1}: "), (err, changed[index])
        return
    assert expected is not None, changed[index]
    rows = DET_ROWS[:-1] if dropped else np.concatenate([DET_ROWS[:index], expected, DET_ROWS[index + 1:]])
    np.testing.assert_array_equal(np.c_[det.frame, det.box, det.score], rows[:, [0, 2, 3, 4, 5, 6]])


def test_50000_line_files_with_a_bad_line_stay_linear(tmp_path):
    """In a fresh interpreter with a timeout: a bad line in the middle is named; a 50 MB line is refused."""
    lines = [f"{1 + i // 10},{i % 10 + 1},{i % 600}.5,{i % 300},20.25,60,1,-1,-1,-1" for i in range(50_000)]
    lines[25_000] = lines[25_000][:-2] + "--1"
    middle = write(tmp_path / "middle.txt", "\n".join(lines))
    digits = write(tmp_path / "digits.txt", b"7" * 50_000_000)
    code = ("import json, sys\nfrom bboxtune.envs.data.mot_io import read_ground_truth\nfor path in sys.argv[1:]:\n"
            "    try:\n        print(json.dumps({'rows': len(read_ground_truth(path))}))\n"
            "    except ValueError as err:\n        print(json.dumps({'error': str(err)}))\n")
    run = subprocess.run([sys.executable, "-c", code, str(middle), str(digits)], cwd=REPO, capture_output=True,
                         text=True, timeout=HANG_TIMEOUT_S)
    assert run.returncode == 0, run.stderr
    results = [json.loads(line) for line in run.stdout.splitlines()]
    assert results[0]["error"].startswith(f"{middle}:25001: '--1' is not a number")
    assert results[1] == {"error": f"{digits}:1: line is 50000000 characters long; allowed at most {MAX_LINE_CHARS}"}


# --- the real MOT15 copy (MOT_ROOT) ---------------------------------------------------------------------------
def test_all_six_sequences_match_sequences_csv(mot_root):
    table = read_sequences_csv(mot_root)
    assert sorted(table) == ["ADL-Rundle-6", "ADL-Rundle-8", "ETH-Bahnhof", "ETH-Pedcross2", "KITTI-13", "Venice-2"]
    for name, info in table.items():
        det = read_detections(mot_root / name / "det" / "det.txt")
        gt = read_ground_truth(mot_root / name / "gt" / "gt.txt")
        assert (len(det), len(gt), int((~gt.flag).sum())) == (info.detections, info.gt_rows, info.gt_rows_flag0), name
        assert len(np.unique(gt.id)) == info.identities and max(det.frame.max(), gt.frame.max()) == info.frames, name
    assert (table["ETH-Bahnhof"].fps, table["KITTI-13"].fps, table["Venice-2"].fps) == (14, 10, 30)
