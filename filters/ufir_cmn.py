"""UFIR-CMN: the UFIR filter for Gauss–Markov coloured measurement noise ([Shmaliy-CMN] Alg. 2; notes §1.3).

Measurement noise ``v_l = ψ v_{l−1} + ξ_l`` is whitened by differencing ([Shmaliy-CMN] eqs. 4–5, backward Euler):

    z_l = y_l − ψ y_{l−1} = D x_l + v̄_l,      D = H − ψ H F⁻¹        (CV model: D = [1 − ψ, ψτ])

and UFIR-CMN is the ordinary UFIR of :mod:`bboxtune.filters.ufir` applied to (z, D): over the horizon of N
differenced samples ``z_m … z_n`` (N + 1 raw samples ``y_{m−1} … y_n``), with rows ``D F^{−(n−l)}``,

    x̂_n = (C̄ᵀ C̄)⁻¹ C̄ᵀ Z,      C̄ = [D F^{−(N−1)}; …; D F^{−1}; D]

folded into a gain on the raw window (``z_l`` puts weight w on y_l and −ψ w on y_{l−1}). ψ = 0 gives UFIR.
No noise statistics enter (σ_w, σ_v only set the default horizon by the white-noise N_opt rule, which is
too short for ψ ≳ 0.5 — notes §4; pass ``horizon`` explicitly).

Rows without a predecessor (``Ψ_l = 0`` in Alg. 2's time-varying notation): the track's first frame and a
sample right after a missing one enter undifferenced, ``z_l = y_l`` with row ``H F^{−(n−l)}`` — so start-up
(n < N: growing horizon, frames 0 … n) uses ``[y_0, z_1, …, z_n]`` and ψ = 0 reproduces UFIR on every frame,
gaps included. The oldest raw sample of a full window is only the predecessor of the next. A missing y_l
gives no row. Windows whose rows do not determine the state (fewer than 2, or a rank-deficient pattern) output
the latest valid measurement as position and velocity 0. :func:`bboxtune.filters.ufir.ufir_iterative` with ``psi`` is
the literal Algorithm 2 reference under the same conventions. The vectorised start-up and NaN-window forms are
inherited from :class:`bboxtune.filters.ufir.UFIR` (they carry Ψ_l); only the gain, its rows and observability differ.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from bboxtune.filters.fir_core import check_fir_params
from bboxtune.filters.ufir import (
    UFIR,
    back_projected_rows,
    determined,
    ls_gains,
    ls_gains_of_columns,
    row_kinds,
    row_statistics,
)
from bboxtune.filters.validation import check_psi


class UFIRCMN(UFIR):
    """UFIR for coloured measurement noise. Parameters (scalars or per-track (B,) arrays): ``psi``
    (0 <= ψ <= 0.99: beyond, windows with missing samples lose accuracy, :mod:`bboxtune.filters.validation`),
    ``horizon`` N (differenced samples, integer >= 2; None → the white-noise N_opt rule),
    ``sigma_w``, ``sigma_v`` (σ_ξ; used only by that rule)."""

    name: ClassVar[str] = "ufir_cmn"
    DEFAULTS: ClassVar[dict[str, Any]] = {"psi": 0.0, "horizon": None, "sigma_w": 1.0, "sigma_v": 1.0}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("psi", "horizon", "sigma_w", "sigma_v")
    GAIN_PARAMS: ClassVar[tuple[str, ...]] = ("psi", "horizon")
    EXTRA_SAMPLES: ClassVar[int] = 1

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        return check_fir_params({**params, "psi": check_psi(params["psi"])}, self.model)

    def window_gain(self, valid: np.ndarray, params: dict[str, float | int]) -> np.ndarray:
        return self.window_gains(np.asarray(valid, bool)[None], {k: np.array([v]) for k, v in params.items()})[0]

    def window_gains(self, valid: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        diff, C = self._rows(valid, params)
        A = ls_gains(C)  # gains on the rows (z or y), [Shmaliy-CMN] Alg. 2 batch form
        psi = params["psi"][:, None, None]
        W = A.copy()  # fold z_l = y_l − ψ y_{l−1} into weights on raw samples
        W[:, :, :-1] -= psi * A[:, :, 1:] * diff[:, None, 1:]
        return W

    def clean_gains(self, params: dict[str, np.ndarray], L_max: int) -> np.ndarray:
        """All full-window gains in one least-squares batch: a window of L = N + 1 raw samples right-aligned in
        L_max columns has the rows ``D F^{−(L_max−1−j)}`` of the L_max-window at its columns j > L_max − L (its
        oldest sample only feeds the next difference) and zero rows before, which give zero gain columns."""
        axis = self.model.axis()
        h = back_projected_rows(axis.F, axis.H, L_max + 1)  # h[j + 1] = H F^{−(L_max−1−j)}
        first_row = L_max - params["horizon"]  # column of the oldest differenced sample
        present = np.arange(L_max)[None, :] >= first_row[:, None]  # (P, L_max)
        psi = params["psi"][:, None]
        A = ls_gains_of_columns([present * (h[1:, k] - psi * h[:-1, k]) for k in range(2)])
        A[:, :, :-1] -= psi[:, None] * A[:, :, 1:] * present[:, None, 1:]
        return A

    def observable(self, valid: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        plain, diff = self._kinds(valid, params)
        n_plain, n_diff, sum_plain, sum_diff = (a.sum(axis=-1) for a in row_statistics(plain, diff))
        return determined(n_plain, n_diff, sum_plain, sum_diff, params["psi"])

    def _kinds(self, valid: np.ndarray, params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Row kinds (P, L) of raw windows ``valid`` (P, L) (:func:`bboxtune.filters.ufir.row_kinds`); the oldest sample
        of a full window (L = N + 1) is only the predecessor of the next and gives no row."""
        plain, diff = row_kinds(valid)
        plain[:, 0] &= valid.shape[1] < params["horizon"] + self.EXTRA_SAMPLES  # start-up: frame 0 is a row
        return plain, diff

    def _rows(self, valid: np.ndarray, params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Windows ``valid`` (P, L) → ``diff`` (P, L), True where sample i enters differenced (z_i), and the
        stacked design C̄ (P, L, 2): rows D F^{−(L−1−i)} (z_i), H F^{−(L−1−i)} (undifferenced y_i) or 0 (none)."""
        plain, diff = self._kinds(valid, params)
        axis = self.model.axis()
        h = back_projected_rows(axis.F, axis.H, valid.shape[1] + 1)  # h[i + 1] = H F^{−(L−1−i)}, h[0] one older
        psi = params["psi"][:, None, None]
        d = h[None, 1:] - psi * h[None, :-1]  # D F^{−(L−1−i)} = H F^{−(L−1−i)} − ψ H F^{−(L−i)}
        C = np.where(diff[:, :, None], d, np.where(plain[:, :, None], h[None, 1:], 0.0))
        return diff, C
