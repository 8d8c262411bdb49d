"""The online FIR engine's kernels (bboxtune.filters.online_fir_kernels) equal their numpy reference (the numpy path
of WindowGroups.newest_positions, ``jit.ENABLED`` off): the window kinds exactly (as ``np.unique`` numbers them),
the newest estimates to ≤ 1e-9 relative, on random spans of every FIR back end with per-track horizons, start-up
windows (spans shorter than the window), missing samples isolated or in runs, undetermined windows (the held latest
measurement) and channels never measured."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import online_fir_kernels
from bboxtune.filters.fir_core import FIRFilter
from bboxtune.filters.online_carry import channel_params
from bboxtune.filters.online_fir import WindowGroups

from ..kernel_modes import both

FIR_FAMILY = ["ufir", "ufir_cmn", "ofir", "oufir", "fir"]


def spans(rng: np.random.Generator, C: int, S: int) -> np.ndarray:
    """Random-walk measurements (C, S) around 200 px with 0–70 % of the samples missing, isolated or in runs; the
    last channel never measured when C > 2."""
    z = 200.0 + np.cumsum(rng.normal(0.0, 2.0, (C, S)), axis=1)
    for c in range(C):
        share = rng.uniform(0.0, 0.7)
        if rng.random() < 0.5:
            z[c, rng.random(S) < share] = np.nan
        else:
            while np.isnan(z[c]).mean() < share:
                start = rng.integers(0, S)
                z[c, start:start + rng.integers(1, 5)] = np.nan
    if C > 2:
        z[-1] = np.nan
    return z


def window_groups(name: str, rng: np.random.Generator, tracks: int) -> WindowGroups:
    f = filters.make(name, filters.constant_velocity(1 / 14, ndim=4), sigma_w=300.0, sigma_v=3.0)
    per_track = {k: np.broadcast_to(np.asarray(f.params[k], dtype=float), (tracks,)).copy() for k in f.PER_TRACK}
    per_track["horizon"] = rng.choice([2.0, 4.0, 8.0], tracks)  # per-track windows of 3 … 9 (+ extra) frames
    if "psi" in per_track:
        per_track["psi"] = rng.choice([0.0, 0.3, 0.9], tracks)
    assert isinstance(f, FIRFilter)
    return WindowGroups(f, channel_params(f, per_track), {})


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), name=st.sampled_from(FIR_FAMILY), tracks=st.integers(1, 6), S=st.integers(1, 14),
       subset=st.booleans())
def test_newest_positions_kernels_equal_reference(seed: int, name: str, tracks: int, S: int, subset: bool) -> None:
    rng = np.random.default_rng(seed)
    windows = window_groups(name, rng, tracks)
    C = tracks * 4
    channels = np.sort(rng.choice(C, int(rng.integers(1, C + 1)), replace=False)) if subset else None
    z = spans(rng, C if channels is None else len(channels), S)
    kernel, reference = both(lambda: windows.newest_positions(z, channels))
    np.testing.assert_array_equal(np.isnan(kernel), np.isnan(reference))
    np.testing.assert_allclose(kernel, reference, rtol=1e-9, atol=1e-9 * np.nanmax(np.abs(z), initial=1.0))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), C=st.integers(1, 40), L=st.integers(1, 12), n_groups=st.integers(1, 5))
def test_window_kinds_equal_numpy_unique(seed: int, C: int, L: int, n_groups: int) -> None:
    rng = np.random.default_rng(seed)
    window = np.where(rng.random((C, L)) < 0.3, np.nan, 1.0)
    lengths = rng.integers(1, L + 1, C)
    group = rng.integers(0, n_groups, C)
    masks = ~np.isnan(window) & (np.arange(L) >= L - lengths[:, None])
    codes = ((masks @ (np.int64(1) << np.arange(L, dtype=np.int64))) + (lengths << L)) * n_groups + group
    unique, first, kind = np.unique(codes, return_index=True, return_inverse=True)
    got_codes, got_first, got_kind = online_fir_kernels.window_kinds(window, lengths, group, n_groups)
    np.testing.assert_array_equal(got_codes, unique)
    np.testing.assert_array_equal(got_first, first)
    np.testing.assert_array_equal(got_kind, kind.reshape(-1))
