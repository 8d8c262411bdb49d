from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np
import pytest

from bboxtune.envs.data.boxes import MAX_COORD
from bboxtune.envs.data.otb import OTBDataset, resolve_root, split, video_of
from bboxtune.envs.data.otb_io import MAX_FILE_BYTES, parse_boxes, read_boxes

OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset (CI: OTB_ROOT=../shared/data/otb)")

BOXES = np.array([[70, 51, 107, 87], [71, 50.5, 106, 88], [-3, 2, 10, 12]], dtype=float)


def write(path: Path, content: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


# --- accepted box text ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text",
    [
        "70,51,107,87\n71,50.5,106,88\n-3,2,10,12\n",
        "70,51,107,87\n71,50.5,106,88\n-3,2,10,12",  # no final newline
        "70\t51\t107\t87\n71\t50.5\t106\t88\n-3\t2\t10\t12\n",  # tabs
        "70 51 107 87\n71  50.5 106 88\n-3 2 10 12\n",  # spaces
        "70, 51, 107, 87\r\n71 ,50.5,106,88\r\n-3,2,10,12\r\n\r\n",  # comma+space, CRLF, trailing blank line
        "\ufeff70,51,107,87\n71\t50.5\t106\t88\n-3 2 1e1 1.2E1\n",  # BOM, one kind per line, exponents
        "+70,51.,107,87\n71,50.5,106,88\n-3,2,10,12 \n",  # sign, point without decimals, last line ends with a space
        "70,51,107,87\n71,50.5,106,88\n-3,2,10,12\n\n \n",  # blank lines (also spaces) only at the end
        "70.0e0,0051,1070e-1,.87e2\n7.1e1,50.5,106,88\n-3,2,10,12",  # exponents, leading zeros, leading point
    ],
)
def test_box_text_variants_parse_identically(tmp_path, text):
    np.testing.assert_array_equal(read_boxes(write(tmp_path / "gt.txt", text)), BOXES)


def test_zero_size_box_is_a_logged_missing_frame(tmp_path, caplog):
    path = write(tmp_path / "Board.txt", "1,2,3,4\n0,0,0,0\n5,6,0,8\n")
    with caplog.at_level(logging.INFO, logger="bboxtune.envs.data.otb_io"):
        boxes = read_boxes(path)
    assert np.isnan(boxes[1:]).all() and np.isfinite(boxes[0]).all()
    assert f"{path}:2" in caplog.text and f"{path}:3" in caplog.text


