"""Blind validation campaigns over executors: the same cases and scores as the command line,
only the blind recording and the model sent out, the truths read only once every case is back."""

from __future__ import annotations

import json
import pickle
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, Callable, List

import numpy as np
import pytest

import rollest
from rollest.campaign import diagnose_case

from conftest import cli, rebuilt

#: A small slice of a campaign of this project's tunnel: a clean case and a delay, short runs.
SLICE = dict(cases=14, seed=5, duration_s=10.0, only=[0, 1])
SCORED = ("class", "truth_sha256", "verdict", "named", "named_channels", "correct", "required_channels")


class RecordingExecutor(ThreadPoolExecutor):
    """Threads that note what each submitted call was given."""

    def __init__(self) -> None:
        super().__init__(max_workers=2)
        self.calls: List[tuple] = []

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:  # type: ignore[override]
        self.calls.append((fn, args, kwargs))
        return super().submit(fn, *args, **kwargs)


def by_id(validation: rollest.Validation) -> dict:
    """The scored cases by id, without the seconds each diagnosis took."""
    return {case["id"]: {k: v for k, v in case.items() if k != "diagnosis_s"} for case in validation.results["cases"]}


@pytest.fixture(scope="module")
def local_run() -> rollest.Validation:
    """The slice on the default executor: local processes on every core."""
    return rollest.validate_diagnosis(**SLICE)


def test_a_campaign_sends_out_only_blind_recordings_and_scores_as_the_command_line(host_tools, tmp_path):
    one = dict(SLICE, only=[1])
    executor = RecordingExecutor()
    with executor:
        validation = rollest.validate_diagnosis(**one, executor=executor, report=tmp_path / "report")
    assert validation.page is not None and validation.page.exists()
    # Only the blind recording and the model went out: no truth, no provenance keys.
    assert len(executor.calls) == 1
    fn, args, kwargs = executor.calls[0]
    assert fn is diagnose_case and not kwargs and len(args) == 2
    dataset, model = args
    assert isinstance(dataset, rollest.Dataset) and isinstance(model, rollest.Model)
    assert dataset.extra == {} and all(run.extra == {} for run in dataset.runs)
    cli(host_tools, "validate-diagnosis", "--cases", one["cases"], "--seed", one["seed"], "--duration-s",
        one["duration_s"], "--only", 1, "--report", tmp_path / "cli")  # fmt: skip
    expected = json.loads((tmp_path / "cli" / "validation.json").read_text())["cases"]
    (case,) = validation.results["cases"]
    assert len(expected) == 1 and all(case[key] == expected[0][key] for key in SCORED)
    if expected[0]["shrink"] is not None:  # read back from the contract's JSON text
        assert case["shrink"] == pytest.approx(expected[0]["shrink"], rel=1e-12)


def test_a_dask_cluster_scores_every_case_as_the_local_processes(local_run, dask_executor):
    validation = rollest.validate_diagnosis(**SLICE, executor=dask_executor)
    assert len(local_run.results["cases"]) == len(SLICE["only"])
    assert by_id(validation) == by_id(local_run)
    timeless = lambda summary: {k: v for k, v in summary.items() if k != "median_diagnosis_s"}  # noqa: E731
    assert timeless(validation.summary) == timeless(local_run.summary)


def test_the_truths_are_read_only_once_every_case_is_diagnosed(tmp_path):
    blind = rollest._rollest.BlindCampaign(**SLICE)
    with pytest.raises(rollest.RollestError, match="case 1 was diagnosed but never drawn"):
        blind.score([(1, "{}", 0.0)], "none drawn")
    index = {"format": "foreign-campaign/1", "seed": 3, "clean": "clean", "cases": [
        {"id": 0, "data": "cases/case-000", "truth": "sealed/case-000.json", "truth_sha256": "0" * 64}
    ]}  # fmt: skip
    (tmp_path / "campaign.json").write_text(json.dumps(index))
    foreign = rollest._rollest.ForeignCampaign(str(tmp_path))
    with pytest.raises(rollest.RollestError, match="case 0 has no diagnosis"):
        foreign.score([], "nothing diagnosed")


def test_recordings_and_models_travel_to_other_processes_unchanged(campaign, model):
    dataset = pickle.loads(pickle.dumps(campaign))
    assert [run.file for run in dataset.runs] == [run.file for run in campaign.runs]
    for original, copy in zip(campaign.runs, dataset.runs):
        assert all(np.array_equal(values, copy.arrays[name], equal_nan=True) for name, values in original.arrays.items())
    copied = pickle.loads(pickle.dumps(model))
    assert copied.blob() == model.blob() and copied.report == model.report and copied.source == model.source


def test_arrays_from_out_of_band_buffers_are_read_whatever_their_alignment(campaign):
    # Dask sends large arrays as out-of-band pickle buffers, which may start at any byte.
    unaligned = []
    for run in campaign.runs:
        columns = {}
        for name, values in run.arrays.items():
            raw = bytearray(values.nbytes + 1)
            shifted = np.frombuffer(memoryview(raw)[1:], dtype=np.float64)
            shifted[:] = values
            columns[name] = shifted
        unaligned.append(columns)
    assert not unaligned[0]["cl"].flags.aligned
    built = rebuilt(campaign, unaligned)
    assert all(np.array_equal(a.arrays["cl"], b.arrays["cl"], equal_nan=True) for a, b in zip(built.runs, campaign.runs))


def test_errors_raised_in_workers_come_back_with_their_attributes():
    error = rollest.DatasetError("runs/roll_a20.csv: column cp03: expected a number")
    error.file, error.row, error.column, error.key = "runs/roll_a20.csv", 7, "cp03", None
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is rollest.DatasetError and isinstance(again, rollest.RollestError)
    assert (again.args, again.file, again.row, again.column, again.key) == (error.args, "runs/roll_a20.csv", 7, "cp03", None)
