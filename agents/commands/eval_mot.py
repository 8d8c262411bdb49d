"""Score a tracker's MOT Challenge results on MOT15 with motmetrics: MOTA, IDF1, ID switches (also per identity), MT/ML.

    python scripts/eval_mot.py --results runs/track_mot --gt-root ../shared/data/mot15 --out runs/track_mot_scores.csv
    python scripts/eval_mot.py --results runs/track_mot --sequences KITTI-13

``--results DIR`` holds one file ``<SEQUENCE>.txt`` per sequence, lines ``frame,id,x,y,w,h,score,-1,-1,-1``
(what ``scripts/track_mot.py`` writes); ``--gt-root DIR`` (default: ``$MOT_ROOT``) holds ``<SEQUENCE>/gt/gt.txt``.
Every ``.txt`` file in ``--results`` must name a sequence of ``--gt-root``; every ground-truth sequence needs its
results file unless ``--sequences`` (comma-separated) leaves it out. The scores are motmetrics' own
(:mod:`bboxtune.agents.evaluation.mot_metrics`: flag-0 ground truth ignored, matches need IoU >= 0.5; ``motp`` is
the mean 1 − IoU of the matches; ``switches_per_identity`` is ID switches / ground-truth identities), one row per
sequence and an ``OVERALL`` row. HOTA is not computed (motmetrics has none).

Prints the scores as a markdown table; ``--out FILE`` also writes them as CSV (atomically; an existing file is
never overwritten). Every file is read and checked before anything is scored or written: a bad flag, folder or
data line ends the run with exit status 2 and one line naming it (``file:line`` for a malformed row).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import motmetrics as mm

from bboxtune.agents.cli import ArgumentParser, HelpFormatter, argument_errors, command, existing_dir, new_file
from bboxtune.agents.evaluation import mot_metrics
from bboxtune.agents.evaluation.video_tables import csv_text
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.mot import MOT_ROOT_ENV
from bboxtune.envs.data.mot_io import read_ground_truth, read_results
from bboxtune.envs.data.number_grammar import shorten


def sequence_names(text: str) -> tuple[str, ...]:
    """``--sequences``: distinct comma-separated sequence names (checked against ``--gt-root`` later).

    >>> sequence_names("KITTI-13,ADL-Rundle-6")
    ('KITTI-13', 'ADL-Rundle-6')
    """
    names = tuple(name.strip() for name in text.split(","))
    if not all(names) or len(set(names)) < len(names):
        raise argparse.ArgumentTypeError(f"{shorten(text)}: expected distinct comma-separated sequence names")
    return names


def _gt_root(parser: ArgumentParser, given: Path | None) -> Path:
    """``--gt-root``, else ``$MOT_ROOT`` (an existing folder); one-line error naming whichever was used."""
    if given is not None:
        return given
    env = os.environ.get(MOT_ROOT_ENV)
    if not env:
        parser.error(f"--gt-root: not given and ${MOT_ROOT_ENV} is not set")
    if not Path(env).is_dir():
        parser.error(f"--gt-root: ${MOT_ROOT_ENV}={env!r} is not an existing folder")
    return Path(env)


def chosen_files(parser: ArgumentParser, results: Path, gt_root: Path,
                 sequences: tuple[str, ...] | None) -> dict[str, tuple[Path, Path]]:
    """Sequence → (gt.txt, results file) of the sequences to score (module docstring: the rules)."""
    gts, found = mot_metrics.ground_truth_files(gt_root), mot_metrics.results_files(results)
    if not gts:
        parser.error(f"--gt-root {gt_root}: no <SEQUENCE>/gt/gt.txt in it")
    for name, path in found.items():
        if name not in gts:
            parser.error(f"--results: {path} has no ground truth {gt_root / name / 'gt' / 'gt.txt'} "
                         f"(--gt-root sequences: {', '.join(gts)})")
    for name in sequences or ():
        if name not in gts:
            parser.error(f"--sequences: unknown sequence {shorten(name)!r}; allowed: {', '.join(gts)}")
    names = list(sequences or gts)
    missing = [name for name in names if name not in found]
    if missing:
        hint = "" if sequences else "; --sequences chooses which to score"
        parser.error(f"--results {results}: no results file for {', '.join(missing)} "
                     f"(expected {results / (missing[0] + '.txt')}){hint}")
    return {name: (gts[name], found[name]) for name in names}


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="eval_mot.py", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--results", required=True, type=existing_dir, metavar="DIR",
                        help="folder of <SEQUENCE>.txt results files (MOT Challenge format)")
    parser.add_argument("--gt-root", default=None, type=existing_dir, metavar="DIR",
                        help=f"MOT15 folder with <SEQUENCE>/gt/gt.txt (default: ${MOT_ROOT_ENV})")
    parser.add_argument("--sequences", default=None, type=sequence_names, metavar="A,B",
                        help="score only these sequences (default: every sequence of --gt-root)")
    parser.add_argument("--out", default=None, type=new_file, metavar="FILE.csv",
                        help="also write the scores as CSV to this new file")
    args = parser.parse_args(argv)
    files = chosen_files(parser, args.results, _gt_root(parser, args.gt_root), args.sequences)
    accumulators = {}
    for name, (gt_path, results_path) in files.items():  # every file read and checked before any scoring
        with argument_errors(parser, "--gt-root"):
            gt = read_ground_truth(gt_path)
        with argument_errors(parser, "--results"):
            accumulators[name] = mot_metrics.accumulate(gt, read_results(results_path))
    scores = mot_metrics.score(accumulators)
    rows = [[name, *(row[c] for c in mot_metrics.COLUMNS)] for name, row in scores.items()]
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.out, csv_text(["sequence", *mot_metrics.COLUMNS], rows))
    print(f"MOT15 scores by motmetrics {mm.__version__} (matches: IoU >= {mot_metrics.MOT_IOU}; "
          f"{len(files)} sequence{'' if len(files) == 1 else 's'})\n")
    print(mot_metrics.markdown_table(scores), end="")
    return 0
