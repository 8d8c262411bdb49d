"""Score real tracker outputs on OTB-100: sequence-averaged success AUC and precision at 20 px.

    python scripts/otb_eval.py --otb-root ../shared/data/otb [--tracker NAME ...] [--json]

Reads ``--otb-root`` (else ``$OTB_ROOT``) in any layout :class:`bboxtune.envs.data.otb.OTBDataset` accepts, with tracker
outputs under ``<root>/trackers/<Tracker>/<Seq>.txt`` (or ``--trackers-root``). Conventions are those of
``bboxtune.envs.data.metrics`` (xywh, frame 1 counts, missing ground truth excluded, missing predictions are failures).
``--json`` prints only ``{tracker: {"success_auc": float, "precision20": float, "n_sequences": int}}``.
A malformed file ends the run with exit status 2 and one line naming the file and line (reading is linear in
the file sizes; limits in :mod:`bboxtune.envs.data.otb_io`); so does a bad command line.
"""

from __future__ import annotations

import json
import logging
import sys

from bboxtune.agents.cli import ArgumentParser, command
from bboxtune.envs.data.metrics import score_sequences
from bboxtune.envs.data.otb import OTBDataset


def evaluate(dataset: OTBDataset, trackers: list[str]) -> dict[str, dict[str, float | int]]:
    """{tracker: {"success_auc", "precision20", "n_sequences"}} over each tracker's available sequences."""
    table: dict[str, dict[str, float | int]] = {}
    for tracker in trackers:
        names = dataset.tracker_sequences(tracker)
        if not names:
            raise ValueError(f"tracker {tracker!r} has no output file for any of the {len(dataset.names)} "
                             "sequences")
        scores = score_sequences(
            [dataset.tracker_boxes(tracker, n) for n in names], [dataset.groundtruth(n) for n in names]
        )
        table[tracker] = {**scores.mean(), "n_sequences": len(names)}
    return table


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="otb_eval.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--otb-root", default=None, help="OTB data folder or OTB100.json (default: $OTB_ROOT)")
    parser.add_argument("--trackers-root", default=None,
                        help="folder of <Tracker>/<Seq>.txt (default: <root>/trackers)")
    parser.add_argument("--tracker", action="append", help="tracker name (repeatable; default: all)")
    parser.add_argument("--json", action="store_true", help="print only the JSON table")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s", stream=sys.stderr)
    try:
        dataset = OTBDataset(args.otb_root, trackers_root=args.trackers_root)
        trackers = args.tracker or list(dataset.trackers)
        if not trackers:
            raise ValueError(f"no tracker outputs found in {dataset.trackers_root}")
        table = evaluate(dataset, trackers)
    except (ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(table))
        return 0
    print(f"{'tracker':<14} {'seqs':>5} {'success AUC':>12} {'precision@20px':>15}")
    for tracker, row in sorted(table.items(), key=lambda kv: -kv[1]["success_auc"]):
        print(f"{tracker:<14} {row['n_sequences']:>5} {row['success_auc']:>12.3f} {row['precision20']:>15.3f}")
    return 0

