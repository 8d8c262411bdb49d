"""Hypothesis strategies of the files a user hands the commands: box tracks (OTB ``x,y,w,h`` lines), MOT lines,
``sequences.csv`` tables, ``seqinfo.ini``, YAML (a run's ``config.yml``, hyperparameters), JSON (tuners, gates,
``sweep.json``, ``OTB100.json``), binary junk and truncated text; and folders in the layouts the commands read
(a train.py run directory, an OTB root, a MOT root or sequence folder, a folder of tracker results).

Also the flag values that are not files' contents: :data:`JUNK` (boundaries, huge, negative, non-finite,
non-ASCII digits, empty, 10 kB), :func:`number`, and :func:`path_value` (missing, wrong-kind, too-long and
generated paths).

Each strategy mixes valid content with one damaged part, so a reader gets past its first line before it meets
the defect. Sizes stay small (a case must run in seconds) except a bounded 10 kB line.
"""

from __future__ import annotations

import json

from hypothesis import strategies as st

TOKENS = ("0", "1", "-1", "10", "1.5", "-0.5", "1e308", "-1e308", "1e400", "nan", "NaN", "inf", "-inf", "", " ",
          "\u0663", "1_0", "abc", "1e7", "10000001", "9" * 40, "0x1f", "1,5")
OTB_NAMES = ("Car4", "Suv", "Basketball", "Biker", "Doll")


def token() -> st.SearchStrategy[str]:
    return st.sampled_from(TOKENS) | st.integers(-10**6, 10**6).map(str) | st.floats(allow_nan=True).map(repr)


def good_box() -> st.SearchStrategy[str]:
    return st.tuples(st.integers(0, 600), st.integers(0, 400), st.integers(1, 200), st.integers(1, 200)).map(
        lambda b: ",".join(map(str, b)))


def bad_box() -> st.SearchStrategy[str]:
    return st.lists(token(), min_size=3, max_size=5).map(",".join) | st.sampled_from(
        ["1e308,1e308,1e308,1e308", "nan,nan,nan,nan", "0,0,0,0", "-5,-5,-1,-1", "1e7,1e7,1,1", "1 2 3 4", "7" * 10_000])


def otb_track() -> st.SearchStrategy[bytes]:
    """``x,y,w,h`` lines: mostly valid (at least 8, the shortest episode), one or two bad ones anywhere."""
    return st.tuples(st.lists(good_box(), min_size=8, max_size=30), st.lists(bad_box(), max_size=2),
                     st.integers(0, 40)).map(lambda t: _splice(t[0], t[1], t[2]))


def mot_line(good: bool) -> st.SearchStrategy[str]:
    if good:
        return st.tuples(st.integers(1, 30), st.integers(1, 4), good_box()).map(
            lambda t: f"{t[0]},{t[1]},{t[2]},1,-1,-1,-1")
    return st.lists(token(), min_size=5, max_size=11).map(",".join)


def mot_file() -> st.SearchStrategy[bytes]:
    return st.tuples(st.lists(mot_line(True), min_size=1, max_size=40), st.lists(mot_line(False), max_size=2),
                     st.integers(0, 40)).map(lambda t: _splice(t[0], t[1], t[2]))


def sequences_csv(kind: str) -> st.SearchStrategy[bytes]:
    if kind == "otb":
        header = "sequence,video_dir,image_folder,n_frames,first_frame,last_frame,img_name_digits,img_ext"
        good = st.sampled_from(OTB_NAMES).map(lambda n: f"{n},{n},{n},30,1,30,4,jpg")
    else:
        header = "sequence,fps,frames,identities,gt_rows,gt_rows_flag0,detections"
        good = st.just("Seq-1,30,30,4,40,0,40")
    bad = st.lists(token(), min_size=1, max_size=9).map(",".join)
    return st.tuples(st.lists(good, min_size=1, max_size=3), st.lists(bad, max_size=1), st.integers(0, 5)).map(
        lambda t: _splice([header, *t[0]], t[1], t[2] + 1))


def seqinfo() -> st.SearchStrategy[bytes]:
    return token().map(lambda v: f"[Sequence]\nname=Seq-1\nframeRate={v}\nseqLength=30\n".encode())


CONFIG = {"algo": "ppo", "env_id": "bboxtune/FilterTune-v0", "env_kwargs": {}, "hyperparams": {}, "seed": 0,
          "total_timesteps": 1000, "eval_freq": 100, "eval_episodes": 2, "checkpoint_freq": 100, "tensorboard": False}


def config_yml() -> st.SearchStrategy[bytes]:
    """A run's ``config.yml``: the valid keys with one value replaced by a generated YAML scalar, or truncated."""
    def render(t: tuple[str, str, int, bool]) -> bytes:
        key, value, cut, truncate = t
        lines = [f"{k}: {json.dumps(v)}" if k != key else f"{k}: {value}" for k, v in CONFIG.items()]
        text = "\n".join(lines) + "\n"
        return (text[: cut % (len(text) + 1)] if truncate else text).encode()
    return st.tuples(st.sampled_from(sorted(CONFIG)), token() | st.sampled_from(["[", "{a: 1}", "- x", "!!python/none", "&a *a"]),
                     st.integers(0, 400), st.booleans()).map(render)


