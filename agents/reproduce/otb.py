"""OTB ground truth + synthetic CMN filtered with the papers' tuned parameters: Car4 ([Shmaliy-CMN] §III) and Suv
([PaleRamon-BBox] §9.2).

Truth = the OTB ground-truth box centre (cx, cy) in px. Measurements = truth + Gauss–Markov CMN in px,
v_n = ψ v_{n−1} + ξ_n with σ_ξ as tuned in the paper (stationary start), ``mc`` independent noise draws.
Every filter runs on (cx, cy) with the paper's τ, σ_w, σ_v = σ_ξ and horizons; errors are Euclidean centre
RMSEs over all frames, pooled over draws. The papers filtered real tracker output ([Shmaliy-CMN]: "measurements made
... along coordinate x"), which is not available here; GT + CMN is the controlled substitute, so ψ is known.

[Shmaliy-CMN] also describes how it chose N: "N ≅ 65 for [UFIR's] output to range close to the standard KF" and
"minimization of the difference between the UFIR and KF outputs gave N ≅ 160" for the CMN versions. We repeat
that procedure (the N minimising the RMS difference to the matching KF) over a grid of N, next to the N that
minimises the error against the ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from bboxtune import filters
from bboxtune.agents.reproduce.common import Section, Settings, fmt, md_table, param_sweep, pooled_rmse, verdict
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.data.otb import OTBDataset
from bboxtune.envs.data.simulate import gauss_markov


@dataclass(frozen=True)
class OTBCase:
    """One sequence and the paper's tuning."""

    sequence: str  # OTB-100 name
    source: str  # paper and section
    tau: float  # s, sampling interval the filters assume
    sigma_w: float  # px/s², filters' acceleration noise std (paper's tuning)
    sigma_xi: float  # px, std of ξ of the synthetic CMN, and the filters' σ_v
    psi: float  # coloredness of the synthetic CMN and the CMN filters' ψ
    horizons: tuple[tuple[str, int], ...]  # (back end, the paper's N); ufir_cmn without one runs at the matched N
    standard: tuple[str, ...]  # white-noise filters of the paper, plotted in panel (a)
    paper_rmse: tuple[tuple[str, float], ...] = ()  # quoted RMSE values (units as printed in the paper)


CASES = (
    OTBCase("Car4", "[Shmaliy-CMN] §III", tau=0.05, sigma_w=3.0, sigma_xi=2.0, psi=0.9,
            horizons=(("ufir", 65), ("ufir_cmn", 160)), standard=("kf", "ufir")),
    # [PaleRamon-BBox] calls Suv's data noise CMN but its ψ is lost in our text copy: ψ = 0.9 ([Shmaliy-CMN]'s Car4) is ours.
    OTBCase("Suv", "[PaleRamon-BBox] §9.2", tau=0.05, sigma_w=10.0, sigma_xi=5.0, psi=0.9,
            horizons=(("ofir", 49), ("ufir", 49), ("oufir", 49)), standard=("kf", "ofir", "ufir", "oufir"),
            paper_rmse=(("oufir", 2316.90), ("ufir", 2361.90), ("ofir", 4962.39), ("kf", 4963.56))),
)
REFERENCE = {"ufir": "kf", "ufir_cmn": "kf_cmn"}  # the KF each UFIR is matched to ([Shmaliy-CMN]'s tuning procedure)
COLORS = {"kf": "tab:blue", "kf_cmn": "tab:blue", "ufir": "tab:red", "ufir_cmn": "tab:red", "ofir": "tab:green",
          "oufir": "tab:orange"}


@dataclass(frozen=True)
class OTBResult:
    case: OTBCase
    truth: np.ndarray  # (T, 2) cx, cy
    y: np.ndarray  # (mc, T, 2) measurements
    estimates: dict[str, np.ndarray]  # label → (mc, T, 2) positions
    params: dict[str, str]  # label → parameters as text
    horizons: np.ndarray  # swept N
    sweep_rmse: dict[str, np.ndarray]  # ufir / ufir_cmn → RMSE vs ground truth per N; kf / kf_cmn → per σ_w
    sweep_diff: dict[str, np.ndarray]  # ufir / ufir_cmn → RMS difference to its KF per N
    sigma_w: np.ndarray  # swept σ_w of the KFs (px/s²)
    gt_sigma_w: float  # px/s², σ_w implied by the ground truth's second differences

    def rmse(self, label: str) -> float:
        return float(pooled_rmse(self.estimates[label], np.broadcast_to(self.truth, self.y.shape), axis=(0, 1, 2)))

    def matched(self, name: str) -> int:
        """The horizon of UFIR ``name`` closest to its KF ([Shmaliy-CMN]'s tuning procedure)."""
        return int(argbest(self.horizons, self.sweep_diff[name]))

    def best(self, name: str) -> float:
        """The σ_w (KFs) or N (UFIRs) of ``name`` with the least RMSE against the ground truth."""
        return argbest(self.sigma_w if name.startswith("kf") else self.horizons, self.sweep_rmse[name])


