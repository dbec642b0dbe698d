"""rollest.plots: each figure draws the numbers of the replay, the report, the evaluation or the
diagnosis it is given, unchanged; skipped where matplotlib is not installed."""

from __future__ import annotations

import sys
from typing import Any, Dict, List

import numpy as np
import pytest

import rollest

pytest.importorskip("matplotlib")

from matplotlib.axes import Axes  # noqa: E402
from matplotlib.container import BarContainer  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from rollest import plots  # noqa: E402


def line(axes: Axes, label: str) -> Line2D:
    """The line of ``axes`` labelled ``label``."""
    found = [candidate for candidate in axes.get_lines() if candidate.get_label() == label]
    assert len(found) == 1, f"expected one line labelled {label!r}, found {[l.get_label() for l in axes.get_lines()]}"
    return found[0]


def heights(container: BarContainer) -> List[float]:
    return [patch.get_height() for patch in container.patches]


def number(value: Any) -> float:
    """A JSON number as drawn: NaN for null."""
    return float("nan") if value is None else float(value)


@pytest.fixture(scope="module")
def evaluation(campaign: rollest.Dataset, model: rollest.Model) -> rollest.Evaluation:
    return rollest.evaluate(campaign, model=model)


@pytest.fixture(scope="module")
def diagnosis(model: rollest.Model, tmp_path_factory: pytest.TempPathFactory) -> rollest.Diagnosis:
    """A short recording with a delayed actuator, diagnosed against the model (8 s keeps it
    quick; the ledger is complete whatever the verdict)."""
    real = rollest.simulate(
        tmp_path_factory.mktemp("plots") / "delayed", seed=7, duration_s=8.0, effects=["actuator_delay:delay_s=0.04"]
    )
    return rollest.diagnose(real, model=model)


def test_measured_vs_estimated_draws_the_replay_of_the_run(campaign: rollest.Dataset, model: rollest.Model) -> None:
    index = [run.file for run in campaign.runs].index("runs/rollact_a10.csv")
    replayed = model.replay(campaign)[index]

    figure = plots.measured_vs_estimated(model, campaign, "runs/rollact_a10.csv")

    assert isinstance(figure, Figure)
    top, bottom = figure.axes
    for axes, label, column in [
        (top, "cl (measured)", "cl"),
        (top, "cl_est (estimate)", "cl_est"),
        (bottom, "cl_roll", "cl_roll"),
        (bottom, "cl_afc", "cl_afc"),
        (bottom, "coupling", "coupling"),
    ]:
        drawn = line(axes, label)
        np.testing.assert_array_equal(drawn.get_xdata(), replayed["t_s"])
        np.testing.assert_array_equal(drawn.get_ydata(), replayed[column])


def test_measured_vs_estimated_shades_the_heldout_part(campaign: rollest.Dataset, model: rollest.Model) -> None:
    run = campaign.runs[0]
    figure = plots.measured_vs_estimated(model, campaign, run)

    start = run.arrays["t_s"][rollest.heldout_start(len(run))]
    for axes in figure.axes:
        (span,) = [patch for patch in axes.patches if patch.get_label() == "held out"]
        x0, x1 = span.get_x(), span.get_x() + span.get_width()
        assert (x0, x1) == pytest.approx((start, run.arrays["t_s"][-1]))


def test_measured_vs_estimated_takes_the_first_rolling_blown_run_by_default(
    campaign: rollest.Dataset, model: rollest.Model
) -> None:
    first = next(run for run in campaign.runs if run.kind == "roll+actuation")
    figure = plots.measured_vs_estimated(model, campaign)
    assert figure.get_suptitle().startswith(first.file)


def test_measured_vs_estimated_refuses_a_run_not_in_the_dataset(campaign: rollest.Dataset, model: rollest.Model) -> None:
    with pytest.raises(KeyError, match="runs/nowhere.csv"):
        plots.measured_vs_estimated(model, campaign, "runs/nowhere.csv")


def test_heldout_error_per_alpha_of_a_model_draws_its_report(model: rollest.Model) -> None:
    assert model.report is not None
    rows: List[Dict[str, Any]] = model.report["heldout"]["per_alpha"]

    figure = plots.heldout_error_per_alpha(model)

    errors, coupling = figure.axes
    for block in plots.HELDOUT_BLOCKS:
        drawn = line(errors, block)
        np.testing.assert_array_equal(drawn.get_xdata(), [row["alpha_deg"] for row in rows])
        np.testing.assert_array_equal(drawn.get_ydata(), [row[f"{block}_rms"] for row in rows])
    np.testing.assert_array_equal(line(errors, "noise").get_ydata(), [row["noise_rms"] for row in rows])
    np.testing.assert_array_equal(
        line(coupling, "coupled / linear").get_ydata(), [row["coupling_ratio"] for row in rows]
    )


def test_heldout_error_per_alpha_of_an_evaluation_draws_its_tables(evaluation: rollest.Evaluation) -> None:
    results = evaluation.results["evaluation"]
    figure = plots.heldout_error_per_alpha(evaluation)

    errors, coupling, table1 = figure.axes
    coupled = [row for row in results["blocks"] if row["block"] == "coupled"]
    np.testing.assert_array_equal(line(errors, "coupled").get_xdata(), [row["alpha_deg"] for row in coupled])
    np.testing.assert_array_equal(line(errors, "coupled").get_ydata(), [row["rms"] for row in coupled])
    np.testing.assert_array_equal(line(errors, "noise").get_ydata(), [rms for _, rms in results["noise_rms"]])
    np.testing.assert_array_equal(
        line(coupling, "coupled / linear").get_ydata(), [row["ratio"] for row in results["coupling"]]
    )
    pytest.importorskip("pandas")
    np.testing.assert_array_equal(
        line(table1, "ratio_to_std").get_ydata(), evaluation.heldout_per_alpha()["ratio_to_std"].to_numpy()
    )


def test_gap_location_draws_the_ledger_by_alpha_regime_and_band(diagnosis: rollest.Diagnosis) -> None:
    ledger = diagnosis.results["ledger"]
    by_kind = diagnosis.results["signature"]["gap_to_noise_by_kind"]

    figure = plots.gap_location(diagnosis)

    by_alpha, by_regime, by_band = figure.axes
    drawn_kinds = {str(container.get_label()): container for container in by_alpha.containers}
    assert set(drawn_kinds) == {key for key in by_kind if "@" not in key}
    for kind, container in drawn_kinds.items():
        at_alpha = sorted((float(key.split("@")[1]), value) for key, value in by_kind.items() if key.startswith(kind + "@"))
        assert heights(container) == [value for _, value in at_alpha]
    (regimes,) = [container for container in by_regime.containers if isinstance(container, BarContainer)]
    # A regime the held-out part does not visit has no mean square (null): no bar.
    np.testing.assert_array_equal(heights(regimes), [number(row["mse"]) for row in ledger["regimes"]])
    assert line(by_regime, "noise variance").get_ydata()[0] == diagnosis.gap.noise_rms**2
    (bands,) = by_band.containers
    np.testing.assert_array_equal(heights(bands), [number(row["share"]) for row in ledger["bands"]])
    assert [label.get_text() for label in by_band.get_xticklabels()] == [
        f"{low:g}-{high:g}" for low, high in (row["band_hz"] for row in ledger["bands"])
    ]


def test_plots_without_matplotlib_say_how_to_install_it(
    model: rollest.Model, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    with pytest.raises(ImportError, match=r"pip install 'rollest\[plots\]'"):
        plots.heldout_error_per_alpha(model)
