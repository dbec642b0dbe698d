"""Figures of a fit, an evaluation and a diagnosis, for notebooks and reports.

Each function returns a :class:`matplotlib.figure.Figure` built without pyplot's global
state, so it works in a notebook (which shows it), in a script (``figure.savefig(path)``) and
on a machine without a display. matplotlib is an optional dependency::

    pip install 'rollest[plots]'
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Dict, List, Sequence, Tuple, Union

import numpy as np

from . import DEFAULT_HOLDOUT_FRACTION, Evaluation, Model, heldout_start
from .dataset import Dataset, PathLike, Run, as_dataset
from .diagnosis import Diagnosis

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["gap_location", "heldout_error_per_alpha", "measured_vs_estimated"]

#: The replay columns drawn against the measured roll moment: the final estimate, then the
#: blocks it sums (the disturbance model, the blowing plant, the coupling operator's correction).
ESTIMATE_COLUMN = "cl_est"
BLOCK_COLUMNS: Tuple[str, ...] = ("cl_roll", "cl_afc", "coupling")
#: The blocks of the held-out table, in the order of the chain (``<block>_rms`` in the fit's
#: report, ``block`` in the evaluation's ``blocks`` rows).
HELDOUT_BLOCKS: Tuple[str, ...] = ("egk", "pressure", "fused", "plant", "linear", "coupled")
#: The run kinds of the format, in the order the gap-by-alpha panel groups its bars.
_KINDS: Tuple[str, ...] = ("roll", "actuation", "roll+actuation", "static")


def _figure(**kwargs: Any) -> "Figure":
    """A figure not registered with pyplot (no display, no global state), or an ImportError
    that says how to install matplotlib."""
    try:
        from matplotlib.figure import Figure
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("rollest.plots needs matplotlib: pip install 'rollest[plots]'") from error
    return Figure(**kwargs)


def _pick_run(dataset: Dataset, run: Union[None, int, str, Run]) -> int:
    """The index of ``run`` in ``dataset``: an index, a run file, a :class:`Run` of it, or (None)
    the first ``roll+actuation`` run, where every block of the estimate is at work."""
    if run is None:
        kinds = [candidate.kind for candidate in dataset.runs]
        return kinds.index("roll+actuation") if "roll+actuation" in kinds else 0
    if isinstance(run, int):
        if not -len(dataset.runs) <= run < len(dataset.runs):
            raise IndexError(f"run {run}: the dataset has {len(dataset.runs)} runs")
        return run % len(dataset.runs)
    file = run.file if isinstance(run, Run) else run
    files = [candidate.file for candidate in dataset.runs]
    if file not in files:
        raise KeyError(f"run {file!r}: expected one of {', '.join(files)}")
    return files.index(file)


def _shade_heldout(axes: "Axes", t_s: np.ndarray, start: int) -> None:
    """Shades the held-out part of a run, from sample ``start`` to its end."""
    if start < len(t_s):
        axes.axvspan(float(t_s[start]), float(t_s[-1]), color="0.9", zorder=0, label="held out")


def measured_vs_estimated(
    model: Model,
    dataset: Union[Dataset, PathLike],
    run: Union[None, int, str, Run] = None,
    *,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
) -> "Figure":
    """The measured roll moment of one run against the model's estimate, over time.

    The top axes draw the balance's ``cl`` and the coupled estimate ``cl_est``; the bottom axes
    the blocks the estimate sums (``cl_roll``: the disturbance model, eGK fused with the
    pressures; ``cl_afc``: the blowing plant of both jets; ``coupling``: the coupling operator's
    correction of their superposition), so a gap in the top axes can be traced to the block
    that makes it. The lines are :meth:`Model.replay`'s arrays, bit for bit. The held-out part
    (``heldout_start``, never used by the fit) is shaded: the estimate is judged there.

    ``run`` is an index, a run file or a :class:`Run` of ``dataset``; None takes the first
    ``roll+actuation`` run, where every block is at work.
    """
    data = as_dataset(dataset)
    index = _pick_run(data, run)
    replayed: Dict[str, np.ndarray] = model.replay(data)[index]
    t_s = replayed["t_s"]
    start = heldout_start(len(t_s), holdout_fraction)

    figure = _figure(figsize=(9.0, 6.0), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    for axes in (top, bottom):
        _shade_heldout(axes, t_s, start)
    top.plot(t_s, replayed["cl"], color="0.3", linewidth=0.8, label="cl (measured)")
    top.plot(t_s, replayed[ESTIMATE_COLUMN], color="C3", linewidth=0.8, label=f"{ESTIMATE_COLUMN} (estimate)")
    top.set_ylabel("C_l")
    top.set_title("Measured roll moment against the estimate")
    top.legend(loc="upper right", fontsize="small")
    for column in BLOCK_COLUMNS:
        bottom.plot(t_s, replayed[column], linewidth=0.8, label=column)
    bottom.set_xlabel("t, s")
    bottom.set_ylabel("C_l")
    bottom.set_title("The blocks of the estimate")
    bottom.legend(loc="upper right", fontsize="small")
    figure.suptitle(f"{data.runs[index].file} ({data.runs[index].kind}, alpha {data.runs[index].alpha_deg:g} deg)")
    return figure


def _heldout_rows(source: Union[Evaluation, Model]) -> Tuple[List[float], Dict[str, List[float]], List[float]]:
    """The held-out RMS of C_l per angle of attack: the angles, each block's RMS (NaN where a
    block was not evaluated) and the noise RMS, from an evaluation's ``blocks`` rows or a
    fit's report."""
    if isinstance(source, Evaluation):
        results = source.results["evaluation"]
        noise = {float(alpha): float(rms) for alpha, rms in results["noise_rms"]}
        alphas = sorted(noise)
        by_block = {block: [float("nan")] * len(alphas) for block in HELDOUT_BLOCKS}
        for row in results["blocks"]:
            if row["block"] in by_block and row["rms"] is not None:
                by_block[row["block"]][alphas.index(float(row["alpha_deg"]))] = float(row["rms"])
        return alphas, by_block, [noise[alpha] for alpha in alphas]
    report = source.report
    if report is None:
        raise ValueError(f"{source.source}: expected a fit report (model.json) with the held-out table")
    rows = sorted(report["heldout"]["per_alpha"], key=lambda row: float(row["alpha_deg"]))
    alphas = [float(row["alpha_deg"]) for row in rows]
    by_block = {block: [_number(row.get(f"{block}_rms")) for row in rows] for block in HELDOUT_BLOCKS}
    return alphas, by_block, [_number(row.get("noise_rms")) for row in rows]