# --- malformed box text: a ValueError naming the file and line --------------------------------------------------
@pytest.mark.parametrize(
    "content, line, message",
    [
        ("", 1, "empty"),
        ("\n  \n", 1, "empty"),
        ("1,2,3,4\nnan,2,3,4\n", 2, "non-finite"),
        ("1,2,3,4\n1,2,inf,4\n", 2, "non-finite"),
        ("1,2,3,4\n1,2,-3,4\n", 2, "negative size"),
        ("1,2,3,4\n1,2,3,4\n1,2,3,-0.5\n", 3, "negative size"),
        ("1,2,3\n", 1, "expected 4 values"),
        ("1,2,3,4\n1,2,3,4,5\n", 2, "expected 4 values"),
        ("1,2,3,4,\n", 1, "expected 4 values"),
        ("1,2,3,4\n1,2\t3,4\n", 2, "mixes comma and whitespace"),
        ("1,2,3,4\n1 2, 3 4\n", 2, "mixes comma and whitespace"),
        ("1,2,3,4\n1,2,x,4\n", 2, "'x' is not a number"),
        ("1,2,3,4\n\n1,2,3,4\n", 2, "blank line"),
        (b"1,2,3,4\n1,2,3,4\n1,2,\xff3,4\n", 3, "not UTF-8"),
        ("1;2;3;4\n", 1, "expected 4 values"),
        ("1,2,3,4\n1,2,3,0x10\n", 2, "'0x10' is not a number"),
        ("1,2,3,4\n1_0,2,3,4\n", 2, "'1_0' is not a number"),  # Python's float() reads 10
        ("1,2,3,4\n1,\u0663,3,4\n", 2, "is not a number"),  # Arabic-Indic 3: float() reads 3
        ("1,2,3,4\n1,2,3,\uff14\n", 2, "is not a number"),  # full-width 4
        ("1,2,3,4\n1,2,3,4\n-inf,2,3,4\n", 3, "non-finite value '-inf'"),
        ("1,2,3,4\n1,2,Infinity,4\n", 2, "non-finite value 'Infinity'"),
        ("1,2,3,4\n1,2,3,1e999\n", 2, "overflows"),
        ("1,2,3,4\n1,2,3,4e\n", 2, "'4e' is not a number"),
        ("1,2,3,4\n1,2,3,--4\n", 2, "'--4' is not a number"),
        ("1,2,3,4\n1,2,3,.\n", 2, "'.' is not a number"),
        ("1,2,3,4\n1,2,3,\n", 2, "'' is not a number"),
        ("1,2,3,4\n1,\u00a02,3,4\n", 2, "is not a number"),  # no-break space is not a separator
        ("1 2 3 4\n1\u20032 3 4\n", 2, "expected 4 values"),  # nor is an em space
        ("1,2,3,4\n1,2,3," + "4" * 65 + "\n", 2, "too long for a number"),
        ("1,2,3,4\n1,2,3,4 5\n", 2, "mixes comma and whitespace"),
        ("1,2,3,4\n" + "1," * 600 + "\n", 2, "line is 1200 characters long; allowed at most 1024"),
        ("1,2,3,4\n" + "7" * 5_000_000 + "\n1,2,3,4\n", 2, "line is 5000000 characters long"),
        ("1,2,3,4\n \n1,2,3,4\n", 2, "blank line"),
        ("1,2,3,4\n1.0000001e7,2,3,4\n", 2, r"box \[10000001.0, 2.0, 3.0, 4.0\] is too large; allowed \|x\|, \|y\|, w, h <= 1e7"),
        ("1,2,3,4\n1,2,3,4\n1 -1e300 3 4\n", 3, "is too large"),  # the line-by-line path
        ("1,2,3,4\n1,2,10000001,0\n", 2, "is too large"),  # also where the box is a zero-size (missing) frame
    ],
)
def test_malformed_box_text_names_file_and_line(tmp_path, content, line, message):
    path = write(tmp_path / "bad.txt", content)
    with pytest.raises(ValueError, match=message) as err:
        read_boxes(path)
    assert str(err.value).startswith(f"{path}:{line}:")


def test_boxes_at_the_coordinate_bound_are_read(tmp_path):
    """|x|, |y|, w, h = MAX_COORD (1e7 px) is accepted on both parser paths; beyond it is refused (above)."""
    for text in ("-1e7,1e7,1e7,10000000\n", "-1e7 1e7 1e7 10000000.0\n"):
        np.testing.assert_array_equal(read_boxes(write(tmp_path / "edge.txt", text)),
                                      [[-MAX_COORD, MAX_COORD, MAX_COORD, MAX_COORD]])


@pytest.mark.parametrize("line", [999, 1000, 1001, 2000, 2500])
@pytest.mark.parametrize("bad, message", [("", "blank line"), ("1,2,3", "expected 4 values"), ("1,2,3,4,", "got 5")])
def test_bad_line_at_a_block_boundary_of_the_fallback_is_named(line, bad, message):
    lines = ["70,51,107,87"] * 2500 + ["1, 2, 3, 4"]  # the last line sends the file to the checked fallback
    lines[line - 1] = bad
    with pytest.raises(ValueError, match=rf"^f:{line}: .*{message}"):
        parse_boxes("\n".join(lines) + "\n", "f")


def test_fallback_blocks_keep_every_row():
    rows = np.arange(4 * 2345, dtype=float).reshape(-1, 4) + 1
    lines = [",".join(f"{v:g}" for v in row) for row in rows]
    lines[1500] = lines[1500].replace(",", " , ")  # one valid line the vectorised path does not take
    np.testing.assert_array_equal(parse_boxes("\n".join(lines), "f"), rows)


def test_box_count_must_match_sequences_csv(tmp_path):
    path = write(tmp_path / "gt.txt", "1,2,3,4\n1,2,3,4\n")
    with pytest.raises(ValueError, match=r"gt.txt:3: file has 2 boxes, expected 3"):
        read_boxes(path, n_expected=3)


def test_fast_and_slow_parsers_agree():
    rng = np.random.default_rng(0)
    values = np.round(rng.uniform(1, 200, (50, 4)), 3)
    comma = "\n".join(",".join(repr(float(v)) for v in row) for row in values) + "\n"
    np.testing.assert_array_equal(parse_boxes(comma, "a"), parse_boxes(comma.replace(",", "\t"), "b"))


