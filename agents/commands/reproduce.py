"""Reproduce the papers' experiments and write our numbers beside theirs.

    python scripts/reproduce.py --out DIR [--otb-root DIR] [--mc N] [--seed S] [--quick]
    python scripts/reproduce_shmaliy_cmn.py --out DIR [--mc N] [--seed S] [--quick]          # one part alone;
    python scripts/reproduce_mo_fir.py ...  /  python scripts/reproduce_otb.py ... [--otb-root DIR]  # the others

Writes ``DIR/reproduction.md`` (markdown tables: ours vs the paper, one verdict per claim) and PNG figures:

* [Shmaliy-CMN] Fig. 2 (a), (b): RMSE vs ψ of KF, KF-CMN, UFIR, UFIR-CMN, exact and wrong noise statistics;
* [Shmaliy-CMN]: the measured N_opt(ψ) of UFIR-CMN (grid search of N per ψ) vs the paper's 20 / 30 / 100;
* [Mo-FIR] Table I: KF vs Kwon's FIR at sampling-time error δ = 0 and 10;
* Car4 ([Shmaliy-CMN]) and Suv ([PaleRamon-BBox]): OTB ground truth + CMN, filtered with the papers' tuned parameters.

The papers ([Shmaliy-CMN] … [Mo-FIR]) and their full references are in ``docs/references.md``. The OTB experiments need
``--otb-root`` or ``$OTB_ROOT``; without either they are skipped with the reason printed and written into the
markdown (``reproduce_otb.py`` alone refuses to run without them). A part run alone writes
``DIR/reproduction_<part>.md`` and its figures, with the same numbers as in the full run. ``--quick`` (coarse
grids, 6 Monte Carlo runs) finishes in seconds; the default run takes a few minutes on 2 cores.

The whole command line is checked before any work (a bad value exits 2 with one line naming the flag, and
nothing is written). ``DIR`` is created if missing; in an existing ``DIR`` the files of the same names are
replaced and every other file is left alone. Every output file is written atomically (temporary file +
rename). Experiment k draws from ``numpy.random.default_rng([seed, k])``: same seed → same numbers.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import cast

import numpy as np

from bboxtune.agents.cli import ArgumentParser, HelpFormatter, argument_errors, command, int_range, nonnegative_int, out_dir
from bboxtune.agents.reproduce import mo_fir, otb, shmaliy_cmn
from bboxtune.agents.reproduce.common import Section, Settings, make_settings, save_figure
from bboxtune.envs.data.atomic_files import atomic_write_file
from bboxtune.envs.data.otb import OTB_ROOT_ENV, OTBDataset

PARTS = {"shmaliy_cmn": shmaliy_cmn, "mo_fir": mo_fir, "otb": otb}  # part → module; reproduce_<part>.py runs it alone
Experiments = list[tuple[str, Callable[[], Section]]]  # (progress name, experiment returning its Section)


def parse_args(argv: list[str], part: str | None = None) -> argparse.Namespace:
    """Arguments of the full run (``part`` None) or of one part; ``args.dataset`` is the opened OTB data (or
    None). Every check happens here, before any work: a bad value exits 2 with one line."""
    script = "reproduce.py" if part is None else f"reproduce_{part}.py"
    doc = __doc__ if part is None else f"{PARTS[part].__doc__}\nRun alone: {script} --out DIR; see reproduce.py --help."
    parser = ArgumentParser(prog=script, description=doc, formatter_class=HelpFormatter)
    parser.add_argument("--out", required=True, type=out_dir, metavar="DIR",
                        help="output folder (created if missing; files of the same names are replaced)")
    if part in (None, "otb"):
        parser.add_argument("--otb-root", default=None, metavar="DIR",
                            help=f"OTB data (folder or OTB100.json) for Car4 / Suv (default: ${OTB_ROOT_ENV}"
                                 + ("; skipped if neither)" if part is None else ")"))
    parser.add_argument("--mc", type=int_range(2, 10_000), default=None,
                        help="Monte Carlo runs per grid point / noise draws per sequence (default 200; quick 6; "
                             "time and memory grow in proportion)")
    parser.add_argument("--seed", type=nonnegative_int, default=0, help="base random seed")
    parser.add_argument("--quick", action="store_true", help="coarse grids and few runs (seconds; used by the test)")
    args = parser.parse_args(argv)
    args.dataset = open_otb(parser, args.otb_root, required=part == "otb") if part in (None, "otb") else None
    return args


def open_otb(parser: argparse.ArgumentParser, root: str | None, required: bool) -> OTBDataset | None:
    """The OTB data at ``root`` (else ``$OTB_ROOT``) with the ground truth of every OTB case read (so a bad
    folder fails now, naming the flag); None if neither is given and the OTB part is optional."""
    flag = "--otb-root" if root is not None else f"${OTB_ROOT_ENV}"
    root = root if root is not None else os.environ.get(OTB_ROOT_ENV) or None
    if root is None:
        if required:
            parser.error(f"--otb-root: the OTB part needs the OTB data (--otb-root DIR or ${OTB_ROOT_ENV})")
        return None
    with argument_errors(parser, flag):
        dataset = OTBDataset(root)
        for case in otb.CASES:
            dataset.groundtruth(case.sequence)
    return dataset


def run_shmaliy_cmn(settings: Settings) -> Experiments:
    """[Shmaliy-CMN] Fig. 2 and the N_opt(ψ) search, each returning its Section with figures."""

    def fig2() -> Section:
        res = shmaliy_cmn.run_fig2(settings)
        return _with(shmaliy_cmn.section_fig2(res), shmaliy_cmn.figure_fig2(res), shmaliy_cmn)

    def nopt() -> Section:
        res = shmaliy_cmn.run_nopt(settings)
        return _with(shmaliy_cmn.section_nopt(res), shmaliy_cmn.figure_nopt(res), None)

    return [("[Shmaliy-CMN] Fig. 2 (RMSE vs ψ)", fig2), ("[Shmaliy-CMN] N_opt(ψ) search", nopt)]


def run_mo_fir(settings: Settings) -> Experiments:
    """[Mo-FIR] Table I."""

    def table1() -> Section:
        res = mo_fir.run_table1(settings)
        return _with(mo_fir.section_table1(res), mo_fir.figure_table1(res), mo_fir)

    return [("[Mo-FIR] Table I (KF vs Kwon FIR)", table1)]


def run_otb(settings: Settings, dataset: OTBDataset) -> Experiments:
    """One experiment per OTB sequence; the last one also draws the horizon-sweep figure."""
    done: list[otb.OTBResult] = []

    def make(k: int, case: otb.OTBCase) -> Callable[[], Section]:
        def experiment() -> Section:
            res = otb.run_case(case, dataset, settings, experiment=3 + k)
            done.append(res)
            figures = otb.figure_case(res)
            if len(done) == len(otb.CASES):
                figures |= otb.figure_sweeps(done)
            return _with(otb.section_case(res), figures, otb if k == 0 else None)
        return experiment

    return [(f"{case.sequence} ({case.source})", make(k, case)) for k, case in enumerate(otb.CASES)]


def _with(section: Section, figures: dict, module: object | None) -> Section:
    """``section`` with its figures and, first, the set-up text of ``module`` (its docstring after the title)."""
    # (the reproduce modules all have a docstring)
    setup = "" if module is None else cast(str, module.__doc__).split("\n\n", 1)[1].replace("``", "`").strip() + "\n\n"
    section.markdown = setup + section.markdown
    section.figures = figures
    return section


def render(sections: list[Section], command: str, settings: Settings) -> str:
    """The whole ``reproduction.md``."""
    head = [
        "# The papers' experiments, our numbers beside theirs",
        "",
        f"Command: `{command}`  ",
        f"Seed: {settings.seed} (experiment k uses `numpy.random.default_rng([{settings.seed}, k])`); "
        f"Monte Carlo runs per grid point: {settings.mc}; mode: {'quick' if settings.quick else 'full'}; "
        f"numpy {np.__version__}.",
        "",
        "The papers ([Shmaliy-CMN] … [Mo-FIR]) and their full references are in `docs/references.md`. They give few "
        "numbers: [Shmaliy-CMN] has curves only (Fig. 2 is read off the plot, so its claims are compared, not its "
        "values), [Mo-FIR] Table I and [PaleRamon-BBox] §9.2 print RMSEs under set-ups they do not fully state. "
        "Each table row quotes the paper where it has numbers, gives ours, and a one-line verdict; 'agrees' means "
        "the claim holds in our numbers under the threshold stated in brackets.",
        "",
    ]
    body = []
    for k, sec in enumerate(sections, 1):
        body += [f"## {k}. {sec.title}", "", sec.markdown.rstrip(), ""]
        body += [f"![{name}]({name})" for name in sec.figures] + [""]
    return "\n".join(head + body)


@command
def main(argv: list[str] | None = None, part: str | None = None) -> int:
    """Run every experiment (``part`` None) or those of one part (a key of :data:`PARTS`); returns 0."""
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv, part)
    settings = make_settings(args.mc, args.seed, args.quick)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    script = "reproduce.py" if part is None else f"reproduce_{part}.py"
    command = f"python scripts/{script} " + shlex.join(argv)
    print(f"reproduce: seed {settings.seed}, {settings.mc} Monte Carlo runs, "
          f"{'quick' if settings.quick else 'full'} grids → {out}")
    experiments: Experiments = []
    if part in (None, "shmaliy_cmn"):
        experiments += run_shmaliy_cmn(settings)
    if part in (None, "mo_fir"):
        experiments += run_mo_fir(settings)
    skipped = None
    if args.dataset is not None:
        experiments += run_otb(settings, args.dataset)
    elif part is None:
        skipped = f"skipped: no --otb-root given and ${OTB_ROOT_ENV} is not set, so Car4 and Suv were not run"
        print(f"OTB experiments {skipped}")
    sections = []
    for k, (name, experiment) in enumerate(experiments, 1):
        start = time.perf_counter()
        print(f"[{k}/{len(experiments)}] {name} ...", flush=True)
        section = experiment()
        for file_name, fig in section.figures.items():
            save_figure(fig, out / file_name)
        sections.append(section)
        print(f"[{k}/{len(experiments)}] {name}: done in {time.perf_counter() - start:.1f} s "
              f"({', '.join(section.figures)})", flush=True)
    if skipped:
        sections.append(Section("Car4 and Suv (OTB)", f"{skipped[0].upper()}{skipped[1:]}.\n"))
    text = render(sections, command, settings)
    report = out / ("reproduction.md" if part is None else f"reproduction_{part}.md")
    atomic_write_file(report, lambda fh: fh.write(text.encode()))
    print(f"wrote {report}")
    return 0

