"""scripts/reproduce.py --quick: files written, tables with finite numbers, and results of substance."""

from __future__ import annotations

import math
import os
import re

import pytest

from bboxtune.agents.commands import reproduce, reproduce_mo_fir

FIGURES = ("seed000_fig2a.png", "seed000_fig2b.png", "seed000_nopt.png", "seed004_table1.png")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """One --quick run without OTB data (the OTB part must be skipped, with the reason in the markdown)."""
    out = tmp_path_factory.mktemp("repro")
    mp = pytest.MonkeyPatch()
    mp.delenv("OTB_ROOT", raising=False)
    try:
        assert reproduce.main(["--out", str(out), "--quick", "--seed", "3"]) == 0
    finally:
        mp.undo()
    return out, (out / "reproduction.md").read_text()


def _table_rows(markdown: str, first_cell: str) -> list[list[str]]:
    rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in markdown.splitlines()
            if line.startswith("| ")]
    return [r for r in rows if r[0] == first_cell]


def test_files_written_and_no_temporaries(quick_run):
    out, _ = quick_run
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    assert not list(out.glob(".*.tmp")), "temporary files left behind"


def test_markdown_has_command_seed_and_skip_reason(quick_run):
    _, md = quick_run
    assert "python scripts/reproduce.py --out" in md and "--seed 3" in md
    assert "Seed: 3" in md
    assert re.search(r"Skipped: no --otb-root given and \$OTB_ROOT is not set", md)
    for name in FIGURES:
        assert f"]({name})" in md


def test_tables_have_expected_rows_with_finite_numbers(quick_run):
    _, md = quick_run
    fig2 = _table_rows(md, "0.9")
    assert fig2, "Fig. 2 row for ψ = 0.9 missing"
    values = [float(c) for c in fig2[0][1:5]]  # KF, KF-CMN, UFIR, UFIR-CMN
    assert all(math.isfinite(v) and 0 < v < 100 for v in values)
    nopt = _table_rows(md, "0.95")
    assert any(len(r) == 12 and r[1].isdigit() for r in nopt), "N_opt row for ψ = 0.95 missing"
    for label in ("Kalman filter", "Kwon FIR (N = 24)"):
        (row,) = _table_rows(md, label)
        ours = [float(re.match(r"([\d.]+)", c).group(1)) for c in row[1:3]]
        assert all(math.isfinite(v) and v > 0 for v in ours)
        assert row[3:] in (["6.88", "66.43"], ["7.26", "21.57"])  # the paper's Table I quoted
    assert "n/a" not in md


def test_a_part_alone_gives_the_numbers_of_the_full_run(quick_run, tmp_path):
    """reproduce_mo_fir.py = the [Mo-FIR] part of reproduce.py: same Table I rows for the same seed, its own
    markdown file, and the files already in --out that it does not write are left alone."""
    (tmp_path / "keep.txt").write_text("mine")
    assert reproduce_mo_fir.main(["--out", str(tmp_path), "--quick", "--seed", "3"]) == 0
    part = (tmp_path / "reproduction_mo_fir.md").read_text()
    assert "python scripts/reproduce_mo_fir.py --out" in part and "[Shmaliy-CMN] Fig. 2" not in part
    for label in ("Kalman filter", "Kwon FIR (N = 24)"):
        assert _table_rows(part, label) == _table_rows(quick_run[1], label)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt", "reproduction_mo_fir.md", "seed004_table1.png"]
    assert (tmp_path / "keep.txt").read_text() == "mine"


def test_cmn_filters_beat_white_noise_filters_at_high_psi(quick_run):
    """Substance: under exact statistics the CMN-aware KF beats the standard KF at ψ = 0.9 ([Shmaliy-CMN] Fig. 2a)."""
    _, md = quick_run
    kf, kf_cmn = (float(c) for c in _table_rows(md, "0.9")[0][1:3])
    assert kf_cmn < 0.95 * kf


def test_outputs_get_the_usual_permissions(quick_run):
    """mkstemp creates 0600 files; the outputs must get 0666 minus the umask, like any other new file."""
    out, _ = quick_run
    umask = os.umask(0)
    os.umask(umask)
    for path in out.iterdir():
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path.name