# --- layouts -----------------------------------------------------------------------------------------------------
def make_shared(root: Path) -> Path:
    write(root / "groundtruth" / "Car4.txt", "70,51,107,87\n71,52,107,87\n72,53,108,88\n")
    write(root / "groundtruth" / "Jogging-1.txt", "10,10,20,40\n11,10,20,40\n")
    write(root / "groundtruth" / "Board.txt", "5,5,50,50\n0,0,0,0\n")
    write(root / "sequences.csv", "sequence,video_dir,image_folder,n_frames,first_frame\n"
          "Car4,Car4,Car4,3,1\nJogging-1,Jogging-1,Jogging,2,1\nBoard,Board,Board,2,1\n")
    write(root / "attributes.csv", "sequence,IV,SV,OCC\nCar4,1,1,0\nJogging-1,0,0,1\nBoard,0,0,0\n")
    write(root / "trackers" / "T1" / "Car4.txt", "70,51,107,87\n70,51,107,87\n70,51,107,87\n")
    write(root / "trackers" / "T1" / "jogging_1.txt", "10,10,20,40\n")  # short, other spelling
    write(root / "trackers" / "T1" / "Board.txt", "5,5,50,50\n")  # short only on the unannotated frame
    write(root / "trackers" / "T2" / "Car4.txt", "1,1,1,1\n1,1,1,1\n1,1,1,1\n1,1,1,1\n")  # too long
    return root


def test_shared_layout(tmp_path, caplog):
    ds = OTBDataset(make_shared(tmp_path))
    assert ds.layout == "shared" and ds.names == ("Board", "Car4", "Jogging-1") and ds.trackers == ("T1", "T2")
    car4 = ds.sequence("Car4")
    assert car4.n_frames == 3 and car4.first_frame == 1 and car4.attributes == {"IV", "SV"}
    assert ds.sequence("Jogging-1").video == "Jogging"
    assert np.isnan(ds.groundtruth("Board")[1]).all()
    assert ds.tracker_sequences("T1") == ("Board", "Car4", "Jogging-1")
    with caplog.at_level(logging.INFO, logger="bboxtune.envs.data.otb"):
        jog = ds.tracker_boxes("T1", "Jogging-1")
    assert np.isnan(jog[1]).all() and "jogging_1.txt" in caplog.text
    assert any(r.levelno == logging.WARNING for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="bboxtune.envs.data.otb"):
        ds.tracker_boxes("T1", "Board")
    assert [r.levelno for r in caplog.records] == [logging.INFO]  # the padded frame has no ground truth
    with pytest.raises(ValueError, match=r"jogging_1.txt:2: file has 1 boxes, ground truth has 2"):
        ds.tracker_boxes("T1", "Jogging-1", strict=True)
    with pytest.raises(ValueError, match=r"T2/Car4.txt:4: file has 4 boxes, ground truth has 3"):
        ds.tracker_boxes("T2", "Car4")
    with pytest.raises(ValueError, match="no output"):
        ds.tracker_boxes("T2", "Board")
    with pytest.raises(ValueError, match="unknown tracker"):
        ds.tracker_boxes("T3", "Car4")
    with pytest.raises(ValueError, match="unknown sequence"):
        ds.sequence("Nope")


SEQ_HEADER = "sequence,image_folder,n_frames,first_frame\n"


