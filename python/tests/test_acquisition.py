"""examples/acquisition.py: a campaign written by an acquisition system (MATLAB ``.mat``, HDF5,
under the tunnel's own channel names, the balance in N m) reads back as the campaign and fits
the model of the same readings given in the dataset format."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType
from typing import Any, Dict

import numpy as np
import pytest

import rollest
from conftest import rebuilt

pytest.importorskip("pandas")
h5py = pytest.importorskip("h5py")
scipy_io = pytest.importorskip("scipy.io")

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "acquisition.py"


@pytest.fixture(scope="module")
def acquisition() -> ModuleType:
    """The example, imported from its file."""
    spec = importlib.util.spec_from_file_location("acquisition", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def q_s_b(campaign: rollest.Dataset) -> float:
    """The balance's scale, N m: dynamic pressure times the wing's area and span."""
    q_pa = 0.5 * campaign.tunnel["rho_kgm3"] * campaign.tunnel["u_inf_mps"] ** 2
    return float(q_pa * campaign.wing["area_m2"] * campaign.wing["span_m"])


def recorded(acquisition: ModuleType, campaign: rollest.Dataset) -> Dict[str, Dict[str, Any]]:
    """The campaign's runs as the acquisition system records them: its channel names, Mx in
    N m, and each run's kind and angle of attack."""
    names = {ours: theirs for theirs, ours in acquisition.CHANNELS.items()}
    runs = {}
    for run in campaign.runs:
        channels: Dict[str, Any] = {names[column]: values for column, values in run.arrays.items() if column != "cl"}
        channels["Mx"] = run.arrays["cl"] * q_s_b(campaign)
        channels["kind"] = run.kind
        channels["alpha"] = run.alpha_deg
        runs[Path(run.file).stem] = channels
    return runs


@pytest.fixture(scope="module")
def mat_file(acquisition: ModuleType, campaign: rollest.Dataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("acquisition") / "campaign.mat"
    scipy_io.savemat(
        path,
        {
            "U_inf": campaign.tunnel["u_inf_mps"],
            "rho": campaign.tunnel["rho_kgm3"],
            "fs": campaign.runs[0].sample_hz,
            "runs": recorded(acquisition, campaign),
        },
    )
    return path


@pytest.fixture(scope="module")
def h5_file(acquisition: ModuleType, campaign: rollest.Dataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("acquisition") / "campaign.h5"
    with h5py.File(path, "w") as file:
        file.attrs["U_inf"] = campaign.tunnel["u_inf_mps"]
        file.attrs["rho"] = campaign.tunnel["rho_kgm3"]
        file.attrs["fs"] = campaign.runs[0].sample_hz
        runs = file.create_group("runs", track_order=True)
        for name, channels in recorded(acquisition, campaign).items():
            group = runs.create_group(name)
            for channel, values in channels.items():
                if channel in ("kind", "alpha"):
                    group.attrs[channel] = values
                else:
                    group.create_dataset(channel, data=values)
    return path


def assert_same_campaign(read: rollest.Dataset, campaign: rollest.Dataset) -> None:
    """Every run's metadata and channels as the campaign's; cl to rounding (it went through N m)."""
    assert read.tunnel == campaign.tunnel
    assert read.wing == campaign.wing
    assert [(run.file, run.kind, run.alpha_deg, run.sample_hz) for run in read.runs] == [
        (run.file, run.kind, run.alpha_deg, run.sample_hz) for run in campaign.runs
    ]
    for got, expected in zip(read.runs, campaign.runs):
        assert sorted(got.arrays) == sorted(expected.arrays), got.file
        for column, values in expected.arrays.items():
            if column == "cl":
                np.testing.assert_allclose(got.arrays[column], values, rtol=1e-12, atol=0, err_msg=got.file)
            else:
                np.testing.assert_array_equal(got.arrays[column], values, err_msg=f"{got.file}: {column}")


def test_a_mat_recording_reads_as_the_campaign(
    acquisition: ModuleType, mat_file: Path, campaign: rollest.Dataset
) -> None:
    assert_same_campaign(acquisition.read_recording(mat_file, wing=campaign.wing), campaign)


def test_an_hdf5_recording_reads_as_the_campaign(
    acquisition: ModuleType, h5_file: Path, campaign: rollest.Dataset
) -> None:
    assert_same_campaign(acquisition.read_recording(h5_file, wing=campaign.wing), campaign)


def test_a_recording_reads_as_the_balance_readings_given_directly_and_fits(
    acquisition: ModuleType, mat_file: Path, campaign: rollest.Dataset
) -> None:
    # The same readings given to the format directly (the balance in N m as `mx_nm`), not the
    # campaign itself: Mx / (q S b) rounds cl in its last bit on about one sample in seven.
    readings = []
    for run in campaign.runs:
        columns = {name: values for name, values in run.arrays.items() if name != "cl"}
        columns["mx_nm"] = run.arrays["cl"] * q_s_b(campaign)
        readings.append(columns)
    given = rebuilt(campaign, readings, sample_hz=[run.sample_hz for run in campaign.runs])
    read = acquisition.read_mat(mat_file, wing=campaign.wing)
    # The same readings, bit for bit, make the same model (the fit is deterministic): one fit
    # of the recording, checked against the readings' arrays, instead of a second fit.
    for mine, theirs in zip(read.runs, given.runs):
        assert mine.arrays.keys() == theirs.arrays.keys()
        for name, values in theirs.arrays.items():
            assert np.array_equal(mine.arrays[name], values, equal_nan=True), (mine.file, name)
    fitted = rollest.fit(read)
    assert fitted.report is not None and fitted.report["heldout"]["per_alpha"]


def test_a_recording_of_another_format_is_refused_by_name(acquisition: ModuleType, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"campaign\.tdms: expected a \.mat, \.h5 or \.hdf5 recording"):
        acquisition.read_recording(tmp_path / "campaign.tdms")
