"""bboxtune.agents.policies.gate_file: a gate written and read back predicts the same, ±inf margins survive JSON, and
a malformed file
is refused with its name and the field."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.policies.gate_file import Gate, LinearGain, read_gate, write_gate

F = 3


def gate(margin: float) -> Gate:
    return Gate(LinearGain(np.array([1.0, 2.0, 3.0]), np.array([0.5, 1.0, 2.0]), np.array([1.0, -1.0, 0.5]), 0.25), margin)


@pytest.mark.parametrize("margin", [0.1, math.inf, -math.inf])
def test_round_trip(tmp_path: Path, margin: float) -> None:
    write_gate(tmp_path / "g.json", gate(margin), about="a test gate")
    back = read_gate(tmp_path / "g.json", F)
    obs = np.array([[1.0, 2.0, 3.0], [2.0, 1.0, 5.0]])
    assert back.margin == margin and json.loads((tmp_path / "g.json").read_text())["about"] == "a test gate"
    np.testing.assert_array_equal(back.gain.predict(obs), gate(margin).gain.predict(obs))
    assert back.gain.predict(obs).tolist() == [0.25, 2.0 + 1.0 + 0.5 + 0.25]  # ((obs - mean) / scale) · coef + b
    assert back.opens(obs).tolist() == gate(margin).opens(obs).tolist()


@pytest.mark.parametrize(("change", "message"), [
    ({"coef": [1.0, 2.0]}, "coef must be a list of 3 finite numbers"),
    ({"mean": [1.0, "x", 2.0]}, "mean must be a list of 3 finite numbers"),
    ({"scale": [1.0, 0.0, 2.0]}, "scale must be > 0 everywhere"),
    ({"intercept": True}, "intercept=True; expected a finite number"),
    ({"margin": "nan"}, "margin='nan'; expected a finite number"),
    ({"margin": None}, "margin=None; expected a finite number"),
])
def test_malformed_fields_are_named(tmp_path: Path, change: dict, message: str) -> None:
    write_gate(tmp_path / "g.json", gate(0.0), about="x")
    data = {**json.loads((tmp_path / "g.json").read_text()), **change}
    (tmp_path / "g.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=f"g.json: {message}"):
        read_gate(tmp_path / "g.json", F)


def test_unreadable_or_incomplete_files(tmp_path: Path) -> None:
    (tmp_path / "a.json").write_text("{not json")
    (tmp_path / "b.json").write_text("[1, 2]")
    (tmp_path / "c.json").write_text(json.dumps({"margin": 0.0, "mean": [0, 0, 0]}))
    (tmp_path / "e.json").write_text('{"margin": Infinity}')
    for name, message in (("a.json", "a.json:1:2: invalid JSON"), ("b.json", "holds a JSON object, not list"),
                          ("c.json", "scale must be a list of 3"), ("e.json", "non-standard JSON constant Infinity"),
                          ("none.json", "none.json")):
        with pytest.raises(ValueError, match=message):
            read_gate(tmp_path / name, F)
    write_gate(tmp_path / "d.json", gate(0.0), about="x")
    with pytest.raises(ValueError, match="list of 20 finite numbers >= -inf \\(the tuner's features\\)"):
        read_gate(tmp_path / "d.json", 20)  # fitted for another tuner's features