@pytest.mark.parametrize(
    "file, content, message",
    [
        ("sequences.csv", "sequence,image_folder,n_frames,first_frame\nCar4,Car4,three,1\n",
         r"sequences.csv:2: n_frames='three'"),
        ("sequences.csv", "sequence,image_folder,n_frames,first_frame\nCar4,Car4,3,0\n", r"sequences.csv:2: first_frame=0"),
        ("sequences.csv", "sequence,n_frames\nCar4,3\n", r"sequences.csv:1: header .* lacks column"),
        ("sequences.csv", "sequence,image_folder,n_frames,first_frame\nCar4,Car4,4,1\n",
         r"Car4.txt:4: file has 3 boxes, expected 4"),
        ("sequences.csv", "sequence,image_folder,n_frames,first_frame\nCar4,Car4,3,1\nCar5,Car5,3,1\n",
         r"sequences.csv:3: sequence 'Car5' has no ground-truth file"),
        ("attributes.csv", "sequence,IV\nCar4,2\n", r"attributes.csv:2: attribute IV='2'"),
        ("attributes.csv", "sequence,IV\nCar4,1,1\n", r"attributes.csv:2: wrong number of fields"),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,3,1\nBoard,Board,2,1\nCar4,Car4,3,1\n",
         r"sequences.csv:4: duplicate row for sequence 'Car4' \(first at line 2\)"),
        ("sequences.csv", SEQ_HEADER + "\nCar4,Car4,3,1\nCar4,Car4,3,1\n",
         r"sequences.csv:4: duplicate row"),  # the line counts the skipped blank line
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,1_0,1\n", r"sequences.csv:2: n_frames='1_0'"),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,\u0663,1\n", r"sequences.csv:2: n_frames="),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4, 3,1\n", r"sequences.csv:2: n_frames=' 3'"),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,3" + "0" * 30 + ",1\n",
         r"sequences.csv:2: n_frames='30+.* is too long for an integer"),
        ("sequences.csv", "sequence,n_frames,n_frames,first_frame\nCar4,3,4,1\n", r"sequences.csv:1: header .* repeats"),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,3,1\nBo\0ard,Board,2,1\n",
         r"sequences.csv:3: sequence 'Bo\\x00ard' has no ground-truth file"),
        ("sequences.csv", SEQ_HEADER + "Car4,Car4,3,1\nBoard," + "B" * 200_000 + ",2,1\n",
         r"sequences.csv:3: malformed CSV \(field larger than field limit"),
        ("attributes.csv", "sequence,IV\nCar4,1\nCar4,0\n", r"attributes.csv:3: a second row for sequence 'Car4'"),
        ("attributes.csv", "sequence,IV\nCar5,1\n", r"attributes.csv:2: no ground-truth file for sequence 'Car5'"),
    ],
)
def test_shared_layout_bad_tables(tmp_path, file, content, message):
    root = make_shared(tmp_path)
    write(root / file, content)
    with pytest.raises(ValueError, match=message):
        OTBDataset(root).sequence("Car4")


@pytest.mark.parametrize("path", ["sequences.csv", "attributes.csv", "groundtruth/Extra.txt",
                                  "trackers/T1/Car4.txt"])
def test_directory_where_a_file_is_expected_is_named(tmp_path, path):
    root = make_shared(tmp_path)
    target = root / path
    if target.exists():
        target.unlink()
    target.mkdir(parents=True)
    with pytest.raises(ValueError, match=rf"{target}: is (a directory|not a regular file)"):
        OTBDataset(root).tracker_boxes("T1", "Car4")


def test_pipe_large_file_and_missing_file_are_named_errors(tmp_path):
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)  # opening it for reading would block until a writer comes: it must not be opened
    with pytest.raises(ValueError, match=rf"{fifo}: not a regular file"):
        read_boxes(fifo)
    big = tmp_path / "big.txt"
    with open(big, "wb") as f:
        f.truncate(MAX_FILE_BYTES + 1)  # sparse: no disk used
    with pytest.raises(ValueError, match=rf"{big}: file is larger than {MAX_FILE_BYTES} bytes"):
        read_boxes(big)
    with pytest.raises(ValueError, match=rf"{tmp_path / 'none.txt'}: cannot read the file"):
        read_boxes(tmp_path / "none.txt")


def test_trackers_root_and_duplicate_tracker_files(tmp_path):
    root = make_shared(tmp_path)
    write(root / "trackers" / "T1" / "car4.txt", "70,51,107,87\n70,51,107,87\n70,51,107,87\n")
    with pytest.raises(ValueError, match=r"T1/car4.txt: same sequence as Car4.txt"):
        OTBDataset(root).tracker_sequences("T1")
    with pytest.raises(ValueError, match="is not a folder"):
        OTBDataset(root, trackers_root=root / "sequences.csv")
    moved = make_shared(tmp_path / "b")
    for p in sorted((moved / "trackers").rglob("*"), reverse=True):
        p.unlink() if p.is_file() else p.rmdir()
    (moved / "trackers").rmdir()
    write(moved / "trackers", "not a folder")
    with pytest.raises(ValueError, match="trackers'? is not a folder"):
        OTBDataset(moved)


