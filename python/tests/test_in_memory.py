"""Data in memory: datasets built from arrays and DataFrames, checked as folders are; fit,
evaluate and diagnose without a folder; the results as DataFrames and typed objects."""

from __future__ import annotations

import json
import os
import tempfile

import numpy as np
import pytest

import rollest
from conftest import rebuilt



def arrays_of(dataset: rollest.Dataset) -> list:
    return [dict(run.arrays) for run in dataset.runs]


def test_a_dataset_from_arrays_writes_and_reads_back_bit_for_bit(campaign, tmp_path):
    built = rebuilt(campaign, arrays_of(campaign))
    assert built.path is None and len(built) == len(campaign)
    built.write(tmp_path / "written")
    again = rollest.load_dataset(tmp_path / "written")
    for original, read in zip(campaign.runs, again.runs):
        assert (read.file, read.kind, read.alpha_deg, read.sample_hz) == (
            original.file,
            original.kind,
            original.alpha_deg,
            original.sample_hz,
        )
        assert original.arrays.keys() == read.arrays.keys()
        for name, values in original.arrays.items():
            assert np.array_equal(values, read.arrays[name], equal_nan=True), (read.file, name)


def test_a_long_dataframe_comes_back_as_the_same_dataset(campaign):
    pytest.importorskip("pandas")
    frame = campaign.to_pandas()
    built = rollest.Dataset.from_pandas(
        frame, u_inf_mps=campaign.tunnel["u_inf_mps"], rho_kgm3=campaign.tunnel["rho_kgm3"], wing=campaign.wing
    )
    assert [(run.file, run.kind, run.alpha_deg) for run in built.runs] == [
        (run.file, run.kind, run.alpha_deg) for run in campaign.runs
    ]
    for original, read in zip(campaign.runs, built.runs):
        assert read.sample_hz == pytest.approx(original.sample_hz, rel=1e-9)
        for name, values in original.arrays.items():
            assert np.array_equal(values, read.arrays[name], equal_nan=True), (read.file, name)


def test_a_fit_in_memory_is_the_fit_of_the_folder_and_leaves_nothing_behind(campaign, model):
    built = rebuilt(campaign, arrays_of(campaign))
    before = set(os.listdir(tempfile.gettempdir()))
    fitted = rollest.fit(built)
    after = set(os.listdir(tempfile.gettempdir()))
    assert fitted.path is None and "in memory" in fitted.source
    assert fitted.blob() == model.blob()
    assert not {name for name in after - before if "rollest" in name}, after - before
    assert fitted.card is not None and fitted.report is not None


def test_bad_arrays_are_refused_naming_the_run_and_column(campaign):
    runs = arrays_of(campaign)
    missing = [dict(run) for run in runs]
    del missing[1]["cp05"]
    with pytest.raises(rollest.DatasetError) as error:
        rebuilt(campaign, missing)
    assert error.value.column == "cp05" and error.value.file.endswith(campaign.runs[1].file), str(error.value)

    infinite = [dict(run) for run in runs]
    infinite[2]["cl"] = infinite[2]["cl"].copy()
    infinite[2]["cl"][9] = np.inf
    with pytest.raises(rollest.DatasetError) as error:
        rebuilt(campaign, infinite)
    # Row 11: the header is row 1, as in the run's file.
    assert (error.value.column, error.value.row) == ("cl", 11), str(error.value)

    jumpy = [dict(run) for run in runs]
    jumpy[0]["t_s"] = jumpy[0]["t_s"].copy()
    jumpy[0]["t_s"][100] += 0.5 / campaign.runs[0].sample_hz
    with pytest.raises(rollest.DatasetError) as error:
        rebuilt(campaign, jumpy)
    assert (error.value.column, error.value.row) == ("t_s", 102), str(error.value)

    short = [dict(run) for run in runs]
    short[0]["cp01"] = short[0]["cp01"][:-1]
    with pytest.raises(rollest.DatasetError, match="cp01"):
        rebuilt(campaign, short)

    with pytest.raises(rollest.DatasetError) as error:
        rebuilt(campaign, runs, kind="rolling")
    assert error.value.key == "run[1].kind", str(error.value)

    with pytest.raises(rollest.DatasetError) as error:
        rebuilt(campaign, runs, u_inf_mps=-1.0)
    assert error.value.key == "tunnel.u_inf_mps", str(error.value)