def _number(value: Any) -> float:
    """A JSON number, NaN for null (a figure the report does not know)."""
    return float("nan") if value is None else float(value)


def heldout_error_per_alpha(source: Union[Evaluation, Model]) -> "Figure":
    """The held-out error of every block per angle of attack, and what the coupling operator
    gains over the linear superposition.

    The first axes draw the RMS of C_l on the held-out part for each block of the chain (eGK,
    pressure model, their fusion, the plant, the linear superposition, the coupled estimate)
    against the angle of attack, with the balance's noise RMS dashed: a block near the noise
    is as good as the data let it be. The second axes draw the coupling ratio (coupled over
    linear superposition; below 1 the operator helps), with its bootstrap 95 % interval when
    ``source`` is an :class:`Evaluation`. An evaluation adds a third axes, the paper's Table 1
    (the estimate's error spread over the roll moment's, ``ratio_to_std``).

    ``source`` is an :class:`Evaluation` (:func:`rollest.evaluate`) or a fitted :class:`Model`
    (its report's ``heldout.per_alpha`` rows, the same numbers).
    """
    alphas, by_block, noise = _heldout_rows(source)
    evaluation = source if isinstance(source, Evaluation) else None
    figure = _figure(figsize=(9.0, 3.6), layout="constrained")
    axes = figure.subplots(1, 3 if evaluation is not None else 2)

    for block in HELDOUT_BLOCKS:
        values = by_block[block]
        if not all(np.isnan(values)):
            axes[0].plot(alphas, values, marker="o", label=block)
    axes[0].plot(alphas, noise, color="0.4", linestyle="--", label="noise")
    axes[0].set_xlabel("alpha, deg")
    axes[0].set_ylabel("held-out RMS of C_l")
    axes[0].set_title("Error per block")
    axes[0].legend(fontsize="small")

    if evaluation is not None:
        rows = sorted(evaluation.results["evaluation"]["coupling"], key=lambda row: float(row["alpha_deg"]))
        ratio_alphas = [float(row["alpha_deg"]) for row in rows]
        ratios = np.array([_number(row["ratio"]) for row in rows])
        bounds = np.array([row.get("ratio_ci95") or [float("nan")] * 2 for row in rows], dtype=np.float64)
        spread = np.abs(bounds.reshape(-1, 2).T - ratios)
        (ratio_line,) = axes[1].plot(ratio_alphas, ratios, marker="o", label="coupled / linear")
        axes[1].errorbar(ratio_alphas, ratios, yerr=spread, fmt="none", capsize=3, ecolor=ratio_line.get_color())
    elif isinstance(source, Model) and source.report is not None:
        per_alpha = sorted(source.report["heldout"]["per_alpha"], key=lambda row: float(row["alpha_deg"]))
        axes[1].plot(
            [float(row["alpha_deg"]) for row in per_alpha],
            [_number(row.get("coupling_ratio")) for row in per_alpha],
            marker="o",
            label="coupled / linear",
        )
    axes[1].axhline(1.0, color="0.4", linestyle="--", linewidth=0.8)
    axes[1].set_xlabel("alpha, deg")
    axes[1].set_ylabel("RMS ratio")
    axes[1].set_title("Coupling against superposition")

    if evaluation is not None:
        table1 = sorted(evaluation.results["evaluation"]["table1"], key=lambda row: float(row["alpha_deg"]))
        axes[2].plot(
            [float(row["alpha_deg"]) for row in table1],
            [_number(row["ratio_to_std"]) for row in table1],
            marker="o",
            label="ratio_to_std",
        )
        axes[2].set_xlabel("alpha, deg")
        axes[2].set_ylabel("error std / C_l std")
        axes[2].set_title("Table 1")
    return figure