def json_doc() -> st.SearchStrategy[bytes]:
    """A JSON object (a tuner's, a gate's, ``sweep.json``-like), possibly truncated or with non-finite numbers."""
    scalars = st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats() | st.text(max_size=8)
    doc = st.dictionaries(st.sampled_from(["backend", "params", "action", "tau", "version", "trials", "kind", "x"]),
                          scalars | st.lists(scalars, max_size=4), max_size=5)
    return st.tuples(doc, st.integers(0, 300), st.booleans()).map(
        lambda t: (json.dumps(t[0])[: t[1]] if t[2] else json.dumps(t[0])).encode())


def contents() -> st.SearchStrategy[bytes]:
    """The contents of one generated file, of any of the kinds above."""
    return st.one_of(st.binary(max_size=200), otb_track(), mot_file(), sequences_csv("otb"), sequences_csv("mot"),
                     config_yml(), json_doc(), seqinfo(), st.just(b""), st.just(b"7" * 10_000 + b"\n"),
                     st.text(max_size=50).map(str.encode))


def path_name() -> st.SearchStrategy[str]:
    return st.sampled_from(["Car4.txt", "det.txt", "tuned.json", "gate.json", "hp.yml", "OTB100.json", "x.csv", "f"])


def folder() -> st.SearchStrategy[tuple[tuple[str, bytes], ...]]:
    """Files of one folder, relative to it, in one of the layouts the commands read."""
    run = st.tuples(config_yml(), st.binary(max_size=50), st.booleans()).map(
        lambda t: (("config.yml", t[0]), ("command.txt", b"python scripts/train.py\n"),
                   *((("model.zip", t[1]),) if t[2] else ())))
    otb = st.tuples(sequences_csv("otb"), st.sampled_from(OTB_NAMES), otb_track(), otb_track()).map(
        lambda t: (("sequences.csv", t[0]), (f"groundtruth/{t[1]}.txt", t[2]), (f"trackers/SiamFC/{t[1]}.txt", t[3])))
    mot = st.tuples(sequences_csv("mot"), mot_file(), mot_file(), seqinfo()).map(
        lambda t: (("sequences.csv", t[0]), ("Seq-1/det/det.txt", t[1]), ("Seq-1/gt/gt.txt", t[2]),
                   ("Seq-1/seqinfo.ini", t[3])))
    results = st.lists(st.tuples(st.sampled_from(OTB_NAMES).map(lambda n: f"{n}.txt"), otb_track()), min_size=1, max_size=3)
    junk = st.lists(st.tuples(path_name(), contents()), max_size=3)
    return st.one_of(run, otb, mot, results.map(tuple), junk.map(tuple))


def _splice(lines: list[str], bad: list[str], at: int) -> bytes:
    out = list(lines)
    for k, line in enumerate(bad):
        out.insert((at + k) % (len(out) + 1), line)
    return ("\n".join(out) + "\n").encode()


# --- flag values ----------------------------------------------------------------------------------------------
JUNK = ("", "-1", "0", "1e308", "-1e308", "1e400", str(10**30), "nan", "inf", "-inf", "\u0663", "\uff11", "1_0",
        "0x10", " 1", "1 ", "2.5", "-0", "+1", "9" * 19, "a" * 10_000, "\x00", "--", "-", "é,ü")
KV_KEYS = ("track_length", "tau", "otb_root", "trackers", "detector", "psi_range", "learning_rate", "n_steps",
           "batch_size", "n_envs", "gamma", "policy_kwargs", "normalize", "nope", "lr", "split", "backend")


def number(kind: str) -> st.SearchStrategy[str]:
    ints = st.integers(-3, 300).map(str) | st.sampled_from(["1", "2", "8", "10", "100", "10000", "10001", "1000000"])
    floats = st.floats(allow_nan=True, allow_infinity=True).map(repr) | st.sampled_from(["0.5", "1", "1e-9", "30"])
    return (ints if kind == "int" else floats) | st.sampled_from(JUNK)


def path_value(kind: str, junk: bool) -> st.SearchStrategy[tuple[str, tuple[tuple[str, bytes], ...]]]:
    """(argument, files to create) for a path flag of ``kind`` file / dir / out / any: a missing, wrong-kind or
    malformed one (``junk``), else an existing one or one with generated contents."""
    if kind == "out":
        bad = ["{dir}/../file.txt", "{file}", "{under_file}", "", "{root}/" + "n" * 300, "a" * 10_000]
        return st.sampled_from(bad if junk else ["{out}", "{dir}", "{root}/new/deeper"]).map(lambda a: (a, ()))
    bad = ["{missing}", "{under_file}", "", "{root}/" + "n" * 300, "{bad_json}", "{bad_yaml}", "a" * 10_000]
    bad += ["{dir}"] if kind == "file" else ["{file}"] if kind == "dir" else []
    good = ["{file}"] if kind == "file" else ["{otb}", "{mot}", "{mot}/ADL-Rundle-6", "{dir}"]
    plain = st.sampled_from(bad if junk else good).map(lambda a: (a, ()))
    made_file = st.tuples(path_name(), contents()).map(lambda t: ("{root}/gen/" + t[0], (("gen/" + t[0], t[1]),)))
    made_dir = folder().map(lambda files: ("{root}/gen", tuple(("gen/" + p, b) for p, b in files)))
    made = made_file if kind == "file" else made_dir if kind == "dir" else made_file | made_dir
    return plain | made | made if not junk else plain | made