def argbest(grid: np.ndarray, values: np.ndarray) -> float:
    """The grid point with the smallest value."""
    return grid[np.argmin(values)]


def implied_sigma_w(truth: np.ndarray, tau: float) -> float:
    """σ_w (px/s²) of a CV model that would give the truth's second differences: Δ²p_n = τ²(w_{n−1} + w_n)/2
    under (1), so σ_w = √2 · rms(Δ²p) / τ² (pooled over x and y; integer GT rounding inflates it a little)."""
    d2 = np.diff(truth, n=2, axis=0)
    return float(np.sqrt(2.0 * np.nanmean(d2**2)) / tau**2)


def run_case(case: OTBCase, dataset: OTBDataset, settings: Settings, experiment: int) -> OTBResult:
    """Filter ``mc`` CMN draws of the sequence's centre track with the paper's tuning, sweep the UFIR horizons
    (RMSE vs GT and difference to the KF) and the KFs' σ_w, and re-run each at its best value ("tuned on GT")."""
    rng = settings.rng(experiment)
    truth = xywh_to_cxcywh(dataset.groundtruth(case.sequence))[:, :2]
    y = truth + gauss_markov(case.psi, np.full(2, case.sigma_xi), (settings.mc, len(truth), 2), rng)  # (2), (3)
    model = filters.constant_velocity(case.tau, ndim=2)
    full_truth = np.broadcast_to(truth, y.shape)
    noise: dict[str, Any] = {"sigma_w": case.sigma_w, "sigma_v": case.sigma_xi}  # filter parameters, passed on
    extras = {"kf": noise, "kf_cmn": {**noise, "psi": case.psi}, "ufir": {}, "ufir_cmn": {"psi": case.psi}}

    def run(name: str, **params: object) -> np.ndarray:
        return filters.make(name, model, **{**extras.get(name, noise), **params}).run(y)[..., :2]

    def versus(ref: np.ndarray):
        return lambda x: pooled_rmse(x[..., :2], ref, axis=(0, 1, 2))

    estimates = {"measurements": y, "kf": run("kf"), "kf_cmn": run("kf_cmn")}
    params = {"measurements": f"truth + CMN ψ = {case.psi:g}, σ_ξ = {case.sigma_xi:g} px",
              "kf": f"σ_w = {case.sigma_w:g}, σ_v = {case.sigma_xi:g} (paper)",
              "kf_cmn": f"ψ = {case.psi:g}, σ_w = {case.sigma_w:g}, σ_v = {case.sigma_xi:g} (paper)"}
    sweep_rmse, sweep_diff = {}, {}
    for name in ("kf", "kf_cmn"):
        sweep_rmse[name] = param_sweep(name, model, y, "sigma_w", settings.otb_sigma_w, versus(full_truth),
                                       **{k: v for k, v in extras[name].items() if k != "sigma_w"})
    for name, ref in REFERENCE.items():

        def both(x: np.ndarray, r: np.ndarray = estimates[ref]) -> list[np.ndarray]:
            return [versus(full_truth)(x), versus(r)(x)]

        swept = param_sweep(name, model, y, "horizon", settings.otb_horizons, both, **extras[name])
        sweep_rmse[name], sweep_diff[name] = swept[:, 0], swept[:, 1]
    grids = {"kf": np.asarray(settings.otb_sigma_w), "ufir": np.asarray(settings.otb_horizons)}
    paper_n = dict(case.horizons)
    paper_n.setdefault("ufir_cmn", int(argbest(grids["ufir"], sweep_diff["ufir_cmn"])))
    for name, n in paper_n.items():
        estimates[name] = run(name, horizon=n)
        origin = "paper" if name in dict(case.horizons) else "matched to KF-CMN, [Shmaliy-CMN]'s procedure"
        params[name] = f"N = {n} ({origin})" + (f", ψ = {case.psi:g}" if name == "ufir_cmn" else "")
    for name in ("kf", "kf_cmn", "ufir", "ufir_cmn"):
        key, grid = ("horizon", grids["ufir"]) if name.startswith("ufir") else ("sigma_w", grids["kf"])
        value = argbest(grid, sweep_rmse[name])
        estimates[f"{name} tuned"] = run(name, **{key: value})
        edge = ", at the grid's edge" if value in (grid[0], grid[-1]) else ""
        shown = f"{value:.0f}" if value >= 1000 else f"{value:.4g}"
        params[f"{name} tuned"] = (f"{'N' if key == 'horizon' else 'σ_w'} = {shown} "
                                   f"(least RMSE vs GT, oracle{edge})")
    return OTBResult(case, truth, y, estimates, params, grids["ufir"], sweep_rmse, sweep_diff, grids["kf"],
                     implied_sigma_w(truth, case.tau))