def test_folders_layout_two_targets_and_toolkit_frame_ranges(tmp_path):
    write(tmp_path / "Car4" / "groundtruth_rect.txt", "70\t51\t107\t87\n71\t52\t107\t87\n")
    write(tmp_path / "Car4" / "img" / "0001.jpg", b"")
    write(tmp_path / "Jogging" / "groundtruth_rect.1.txt", "1,2,3,4\n")
    write(tmp_path / "Jogging" / "groundtruth_rect.2.txt", "5,6,7,8\n")
    write(tmp_path / "BlurCar1" / "groundtruth_rect.txt", "1,2,3,4\n1 2 3 4\n")  # the original's mixed lines
    write(tmp_path / "Tiger1" / "groundtruth_rect.txt", "".join(f"{i},1,10,10\n" for i in range(1, 355)))
    ds = OTBDataset(tmp_path)
    assert ds.layout == "folders" and ds.names == ("BlurCar1", "Car4", "Jogging-1", "Jogging-2", "Tiger1")
    assert ds.sequence("Jogging-2").video == "Jogging" and ds.groundtruth("Jogging-2")[0].tolist() == [5, 6, 7, 8]
    assert ds.sequence("BlurCar1").first_frame == 247
    tiger = ds.sequence("Tiger1")  # the OTB toolkit skips the first 5 of 354 lines
    assert tiger.n_frames == 349 and tiger.first_frame == 6 and tiger.gt[0, 0] == 6
    assert ds.trackers == ()


def pysot_entry(rects, first=1, attr=("IV",), video_dir="Car4"):
    return {"video_dir": video_dir, "init_rect": rects[0], "attr": list(attr),
            "img_names": [f"{video_dir}/img/{first + i:04d}.jpg" for i in range(len(rects))], "gt_rect": rects}


def test_pysot_json_layout(tmp_path):
    data = {"Car4": pysot_entry([[70, 51, 107, 87], [71, 52, 107, 87]]),
            "Jogging-2": pysot_entry([[1, 2, 3, 4]], video_dir="Jogging"),
            "BlurCar1": pysot_entry([[1, 2, 3, 4]], first=247, attr=(), video_dir="BlurCar1"),
            "Twinnings": pysot_entry([[1, 2, 3, 4], [0, 0, 0, 0]], video_dir="Twinnings")}
    write(tmp_path / "OTB100.json", json.dumps(data))
    write(tmp_path / "trackers" / "T" / "Car4.txt", "70,51,107,87\n70,51,107,87\n")
    for root in (tmp_path, tmp_path / "OTB100.json"):
        ds = OTBDataset(root)
        assert ds.layout == "pysot" and ds.names == ("BlurCar1", "Car4", "Jogging-2", "Twinnings")
        assert ds.trackers == ("T",) and ds.sequence("Jogging-2").video == "Jogging"
        assert ds.sequence("BlurCar1").first_frame == 247 and ds.sequence("Car4").attributes == {"IV"}
        assert np.isnan(ds.groundtruth("Twinnings")[1]).all()
        assert ds.tracker_boxes("T", "Car4").shape == (2, 4)


@pytest.mark.parametrize(
    "content, message",
    [
        ('{"Car4": {"gt_rect": [[1,2,3,4]],\n "img_names": ["0001.jpg"],}}', r"OTB100.json:2: invalid JSON"),
        ('{"Car4": {"gt_rect": [[1,2,3]], "img_names": ["0001.jpg"]}}', r"'Car4' gt_rect\[0\]: expected 4 numbers"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["1.jpg", "2.jpg"]}}', r"gt_rect has 1 boxes for 2 img_names"),
        ('{"Car4": {"gt_rect": [[1,2,3,4], [1,2,NaN,4]], "img_names": ["1.jpg", "2.jpg"]}}', r"gt_rect\[1\]: non-finite"),
        ('{"Car4": {"gt_rect": [[1,2,3,4], [1,2,-3,4]], "img_names": ["1.jpg", "2.jpg"]}}', r"gt_rect\[1\]: negative size"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]]}}', r"needs keys"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["img/first.jpg"]}}', r"no frame number"),
        ('[]', r"OTB100.json:1: expected a non-empty object"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["1.jpg"]},\n "Car4": {"gt_rect": [[1,2,3,4]], '
         '"img_names": ["1.jpg"]}}', r"OTB100.json: invalid JSON \(duplicate key 'Car4'"),
        ('{"Car4": {"gt_rect": [[1,2,3,' + "4" * 5000 + ']], "img_names": ["1.jpg"]}}', r"longer than 64 characters"),
        ("[" * 100_000, r"OTB100.json: invalid JSON \(.*recursion"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["1.jpg"], "attr": "IV"}}', r"attr='IV'; allowed a list"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": [1]}}', r"lists of boxes and of strings"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["img/0000.jpg"]}}', r"no frame number >= 1"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["img/\u0661.jpg"]}}', r"no frame number >= 1"),
        ('{"Car4": {"gt_rect": [[1,2,3,4]], "img_names": ["' + "1" * 40 + '.jpg"]}}', r"too long for an integer"),
        ('{"Car4": {"gt_rect": [[1,2,3,4], [1,2,1e999,4]], "img_names": ["1.jpg", "2.jpg"]}}', r"gt_rect\[1\]: non-finite"),
        ('{"Car4": {"gt_rect": [[1,2,3,4], [1,2,1e300,4]], "img_names": ["1.jpg", "2.jpg"]}}',
         r"gt_rect\[1\]: box .* is too large; allowed"),
    ],
)
def test_pysot_json_bad_input(tmp_path, content, message):
    write(tmp_path / "OTB100.json", content)
    with pytest.raises(ValueError, match=message):
        OTBDataset(tmp_path)


