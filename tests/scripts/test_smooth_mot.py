"""scripts/smooth.py --format mot: MOT result files, folders of them and MOT sequence folders (det/gt) smoothed per
identity with the tuner's parameters for each identity; gaps filled with score -1; short and gated tracks written as
read; the frame rate from --fps, seqinfo.ini or sequences.csv; misuse (exit 2, one line, nothing written); a
bounded-time fuzz of the --fps and seqinfo.ini parsing; and, with $MOT_ROOT, the MOT15 sequence KITTI-13 end to
end."""

from __future__ import annotations

import math
import os
import re
import shutil
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import agents
from bboxtune.agents.commands import smooth as smooth_script
from bboxtune.agents.policies.gate_file import Gate, LinearGain, write_gate
from bboxtune.agents.smoothing import pretrained
from bboxtune.agents.smoothing.mot_smooth import FPS_RANGE, read_seqinfo_fps
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.envs.data.mot import match_identities
from bboxtune.envs.data.mot_io import read_detections, read_ground_truth, read_results
from bboxtune.envs.data.number_grammar import parse_float

from .cli_misuse import check_misuse, misuse

TUNER = "otb_kf_cmn"  # small, no gate
MOT_ROOT = os.environ.get("MOT_ROOT")
SEQINFO = "[Sequence]\nname={name}\nimDir=img1\nframeRate={fps}\nseqLength=600\nimWidth=1920\nimHeight=1080\n"


@pytest.fixture(autouse=True)
def no_mot_root(monkeypatch):
    """Frame rates come from the test's own files: $MOT_ROOT is unset (the KITTI-13 case reads the variable first)."""
    monkeypatch.delenv("MOT_ROOT", raising=False)


def run(*args: object) -> int:
    return smooth_script.main([str(a) for a in args])


