"""bboxtune.agents.reproduce.common: settings checks, the verdict cell of each paper's table, the figure writer."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pytest

from bboxtune.agents.reproduce.common import make_settings, save_figure, verdict


def test_bad_mc_is_rejected():
    with pytest.raises(ValueError, match="mc=1"):
        make_settings(1, seed=0, quick=True)


@pytest.mark.parametrize(("agrees", "why", "style", "cell"), [
    (True, "counted above 1.5", "brackets", "agrees (counted above 1.5)"),  # [Mo-FIR] and OTB tables
    (False, "counted above 1.5", "brackets", "**differs** (counted above 1.5)"),
    (True, "", "brackets", "agrees"),
    (True, "a gap below 20 %", "colon", "agrees: a gap below 20 %"),  # [Shmaliy-CMN] tables
    (False, "x", "colon", "**differs**: x"),
    (False, "", "colon", "**differs**"),
])
def test_verdict_cells(agrees, why, style, cell):
    assert verdict(agrees, why, style=style) == cell


def test_save_figure_writes_a_png_and_closes_the_figure(tmp_path):
    fig = plt.figure()
    save_figure(fig, tmp_path / "a.png")
    assert (tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]