def test_root_resolution(tmp_path, monkeypatch):
    monkeypatch.delenv("OTB_ROOT", raising=False)
    with pytest.raises(ValueError, match="OTB_ROOT"):
        resolve_root(None)
    monkeypatch.setenv("OTB_ROOT", str(tmp_path))
    assert resolve_root(None) == tmp_path
    with pytest.raises(ValueError, match="does not exist"):
        resolve_root(tmp_path / "missing")
    with pytest.raises(ValueError, match="no OTB layout found"):
        OTBDataset(tmp_path)


# --- split -------------------------------------------------------------------------------------------------------
def test_split_is_deterministic_by_video_and_subset_stable():
    names = [f"Seq{i}" for i in range(200)] + ["Jogging-1", "Jogging-2", "Skating2-1", "Skating2-2"]
    parts = split(names)
    assert sorted(sum(parts.values(), ())) == sorted(names)
    assert split(reversed(names)) == parts
    part_of = {n: k for k, v in parts.items() for n in v}
    assert part_of["Jogging-1"] == part_of["Jogging-2"] and part_of["Skating2-1"] == part_of["Skating2-2"]
    sub = split(names[::3])
    assert all(part_of[n] == k for k, v in sub.items() for n in v)
    assert 0.45 < len(parts["train"]) / len(names) < 0.75 and len(parts["test"]) > 20
    assert video_of("Human4-2") == "Human4" and video_of("Car24") == "Car24"


# --- the real data (OTB_ROOT) ------------------------------------------------------------------------------------
@needs_otb
def test_otb100_contents():
    ds = OTBDataset(OTB_ROOT)
    assert len(ds.names) == 100 and len(ds.trackers) == 13
    gts = {n: ds.groundtruth(n) for n in ds.names}
    assert sum(len(g) for g in gts.values()) == 59035
    missing = {n: np.flatnonzero(np.isnan(g).any(axis=1)).tolist() for n, g in gts.items()}
    assert {n: m for n, m in missing.items() if m} == {"Board": [697], "Twinnings": [471]}
    assert gts["Car4"][0].tolist() == [70, 51, 107, 87] and len(gts["Car4"]) == 659
    assert ds.sequence("Tiger1").first_frame == 6 and ds.sequence("Tiger1").n_frames == 349
    assert ds.sequence("BlurCar1").first_frame == 247 and "SV" in ds.sequence("Car4").attributes
    assert len(ds.tracker_sequences("MEEM")) == 73
    assert np.isnan(ds.tracker_boxes("MDNet", "Board")[-1]).all()
    with pytest.raises(ValueError, match=r"STRUCK/ClifBar.txt:330: file has 329 boxes"):
        ds.tracker_boxes("STRUCK", "ClifBar", strict=True)


@needs_otb
def test_otb100_split_counts():
    parts = split(OTBDataset(OTB_ROOT).names)
    assert {k: len(v) for k, v in parts.items()} == {"train": 55, "val": 22, "test": 23}
    assert {"Jogging-1", "Jogging-2"} <= set(parts["test"]) and {"Car4", "Suv"} <= set(parts["train"])