def test_evaluate_and_diagnose_without_a_folder_return_the_folders_results(campaign, model, tmp_path):
    written = rollest.diagnose(campaign, tmp_path / "diagnosis", model)
    in_memory = rollest.diagnose(campaign, model=model)
    assert in_memory.folder is None and in_memory.page is None
    stable = lambda results: {key: value for key, value in results.items() if key != "elapsed_s"}  # noqa: E731
    assert stable(in_memory.results) == stable(json.loads((tmp_path / "diagnosis" / "diagnosis.json").read_text()))
    evaluation = rollest.evaluate(campaign, model=model)
    assert evaluation.folder is None and evaluation.results["evaluation"]["table1"]


def test_a_diagnosis_names_an_injected_delay_in_typed_fields(model, tmp_path):
    real = rollest.simulate(tmp_path / "delayed", seed=8, duration_s=20.0, effects=["actuator_delay:delay_s=0.04"])
    diagnosis = rollest.diagnose(real, model=model)
    assert diagnosis.verdict == "effect", diagnosis.summary()
    first = diagnosis.first
    assert first is not None and first.name == "actuator_delay" and first.block == "plant"
    assert first.params["delay_s"] == pytest.approx(0.04, rel=0.2)
    assert 0.5 < first.shrink <= 1.0 and first.heldout_rms_after < first.heldout_rms_before
    assert diagnosis.where.block == "plant"
    page = diagnosis._repr_html_()
    assert "actuator_delay" in page and "effect" in page


def test_replays_and_runs_come_as_frames_indexed_by_time(campaign, model):
    pytest.importorskip("pandas")
    frames = model.replay(campaign, frame=True)
    arrays = model.replay(campaign)
    assert len(frames) == len(campaign)
    assert frames[0].index.name == "t_s" and np.array_equal(frames[0].index.to_numpy(), campaign.runs[0].arrays["t_s"])
    assert np.array_equal(frames[0]["cl_est"].to_numpy(), arrays[0]["cl_est"])
    run = campaign.runs[-1]
    frame = rollest.Estimator(model).run(run, frame=True)
    assert np.array_equal(frame.index.to_numpy(), run.arrays["t_s"])
    assert np.array_equal(frame["cl_est"].to_numpy(), arrays[-1]["cl_est"])


def test_equations_name_every_term_of_the_fit(model):
    equations = model.equations()
    report = model.report
    coupling_terms = [name for name, value in report["coupling"]["terms"] if value != 0.0]
    assert equations["coupling"].startswith("C_l - C_l,roll - C_l,AFC = ")
    assert all(name in equations["coupling"] for name in coupling_terms)
    assert "plant_port" in equations and "cmu" in equations["plant_port"]
    tables = model.coefficients
    assert isinstance(tables["alpha_schedule_deg"], np.ndarray) and tables["alpha_schedule_deg"].dtype == np.float64
    assert isinstance(tables["pressure"]["cp_mean"], np.ndarray)
    assert len(tables["egk"]) == len(tables["alpha_schedule_deg"])
    with pytest.raises(rollest.RollestError, match="fit report"):
        rollest.Model.built_in().equations()


def test_notebook_views_show_the_results(campaign, model):
    page = model._repr_html_()
    assert "Held-out RMS" in page and "C_l - C_l,roll - C_l,AFC" in page
    evaluation = rollest.evaluate(campaign, model=model)
    assert "<table" in evaluation._repr_html_()


def test_a_bad_dataframe_is_refused_naming_the_run_and_column(campaign):
    pd = pytest.importorskip("pandas")
    run = campaign.runs[0]
    good = run.to_pandas().reset_index()
    metadata = dict(kind=run.kind, alpha_deg=run.alpha_deg, u_inf_mps=10.0, rho_kgm3=1.2)

    def refused(frame: "pd.DataFrame") -> rollest.DatasetError:
        with pytest.raises(rollest.DatasetError) as error:
            rollest.Dataset.from_pandas({"runs/bad.csv": frame}, **metadata)
        assert error.value.file is not None and error.value.file.endswith("runs/bad.csv"), str(error.value)
        return error.value

    assert refused(good.drop(columns=["cp05"])).column == "cp05"
    nan_time = good.copy()
    nan_time.loc[7, "t_s"] = float("nan")
    error = refused(nan_time)
    assert (error.column, error.row) == ("t_s", 9), str(error)
    unsorted = good.copy()
    unsorted.loc[[20, 21], "t_s"] = unsorted.loc[[21, 20], "t_s"].to_numpy()
    error = refused(unsorted)
    assert (error.column, error.row) == ("t_s", 22), str(error)
    wrong_dtype = good.copy()
    wrong_dtype["phi_deg"] = "level"
    assert refused(wrong_dtype).column == "phi_deg"