def figure_case(res: OTBResult) -> dict[str, plt.Figure]:
    """(a) x vs frame, the paper's standard filters; (b) x vs frame, CMN filters; (c) the x–y plane (draw 0)."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5), layout="constrained")
    frames = np.arange(len(res.truth))
    groups = (res.case.standard, ("kf_cmn", "ufir_cmn"), ("kf_cmn", "ufir_cmn"))
    titles = ("(a) x: standard filters", "(b) x: filters modified for CMN", "(c) x–y plane")
    for ax, names, title in zip(axes, groups, titles, strict=False):
        plane = title.startswith("(c)")
        pick = (lambda a: (a[:, 0], a[:, 1])) if plane else (lambda a: (frames, a[:, 0]))
        ax.plot(*pick(res.y[0]), color="0.7", lw=0.8, label="measurements (GT + CMN)")
        ax.plot(*pick(res.truth), color="k", lw=1.2, label="ground truth")
        for name in names:
            ls = "--" if name in ("ofir", "kf") else "-"
            ax.plot(*pick(res.estimates[name][0]), color=COLORS[name], ls=ls, lw=1.0,
                    label=f"{name}: {res.params[name]}")
        ax.set(title=f"{res.case.sequence} {title}", xlabel="x (px)" if plane else "frame",
               ylabel="y (px)" if plane else "x (px)")
        if plane:
            ax.invert_yaxis()
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return {f"otb_{res.case.sequence.lower()}.png": fig}


def figure_sweeps(results: list[OTBResult]) -> dict[str, plt.Figure]:
    """Per sequence: UFIR RMSE vs GT and RMS difference to the KF per horizon (top); KF RMSE per σ_w (bottom)."""
    fig, axes = plt.subplots(2, len(results), figsize=(6.5 * len(results), 8), squeeze=False, layout="constrained")
    for top, bottom, res in zip(axes[0], axes[1], results, strict=False):
        for name, color in (("ufir", "tab:red"), ("ufir_cmn", "tab:purple")):
            top.plot(res.horizons, res.sweep_rmse[name], "-", color=color, label=f"{name}: RMSE vs GT")
            top.plot(res.horizons, res.sweep_diff[name], ":", color=color,
                     label=f"{name}: RMS difference to {REFERENCE[name]}")
        for n in dict(res.case.horizons).values():
            top.axvline(n, color="0.5", ls="--", lw=0.8)
        top.set(xscale="log", yscale="log", xlabel="horizon N", ylabel="px",
                title=f"{res.case.sequence}: horizon sweep (dashed: paper's N)")
        for name, ls in (("kf", "--"), ("kf_cmn", "-")):
            bottom.plot(res.sigma_w, res.sweep_rmse[name], ls, color="tab:blue", label=f"{name}: RMSE vs GT")
        bottom.axvline(res.case.sigma_w, color="0.5", ls="--", lw=0.8, label="paper's σ_w")
        bottom.axvline(res.gt_sigma_w, color="k", ls=":", lw=0.8, label="σ_w implied by the ground truth")
        bottom.set(xscale="log", yscale="log", xlabel="σ_w (px/s²)", ylabel="centre RMSE (px)",
                   title=f"{res.case.sequence}: KF σ_w sweep (σ_v = {res.case.sigma_xi:g} px)")
        for ax in (top, bottom):
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7)
    return {"otb_sweeps.png": fig}


def section_case(res: OTBResult) -> Section:
    case = res.case
    quoted = dict(case.paper_rmse)
    labels = ["measurements", *case.standard, "kf_cmn", "ufir_cmn", "kf tuned", "kf_cmn tuned", "ufir tuned",
              "ufir_cmn tuned"]
    rows = [[name, res.params[name], fmt(res.rmse(name)), fmt(quoted[name]) if name in quoted else "—"]
            for name in labels]
    table = md_table(["filter", "parameters", "centre RMSE (px)", "paper RMSE"], rows)
    table += (f"\nThe 'tuned' rows pick σ_w or N by the least RMSE against the ground truth itself (an oracle, for "
              f"scale). The ground truth's second differences correspond to σ_w ≈ {res.gt_sigma_w:.0f} px/s² at "
              f"τ = {case.tau:g} s (an upper bound: the integer rounding of the boxes alone gives ≈ "
              f"{np.sqrt(2 * 0.5) / case.tau**2:.0f}), far above the paper's σ_w = {case.sigma_w:g}; with ψ = "
              f"{case.psi:g} the paper-tuned KF-CMN leans on its motion model and lags the turns (figure, panel b).\n")
    claims = _car4_claims(res) if case.sequence == "Car4" else _suv_claims(res)
    return Section(f"{case.sequence} ({case.source}): ground truth + CMN, tuned filters", table + "\n" + claims, {})


def _car4_claims(res: OTBResult) -> str:
    e = {k: res.rmse(k) for k in ("measurements", "kf", "ufir", "kf_cmn", "ufir_cmn")}
    t = {k: res.rmse(f"{k} tuned") for k in ("kf", "ufir", "kf_cmn", "ufir_cmn")}
    gap = float(pooled_rmse(res.estimates["kf_cmn"], res.estimates["ufir_cmn"], axis=(0, 1, 2)))
    m_ufir, m_cmn = res.matched("ufir"), res.matched("ufir_cmn")
    return md_table(["paper's claim ([Shmaliy-CMN] §III)", "ours", "verdict"], [
        ["the standard KF (σ_w = 3, σ_ξ = 2) follows the coloured parts and does not remove them",
         f"KF RMSE {fmt(e['kf'])} px vs measurements {fmt(e['measurements'])} px "
         f"({100 * (1 - e['kf'] / e['measurements']):+.1f} % removed)",
         verdict(e["kf"] > 0.7 * e["measurements"], "counted if < 30 % is removed")],
        ["N ≅ 65 brings the UFIR output close to the standard KF",
         f"N minimising RMS(UFIR − KF): {m_ufir} (N giving the least RMSE vs GT: {res.best('ufir')})",
         verdict(0.67 * 65 <= m_ufir <= 1.5 * 65, "counted within a factor 1.5")],
        ["the UFIR–KF difference minimised for the CMN filters at N ≅ 160",
         f"N minimising RMS(UFIR-CMN − KF-CMN): {m_cmn} (least RMSE vs GT: {res.best('ufir_cmn')})",
         verdict(0.67 * 160 <= m_cmn <= 1.5 * 160, "counted within a factor 1.5")],
        ["the modified filters trace much closer to the actual trajectory",
         f"paper's tuning: KF {fmt(e['kf'])} → KF-CMN {fmt(e['kf_cmn'])} px, UFIR {fmt(e['ufir'])} → UFIR-CMN "
         f"{fmt(e['ufir_cmn'])} px; tuned on GT: KF {fmt(t['kf'])} → KF-CMN {fmt(t['kf_cmn'])}, UFIR "
         f"{fmt(t['ufir'])} → UFIR-CMN {fmt(t['ufir_cmn'])} px",
         verdict(e["kf_cmn"] < 0.9 * e["kf"] and e["ufir_cmn"] < 0.9 * e["ufir"],
                  "with the paper's tuning; counted if > 10 % smaller")],
        ["the KF-CMN and UFIR-CMN estimates are poorly distinguishable",
         f"RMS(KF-CMN − UFIR-CMN) = {fmt(gap)} px vs their RMSE {fmt(e['kf_cmn'])} px",
         verdict(gap < 0.5 * e["kf_cmn"], "counted if below half the RMSE")],
    ])


def _suv_claims(res: OTBResult) -> str:
    e = {k: res.rmse(k) for k in ("kf", "ofir", "ufir", "oufir")}
    order = " < ".join(sorted(e, key=lambda k: e[k]))
    return md_table(["paper's claim ([PaleRamon-BBox] §9.2)", "ours", "verdict"], [
        ["RMSE order OUFIR < UFIR < OFIR ≈ KF (2316.90 < 2361.90 < 4962.39 ≈ 4963.56)", order,
         verdict(max(e["oufir"], e["ufir"]) < min(e["ofir"], e["kf"]), "counted if both unbiased FIRs beat "
                                                                        "both OFIR and KF")],
        ["KF about 2.1× the OUFIR error", f"KF / OUFIR = {e['kf'] / e['oufir']:.2f}",
         verdict(e["kf"] / e["oufir"] > 1.5, "counted above 1.5")],
        ["(scale) the paper's values (2317–4964) exceed the size of the Suv frames, so they are not centre "
         "RMSEs in px; only their order is compared", "—", "—"],
    ])