def _gap_by_alpha(diagnosis: Diagnosis) -> Dict[str, Dict[float, float]]:
    """The gap beyond noise per kind of run and angle of attack (mean square over the noise
    variance, on the selection part): the signature's ``kind@alpha`` entries."""
    signature = diagnosis.results.get("signature") or {}
    by_kind: Dict[str, Dict[float, float]] = {}
    for key, value in (signature.get("gap_to_noise_by_kind") or {}).items():
        kind, at, alpha = str(key).partition("@")
        if at and value is not None:
            by_kind.setdefault(kind, {})[float(alpha)] = float(value)
    return by_kind


def _band_label(band: Sequence[float]) -> str:
    return f"{band[0]:g}-{band[1]:g}"


def gap_location(diagnosis: Diagnosis) -> "Figure":
    """Where the gap between the sim and the recording lies: by angle of attack, by regime and
    by frequency band, the three ways the diagnosis's ledger locates it before any effect is
    named (``docs/diagnosis.md``, "The gap ledger").

    - By alpha: the gap beyond noise of each kind of run at each angle of attack, in noise
      variances (the signature's ``kind@alpha`` entries, on the selection part); the angles the
      named effect touches (``where.alpha_deg``) are marked.
    - By regime: the held-out residual's mean square per regime (held or rolling, blowing or
      not) with its bootstrap 95 % interval, against the noise variance (dashed): a regime
      above it holds gap, and which one says which block is wrong.
    - By band: the share of the residual's excess power per frequency band; the dominant band
      (``where.band_hz``) is drawn dark.

    ``diagnosis`` is what :func:`rollest.diagnose` returns.
    """
    ledger: Dict[str, Any] = diagnosis.results["ledger"]
    figure = _figure(figsize=(12.0, 3.8), layout="constrained")
    by_alpha, by_regime, by_band = figure.subplots(1, 3)

    gaps = _gap_by_alpha(diagnosis)
    kinds = [kind for kind in _KINDS if kind in gaps] + sorted(set(gaps) - set(_KINDS))
    alphas = sorted({alpha for values in gaps.values() for alpha in values})
    width = 0.8 / max(len(kinds), 1)
    for offset, kind in enumerate(kinds):
        positions = np.arange(len(alphas)) + (offset - (len(kinds) - 1) / 2) * width
        heights = [gaps[kind].get(alpha, float("nan")) for alpha in alphas]
        by_alpha.bar(positions, heights, width=width, label=kind)
    by_alpha.set_xticks(np.arange(len(alphas)), [f"{alpha:g}" for alpha in alphas])
    for position, alpha in enumerate(alphas):
        if alpha in diagnosis.where.alpha_deg:
            by_alpha.get_xticklabels()[position].set_fontweight("bold")
    by_alpha.axhline(0.0, color="0.4", linewidth=0.8)
    by_alpha.set_xlabel("alpha, deg (bold: touched by the effect)")
    by_alpha.set_ylabel("gap beyond noise / noise variance")
    by_alpha.set_title("By angle of attack")
    if kinds:
        by_alpha.legend(fontsize="small")

    regimes: List[Dict[str, Any]] = ledger.get("regimes") or []
    mse = np.array([_number(row["mse"]) for row in regimes])
    bounds = np.array([row.get("mse_ci95") or [float("nan")] * 2 for row in regimes], dtype=np.float64)
    spread = np.abs(bounds.reshape(-1, 2).T - mse)
    regime_at = np.arange(len(regimes))
    by_regime.bar(regime_at, mse, yerr=spread, capsize=3, color="C1")
    by_regime.set_xticks(regime_at, [str(row["label"]).replace(", ", ",\n") for row in regimes], fontsize="small")
    by_regime.axhline(diagnosis.gap.noise_rms**2, color="0.4", linestyle="--", label="noise variance")
    by_regime.set_ylabel("held-out residual mean square")
    by_regime.set_title("By regime")
    by_regime.legend(fontsize="small")

    bands: List[Dict[str, Any]] = ledger.get("bands") or []
    dominant = diagnosis.where.band_hz
    colours = [
        "C0" if dominant is not None and tuple(row["band_hz"]) == tuple(dominant) else "C9" for row in bands
    ]
    band_at = np.arange(len(bands))
    by_band.bar(band_at, [_number(row["share"]) for row in bands], color=colours)
    by_band.set_xticks(band_at, [_band_label(row["band_hz"]) for row in bands], fontsize="small")
    by_band.set_xlabel("band, Hz (dark: dominant)")
    by_band.set_ylabel("share of the excess power")
    by_band.set_title("By frequency band")

    figure.suptitle(f"Where the gap lies (verdict: {diagnosis.verdict})")
    return figure

