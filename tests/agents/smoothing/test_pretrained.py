"""The pretrained tuners shipped as package data: every folder loads (without its data set), its spaces and action
map are those of the env its config.yml describes, its files are small and pickle-free, and names are discovered."""

from __future__ import annotations

import fnmatch
import os
import shutil
from pathlib import Path

import gymnasium as gym
import pytest

from bboxtune.agents.policies.gate_file import read_gate
from bboxtune.agents.smoothing import pretrained
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.agents.training.runs import load_config

REPO = Path(__file__).resolve().parents[3]
SHIPPED = pretrained.available()
MAX_BYTES = 1_000_000  # "a few hundred kB" per tuner
OTB_SOURCES = ("otb", "otb_tracker", "mix")


def test_the_seeded_tuners_are_found():
    assert {"sim_ufir_cmn", "sim_kf_cmn"} <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_each_tuner_loads_and_fits_the_env_of_its_config(name):
    cfg = load_config(pretrained.folder(name))
    kwargs = cfg["env_kwargs"]
    if kwargs.get("source") in OTB_SOURCES and not os.environ.get("OTB_ROOT"):
        pytest.skip(reason=f"{name}: source {kwargs['source']} needs the OTB data (set OTB_ROOT)")
    if kwargs.get("source") == "mot" and not os.environ.get("MOT_ROOT"):
        pytest.skip(reason=f"{name}: source mot needs the MOT15 data (set MOT_ROOT)")
    tuner = load_pretrained(name)
    env = gym.make(cfg["env_id"], **kwargs).unwrapped
    model = tuner.policy.model
    assert model.observation_space == env.observation_space and model.action_space == env.action_space
    assert tuner.action_map == env.action_map
    assert tuner.config == env.config and tuner.backend == kwargs["backend"]
    assert load_pretrained(name) is tuner  # cached
    assert (tuner.gate is not None) == (pretrained.folder(name) / "gate.json").exists()


def test_the_default_tracker_tuner_is_gated():
    """Its gate (compare.py --gate on its 9 training trackers: docs/results/otb_tracker_kf_cmn/gated_default) chose to
    leave every track alone."""
    gate = read_gate(pretrained.folder("otb_tracker_kf_cmn") / "gate.json", 20)
    assert gate.margin == float("inf")


@pytest.mark.parametrize("name", SHIPPED)
def test_each_tuner_is_small_complete_and_pickle_free(name):
    path = pretrained.folder(name)
    names = {p.name for p in path.iterdir()}
    assert set(pretrained.FILES) <= names <= set(pretrained.FILES) | set(pretrained.OPTIONAL)
    sizes = {p.name: p.stat().st_size for p in path.iterdir()}
    assert sum(sizes.values()) <= MAX_BYTES, sizes


@pytest.mark.parametrize("name", SHIPPED)
def test_each_summary_is_the_compare_summary_of_its_env(name):
    kwargs = load_config(pretrained.folder(name))["env_kwargs"]
    title = pretrained.summary(name).splitlines()[0]
    assert f"backend {kwargs['backend']}" in title and f"source {kwargs['source']}" in title, title


def test_an_unknown_name_lists_the_available_ones():
    with pytest.raises(ValueError, match="'nope' is not installed; available: " + ", ".join(SHIPPED)):
        load_pretrained("nope")


def test_folders_are_discovered_not_listed(tmp_path, monkeypatch):
    shutil.copytree(pretrained.folder("sim_kf_cmn"), tmp_path / "my_tuner")
    (tmp_path / ".hidden").mkdir()
    (tmp_path / "notes.txt").write_text("not a tuner\n")
    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    assert pretrained.available() == ("my_tuner",)
    tuner = load_pretrained("my_tuner")
    assert tuner.name == "my_tuner" and tuner.backend == "kf_cmn"
    with pytest.raises(ValueError, match="'sim_kf_cmn' is not installed; available: my_tuner$"):
        load_pretrained("sim_kf_cmn")


def test_an_incomplete_folder_names_what_it_lacks(tmp_path, monkeypatch):
    shutil.copytree(pretrained.folder("sim_ufir_cmn"), tmp_path / "partial")
    (tmp_path / "partial" / "vecnormalize.json").unlink()
    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    with pytest.raises(ValueError, match="partial.* lacks vecnormalize.json"):
        load_pretrained("partial")


def test_no_folder_means_none_available(tmp_path, monkeypatch):
    monkeypatch.setattr(pretrained, "ROOT", tmp_path / "absent")
    assert pretrained.available() == ()
    with pytest.raises(ValueError, match="available: none"):
        load_pretrained("sim_ufir_cmn")


def test_the_package_data_ships_every_file():
    tomllib = pytest.importorskip("tomllib", reason="tomllib is Python >= 3.11")
    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["bboxtune.agents"]
    for name in SHIPPED:
        for file in pretrained.FILES:
            relative = f"pretrained/{name}/{file}"
            assert any(fnmatch.fnmatch(relative, pattern) for pattern in patterns), relative