def _boxes(seed: int, T: int) -> np.ndarray:
    """(T, 4) xywh: a box of about 30 x 60 px moving right, with noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    truth = np.stack([100 + 4.0 * t + 40 * seed, 200 + 8 * np.sin(t / 4), np.full(T, 30.0), np.full(T, 60.0)], axis=1)
    return truth + rng.normal(0, [1.5, 1.5, 0.5, 0.5], (T, 4))


def track_lines(ident: int, first: int, boxes: np.ndarray, gaps: set[int] = frozenset(), scores=None) -> dict:
    """{(frame, id): result line} of one identity (no line at the frames in ``gaps``)."""
    out = {}
    for t, box in enumerate(boxes):
        frame = first + t
        if frame not in gaps:
            score = f"{0.5 + t / 64:g}" if scores is None else scores[t]
            out[frame, ident] = f"{frame},{ident},{','.join(f'{v:.2f}' for v in box)},{score},-1,-1,-1"
    return out


def write_mot(path: Path, lines: dict) -> Path:
    """A result file of ``lines`` sorted by frame, then id (the MOT devkit's order)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(lines[key] + "\n" for key in sorted(lines)))
    return path


def two_identities(path: Path) -> Path:
    """Identity 1: frames 1..20 without rows at 8..10; identity 2: frames 5..16; identity 7: frames 3..6 (short)."""
    lines = track_lines(1, 1, _boxes(1, 20), gaps={8, 9, 10})
    lines |= track_lines(2, 5, _boxes(2, 12), scores=["1"] * 12)
    lines |= track_lines(7, 3, _boxes(3, 4))
    return write_mot(path, lines)


def by_identity(path: Path) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """{id: (frames, boxes, scores)} of a result file, each in frame order."""
    res = read_results(path)
    out = {}
    for ident in np.unique(res.id):
        rows = np.flatnonzero(res.id == ident)
        rows = rows[np.argsort(res.frame[rows])]
        out[int(ident)] = (res.frame[rows], res.box[rows], res.score[rows])
    return out


def spanned(frames: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(T, 4) boxes from the first to the last frame, NaN rows where a frame has no row."""
    out = np.full((frames[-1] - frames[0] + 1, 4), np.nan)
    out[frames - frames[0]] = boxes
    return out


def params_table(out: Path) -> dict[tuple[str, str], dict[str, str]]:
    lines = [line.split(",") for line in (out / "params.csv").read_text().splitlines()]
    return {(row[0], row[1]): dict(zip(lines[0], row, strict=True)) for row in lines[1:]}


def test_two_identities_with_a_gap(tmp_path, capsys):
    """Gap rows are filled with score -1, input rows keep frame, id and score, the boxes are Tuner.smooth's with the
    parameters chosen for each identity alone; the short identity is written as read."""
    source = two_identities(tmp_path / "in" / "Seq-A.txt")
    out = tmp_path / "out"
    assert run("--format", "mot", "--results", source, "--out", out, "--pretrained", TUNER, "--fps", 25) == 0
    assert sorted(p.name for p in out.iterdir()) == ["Seq-A.txt", "params.csv"]
    text = (out / "Seq-A.txt").read_text().splitlines()
    keys = [tuple(map(int, line.split(",")[:2])) for line in text]
    assert keys == sorted(keys) and len(keys) == len(set(keys))  # sorted by frame, then id
    assert all(line.endswith(",-1,-1,-1") for line in text)
    raw, written, tuner, tau = by_identity(source), by_identity(out / "Seq-A.txt"), load_pretrained(TUNER), 1 / 25
    table = params_table(out)
    for ident in (1, 2):
        frames, boxes, scores = raw[ident]
        measured = spanned(frames, boxes)
        params = tuner.tune(measured, tau)
        out_frames, out_boxes, out_scores = written[ident]
        np.testing.assert_array_equal(out_frames, np.arange(frames[0], frames[-1] + 1))
        np.testing.assert_allclose(out_boxes, tuner.smooth(measured, tau, params), atol=5.1e-4)  # 3 decimals
        filled = np.isnan(measured).any(axis=1)
        np.testing.assert_array_equal(out_scores[~filled], scores)
        assert (out_scores[filled] == -1).all()
        row = table["Seq-A.txt", str(ident)]
        assert [row[k] for k in ("fps", "n_frames", "n_rows_in", "n_filled", "n_dropped", "left_alone")] == \
            ["25", str(len(measured)), str(len(frames)), str(int(filled.sum())), "0", "0"]
        assert {k: row[k] for k in params} == {k: str(v) for k, v in params.items()}  # exact
    assert table["Seq-A.txt", "1"]["n_filled"] == "3"
    short = [line for line in source.read_text().splitlines() if line.split(",")[1] == "7"]
    assert [line for line in text if line.split(",")[1] == "7"] == short  # as read, byte for byte
    assert [table["Seq-A.txt", "7"][k] for k in ("n_frames", "n_rows_in", "n_filled", "left_alone", "psi")] == \
        ["4", "4", "0", "1", ""]
    printed = capsys.readouterr().out
    assert "smoothed 2 of 3 identities with otb_kf_cmn (kf_cmn); written as read: 1 under 8 frames; 3 gap rows" in \
        printed


def test_a_folder_of_two_result_files(tmp_path):
    """Each file of a folder is smoothed as it would be alone; files other than *.txt are ignored."""
    two_identities(tmp_path / "tracker" / "Seq-A.txt")
    write_mot(tmp_path / "tracker" / "Seq-B.txt", track_lines(3, 10, _boxes(5, 30), gaps={20, 21}))
    (tmp_path / "tracker" / "notes.md").write_text("not a result file\n")
    common = ("--format", "mot", "--pretrained", TUNER, "--fps", 30)
    assert run(*common, "--results", tmp_path / "tracker", "--out", tmp_path / "out") == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["Seq-A.txt", "Seq-B.txt", "params.csv"]
    params = (tmp_path / "out" / "params.csv").read_text().splitlines()
    for name in ("Seq-A.txt", "Seq-B.txt"):
        alone = tmp_path / f"alone-{name}"
        assert run(*common, "--results", tmp_path / "tracker" / name, "--out", alone) == 0
        assert (tmp_path / "out" / name).read_text() == (alone / name).read_text()
        assert set((alone / "params.csv").read_text().splitlines()[1:]) <= set(params)
    assert len(params) == 1 + 3 + 1


def write_sequence(folder: Path, fps: int | None = None) -> None:
    """A tiny MOT15 sequence: identities 1 and 2 over frames 1..12 (identity 1 undetected at frames 5 and 6), a
    flag-0 identity, a false detection; a seqinfo.ini with ``fps`` (None: none)."""
    gt, det = [], []
    for ident, first in ((1, 1), (2, 1)):
        truth = _boxes(10 + ident, 12)
        for t, box in enumerate(truth):
            gt.append(f"{first + t},{ident},{','.join(f'{v:.2f}' for v in box)},1,-1,-1,-1")
            if not (ident == 1 and first + t in (5, 6)):
                shifted = box + np.array([0.7, -0.4, 0.3, 0.2])
                det.append(f"{first + t},-1,{','.join(f'{v:.2f}' for v in shifted)},{10 * ident + t / 4:g},-1,-1,-1")
    gt += [f"{f},3,500,500,20,40,0,-1,-1,-1" for f in (1, 2, 3)]
    det.append("2,-1,900,50,25,50,3.5,-1,-1,-1")  # matched to no identity
    (folder / "det").mkdir(parents=True)
    (folder / "gt").mkdir()
    (folder / "det" / "det.txt").write_text("\n".join(det) + "\n")
    (folder / "gt" / "gt.txt").write_text("\n".join(gt) + "\n")
    if fps is not None:
        (folder / "seqinfo.ini").write_text(SEQINFO.format(name=folder.name, fps=fps))


def test_a_sequence_folder_with_det_and_gt_and_its_seqinfo_frame_rate(tmp_path, capsys):
    """Public detections matched to the ground-truth identities are written per identity (the detection's score;
    the frames without a matched detection filled); τ from the folder's seqinfo.ini."""
    folder = tmp_path / "Tiny-1"
    write_sequence(folder, fps=20)
    out = tmp_path / "out"
    assert run("--format", "mot", "--results", folder, "--out", out, "--pretrained", TUNER) == 0
    assert sorted(p.name for p in out.iterdir()) == ["Tiny-1.txt", "params.csv"]
    det, gt = read_detections(folder / "det" / "det.txt"), read_ground_truth(folder / "gt" / "gt.txt")
    det_of_gt = match_identities(det, gt)
    written, tuner = by_identity(out / "Tiny-1.txt"), load_pretrained(TUNER)
    assert sorted(written) == [1, 2]
    for ident in (1, 2):
        rows = np.flatnonzero((gt.id == ident) & (det_of_gt >= 0))
        measured = spanned(gt.frame[rows], det.box[det_of_gt[rows]])
        frames, boxes, scores = written[ident]
        np.testing.assert_array_equal(frames, np.arange(1, 13))
        np.testing.assert_allclose(boxes, tuner.smooth(measured, 1 / 20), atol=5.1e-4)
        filled = np.isnan(measured).any(axis=1)
        np.testing.assert_array_equal(scores[~filled], det.score[det_of_gt[rows]])
        assert (scores[filled] == -1).all() and filled.sum() == (2 if ident == 1 else 0)
    assert {row["fps"] for row in params_table(out).values()} == {"20"}
    printed = capsys.readouterr().out
    assert f"Tiny-1.txt: 2 identities, 20 fps ({folder.resolve() / 'seqinfo.ini'}); 1 detections matched" in printed


@pytest.mark.parametrize("where", ["beside", "above", "--fps", "sequences.csv"])
def test_where_the_frame_rate_comes_from(tmp_path, where):
    """A seqinfo.ini in the result file's folder or the one above; --fps before it; else the --mot-root's
    sequences.csv row of the sequence."""
    folder = tmp_path / "Seq-A" / "res"
    source = two_identities(folder / "Seq-A.txt")
    ini = {"beside": folder, "above": folder.parent, "--fps": folder}.get(where)
    if ini is not None:
        (ini / "seqinfo.ini").write_text(SEQINFO.format(name="Seq-A", fps=12))
    extra = {"--fps": ("--fps", "40"), "sequences.csv": ("--mot-root", tmp_path / "root")}.get(where, ())
    (tmp_path / "root").mkdir()
    (tmp_path / "root" / "sequences.csv").write_text("sequence,fps,frames\nOther,30,100\nSeq-A,15,20\n")
    out = tmp_path / "out"
    assert run("--format", "mot", "--results", source, "--out", out, "--pretrained", TUNER, *extra) == 0
    fps = {"beside": "12", "above": "12", "--fps": "40", "sequences.csv": "15"}[where]
    assert {row["fps"] for row in params_table(out).values()} == {fps}
    frames, boxes, _ = by_identity(source)[2]
    np.testing.assert_allclose(by_identity(out / "Seq-A.txt")[2][1],
                               load_pretrained(TUNER).smooth(spanned(frames, boxes), 1 / float(fps)), atol=5.1e-4)


def test_a_gated_tuner_leaves_tracks_byte_for_byte_as_read(tmp_path, capsys):
    """Where the gate stays closed a track is written as read: the output is the input file (no gaps filled), with
    its spacing, number forms and world coordinates; params.csv still has the model's parameters."""
    lines = {key: line.replace(",", ", ") for key, line in track_lines(1, 1, _boxes(1, 20), gaps={8, 9}).items()}
    lines |= {key: line[:-len("-1,-1,-1")] + "3.5,11.7,0.65" for key, line in track_lines(4, 2, _boxes(4, 10)).items()}
    lines[1, 1] = "1.0,1,   100.00,200.0,30,60,9e-1,-1,-1,-1"
    source = write_mot(tmp_path / "in" / "Seq-A.txt", lines)
    gate = tmp_path / "closed.json"
    write_gate(gate, Gate(LinearGain(np.zeros(20), np.ones(20), np.zeros(20), 0.0), 0.0), about="test")
    out = tmp_path / "out"
    assert run("--format", "mot", "--results", source, "--out", out, "--pretrained", TUNER, "--fps", 30,
               "--gate", gate) == 0
    assert (out / "Seq-A.txt").read_bytes() == source.read_bytes()
    table = params_table(out)
    tuner = load_pretrained(TUNER)
    frames, boxes, _ = by_identity(source)[1]
    assert [table["Seq-A.txt", "1"][k] for k in ("n_filled", "left_alone", "psi")] == \
        ["0", "1", str(tuner.tune(spanned(frames, boxes), 1 / 30)["psi"])]
    assert "smoothed 0 of 2 identities" in capsys.readouterr().out


@pytest.mark.parametrize("name", pretrained.available())
def test_agents_smooth_works_for_every_pretrained_name(name):
    boxes = _boxes(0, 16)
    boxes[5:7] = np.nan
    expected = load_pretrained(name).smooth(boxes, 0.05)
    np.testing.assert_array_equal(agents.smooth(boxes, 0.05, pretrained=name), expected)


@pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is unset: the end-to-end case smooths the MOT15 sequence "
                                         "KITTI-13 (CI: MOT_ROOT=../shared/data/mot15)")
def test_kitti_13_end_to_end(tmp_path, monkeypatch, capsys):
    """The real sequence folder: every identity with a matched detection is written, τ = 1/10 s from $MOT_ROOT's
    sequences.csv, and each smoothed identity equals Tuner.smooth of its matched detections."""
    monkeypatch.setenv("MOT_ROOT", MOT_ROOT)
    folder = Path(MOT_ROOT) / "KITTI-13"
    out = tmp_path / "out"
    assert run("--format", "mot", "--results", folder, "--out", out, "--pretrained", TUNER) == 0
    det, gt = read_detections(folder / "det" / "det.txt"), read_ground_truth(folder / "gt" / "gt.txt")
    det_of_gt = match_identities(det, gt)
    ids = sorted(set(gt.id[det_of_gt >= 0].tolist()))
    written, table, tuner = by_identity(out / "KITTI-13.txt"), params_table(out), load_pretrained(TUNER)
    assert sorted(written) == ids and sorted(int(i) for _, i in table) == ids
    n_rows = sum(len(frames) for frames, _, _ in written.values())
    assert n_rows == len((out / "KITTI-13.txt").read_text().splitlines())
    assert n_rows == sum(int(r["n_rows_in"]) + int(r["n_filled"]) for r in table.values())
    assert {r["fps"] for r in table.values()} == {"10"}
    for ident in ids:
        rows = np.flatnonzero((gt.id == ident) & (det_of_gt >= 0))
        rows = rows[np.argsort(gt.frame[rows])]
        measured = spanned(gt.frame[rows], det.box[det_of_gt[rows]])
        frames, boxes, scores = written[ident]
        if table["KITTI-13.txt", str(ident)]["left_alone"] == "1":
            np.testing.assert_array_equal(boxes, det.box[det_of_gt[rows]])
            continue
        np.testing.assert_allclose(boxes, tuner.smooth(measured, 0.1), atol=5.1e-4)
        np.testing.assert_array_equal(scores[np.isfinite(measured).all(axis=1)], det.score[det_of_gt[rows]])
    assert "KITTI-13.txt: 37 identities, 10 fps" in capsys.readouterr().out


# --- misuse ------------------------------------------------------------------------------------------------------
@pytest.fixture
def mot_inputs(misuse_paths) -> None:
    """Placeholders for the MOT misuse cases: a valid result file without a frame rate, malformed inputs."""
    root = misuse_paths.root
    names = misuse_paths.names
    names["mot"] = str(two_identities(root / "plain" / "Seq-A.txt"))
    row = "1,10,20,30,40,1,-1,-1,-1\n"  # id, box, score, X, Y, Z
    for name, text in (("bad_line", f"1,{row}2,{row}3,1,10,x,30,40,1,-1,-1,-1\n"),
                       ("repeat", f"1,{row}1,{row}"), ("zero_w", f"1,{row}2,1,10,20,0,40,1,-1,-1,-1\n"),
                       ("long_span", f"1,{row}10000000,{row}")):
        (root / name).mkdir()
        names[name] = str(root / name / "Seq-A.txt")
        Path(names[name]).write_text(text)
    for name, ini in (("bad_ini", "[Sequence]\nframeRate\n"), ("zero_rate", SEQINFO.format(name="Seq-A", fps=0)),
                      ("no_rate", "[Sequence]\nname=Seq-A\n"),
                      ("text_rate", SEQINFO.format(name="Seq-A", fps="30fps"))):
        shutil.copytree(root / "plain", root / name)
        (root / name / "seqinfo.ini").write_text(ini)
        names[name] = str(root / name / "Seq-A.txt")
        names[f"{name}_ini"] = str((root / name / "seqinfo.ini").resolve())
    (root / "det_only" / "det").mkdir(parents=True)
    (root / "det_only" / "det" / "det.txt").write_text("1,-1,10,20,30,40,1,-1,-1,-1\n")
    names["det_only"] = str(root / "det_only")
    (root / "csv_root").mkdir()
    (root / "csv_root" / "sequences.csv").write_text("sequence,fps,frames\nOther,30,100\n")
    names["csv_root"] = str(root / "csv_root")


MOT = ("--format", "mot", "--out", "{out}", "--results")
CASES = [
    misuse("--format", "xml", "--results", "{mot}", "--out", "{out}", mentions="--format"),
    misuse("--format", "--results", "{mot}", "--out", "{out}", mentions="--format"),
    misuse(*MOT, "{dir}", mentions="holds neither MOT result files"),  # no .txt files, no det/gt
    misuse(*MOT, "{missing}", mentions="--results"),
    misuse(*MOT, "{file}", "--fps", "30", mentions="{file}:1"),  # not a MOT result file
    misuse(*MOT, "{bad_line}", "--fps", "30", mentions="{bad_line}:3"),
    misuse(*MOT, "{repeat}", "--fps", "30", mentions="{repeat}:2: repeats frame 1, id 1 of line 1"),
    misuse(*MOT, "{zero_w}", "--fps", "30", mentions="{zero_w}:2"),
    misuse(*MOT, "{long_span}", "--fps", "30", mentions="{long_span}: its 1 tracks span 10000000 frames"),
    misuse(*MOT, "{det_only}", "--fps", "30", mentions="has no gt/gt.txt"),
    misuse(*MOT, "{mot}", mentions="no frame rate for Seq-A"),  # no --fps, seqinfo.ini, --mot-root or $MOT_ROOT
    misuse(*MOT, "{mot}", "--mot-root", "{csv_root}", mentions="sequences.csv has no row 'Seq-A'; pass --fps F"),
    misuse(*MOT, "{mot}", env={"MOT_ROOT": "{missing}"}, mentions="MOT root '{missing}' does not exist"),
    misuse(*MOT, "{mot}", "--mot-root", "{missing}"),
    misuse(*MOT, "{mot}", "--mot-root", "{file}"),
    misuse(*MOT, "{bad_ini}", mentions="{bad_ini_ini}:2: expected key=value"),
    misuse(*MOT, "{zero_rate}", mentions="{zero_rate_ini}: frameRate: frame rate 0; allowed 1 <= fps <= 1000"),
    misuse(*MOT, "{no_rate}", mentions="{no_rate_ini}: no frameRate= in section [Sequence]"),
    misuse(*MOT, "{text_rate}", mentions="{text_rate_ini}: frameRate='30fps' is not a number"),
    *[misuse(*MOT, "{mot}", "--fps", v) for v in ("0", "0.5", "1001", "-30", "nan", "inf", "abc", "1_0", "")],
    misuse(*MOT, "{mot}", "--fps"),  # no value
    misuse(*MOT, "{mot}", "--fps", "30", "--tau", "0.04", mentions="--tau is for --format otb"),
    misuse(*MOT, "{mot}", "--fps", "30", "--otb-root", "{dir}", mentions="--otb-root is for --format otb"),
    misuse("--results", "{dir}", "--out", "{out}", "--fps", "30", mentions="--fps is for --format mot"),
    misuse("--results", "{dir}", "--out", "{out}", "--mot-root", "{dir}", mentions="--mot-root is for --format mot"),
    misuse("--results", "{mot}", "--out", "{out}", mentions="--results: {mot} is not a folder"),  # otb: a folder
    misuse(*MOT, "{mot}", "--fps", "30", "--gate", "{missing}"),
    misuse(*MOT, "{mot}", "--fps", "30", "--pretrained", "nope", mentions="pretrained tuner 'nope' is not installed"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_misuse(case, mot_inputs, misuse_paths, capsys, monkeypatch):
    check_misuse(smooth_script.main, case, misuse_paths, capsys, monkeypatch)


# --- fuzz: --fps and seqinfo.ini ---------------------------------------------------------------------------------
DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")  # bboxtune.envs.data.number_grammar's number, ASCII digits


@settings(max_examples=300, deadline=timedelta(seconds=5))  # the deadline only catches a (near-)hang
@given(text=st.one_of(st.text("0123456789.eE+-_ n", max_size=12), st.floats().map(repr), st.text(max_size=8),
                      st.integers(-10, 2000).map(str)))
def test_fps_flag_takes_exactly_decimals_from_1_to_1000(tmp_path_factory, text):
    base = tmp_path_factory.getbasetemp()
    accepted = (DECIMAL.fullmatch(text) is not None and text.isascii() and len(text) <= 64
                and math.isfinite(float(text)) and FPS_RANGE[0] <= float(text) <= FPS_RANGE[1])
    try:
        args = smooth_script.build_parser().parse_args(
            ["--format", "mot", "--results", str(base), "--out", str(base / "never"), "--fps", text])
    except SystemExit as stop:
        assert stop.code == 2 and not accepted, text
        return
    assert accepted and args.fps == float(text), text


KEYS = ("name", "imDir", "seqLength")
RATE_KEYS = ("frameRate", "framerate", "FRAMERATE")  # ini keys are case-insensitive
_values = st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")), max_size=12)
_rates = st.one_of(st.integers(1, 1000).map(str), st.floats(1, 1000).map(repr), st.integers(-5, 1500).map(str),
                   st.floats().map(repr), _values,
                   st.sampled_from(["30", "29.97", " 25 ", "1e3", "1000.0001", ".5", "30 ; comment", "1_0", ""]))


@st.composite
def seqinfo_files(draw) -> tuple[str, float | str | None]:
    """(text, expected): an ini of sections and keys (now and then a repeated one), comments and blank lines;
    expected is the frame rate, "error", or None where a random noise line makes it unknown."""
    sections = draw(st.lists(st.sampled_from(["Other", "sequence"]), max_size=2, unique=True))
    sections[draw(st.integers(0, len(sections))):0] = ["Sequence"] * draw(st.sampled_from([1, 1, 1, 1, 1, 1, 0, 2]))
    lines, rate, error = [], None, len(set(sections)) < len(sections)
    for section in sections:
        lines.append(f"[{section}]")
        keys = draw(st.lists(st.sampled_from(KEYS), max_size=3, unique=draw(st.sampled_from([True, True, False]))))
        for _ in range(draw(st.sampled_from([1, 1, 1, 1, 1, 0, 0, 2]))):
            keys.insert(draw(st.integers(0, len(keys))), draw(st.sampled_from(RATE_KEYS)))
        error |= len({k.lower() for k in keys}) < len(keys)
        for key in keys:
            value = draw(_rates if key in RATE_KEYS else _values)
            lines.append(f"{key}{draw(st.sampled_from(['=', ' = ', ': ']))}{value}")
            if section == "Sequence" and key in RATE_KEYS:
                rate = value.strip()
        if draw(st.booleans()):
            lines.insert(draw(st.integers(1, len(lines))), draw(st.sampled_from(["", "# a comment", "; another"])))
    try:
        fps = parse_float(rate) if rate is not None else math.nan
    except ValueError:
        fps = math.nan
    expected = "error" if error or not FPS_RANGE[0] <= fps <= FPS_RANGE[1] else fps
    if draw(st.integers(0, 3)) == 3:
        lines.insert(draw(st.integers(0, len(lines))), draw(st.text(max_size=30).map(lambda t: t.replace("\n", ""))))
        expected = None
    return "\n".join(lines) + draw(st.sampled_from(["\n", ""])), expected


@settings(max_examples=200, deadline=timedelta(seconds=5))  # the deadline only catches a (near-)hang
@given(ini=seqinfo_files())
def test_seqinfo_frame_rate_parses_as_the_reference_or_names_the_file(tmp_path_factory, ini):
    text, expected = ini
    path = tmp_path_factory.getbasetemp() / "seqinfo.ini"
    path.write_text(text, encoding="utf-8")
    try:
        fps = read_seqinfo_fps(path)
    except ValueError as err:
        message = str(err)
        assert message.startswith(f"{path}") and "\n" not in message, message
        assert expected in ("error", None), (text, message)
        return
    assert FPS_RANGE[0] <= fps <= FPS_RANGE[1]
    assert expected is None or fps == expected, (text, fps)


@pytest.mark.parametrize("peer", ["bytetrack_kf", "sort_kf"])
def test_stock_filter_in_the_tuners_place(tmp_path: Path, peer: str) -> None:
    """--filter: the published filter smooths every track (nothing left alone, no parameters chosen)."""
    from bboxtune.agents.commands import smooth as smooth_command
    from bboxtune.agents.smoothing.stock_filter import StockFilter

    rows = [f"{f},1,{100 + 2 * f},50,30,60,0.9,-1,-1,-1" for f in range(1, 21) if f not in (8, 9, 10)]
    results = tmp_path / "trk.txt"
    results.write_text("\n".join(rows) + "\n")
    out = tmp_path / "out"
    assert smooth_command.main(["--format", "mot", "--results", str(results), "--fps", "30", "--filter", peer,
                                "--out", str(out)]) == 0
    lines = (out / "trk.txt").read_text().splitlines()
    assert [int(line.split(",")[0]) for line in lines] == list(range(1, 21))  # the gap 8-10 filled
    assert all(line.split(",")[6] == "-1" for line in lines[7:10])
    boxes = np.array([[100 + 2 * f, 50, 30, 60] if f not in (8, 9, 10) else [np.nan] * 4 for f in range(1, 21)], float)
    expected = StockFilter(peer).smooth(boxes, 1 / 30)
    written = np.array([[float(v) for v in line.split(",")[2:6]] for line in lines])
    np.testing.assert_allclose(written, expected, atol=5e-4)
    header = (out / "params.csv").read_text().splitlines()[0]
    assert header.endswith("left_alone")  # no parameters chosen


def test_stock_filter_refuses_a_gate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from bboxtune.agents.commands import smooth as smooth_command

    (tmp_path / "trk.txt").write_text("1,1,10,10,5,5,1,-1,-1,-1\n")
    with pytest.raises(SystemExit):
        smooth_command.main(["--format", "mot", "--results", str(tmp_path / "trk.txt"), "--fps", "30",
                             "--filter", "sort_kf", "--no-gate", "--out", str(tmp_path / "o")])
    assert "--gate / --no-gate apply to a tuner" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
