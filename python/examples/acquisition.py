"""Recordings from a tunnel's acquisition system into a rollest Dataset, then a fit.

An acquisition system writes the runs in its own file format and under its own channel names;
this example reads two such layouts, a MATLAB ``.mat`` file (``scipy.io.loadmat``) and an HDF5
file (``h5py``), renames the channels to the dataset format's (``docs/spec/dataset-format.md``)
and builds the campaign with ``Dataset.from_pandas``, in memory: nothing is written but the
model folder, when one is asked for.

    python python/examples/acquisition.py RECORDING.mat|RECORDING.h5 [MODEL_FOLDER]

Both layouts hold, besides the runs, the free-stream speed ``U_inf`` (m/s), the air density
``rho`` (kg/m^3) and the sample rate ``fs`` (Hz); each run holds its channels as 1-D arrays and
its ``kind`` (the format's run kinds) and angle of attack ``alpha`` (deg):

- ``.mat``: the scalars as variables, and a struct ``runs`` with one field per run (``rollact_a10``),
  itself a struct of the channels, ``kind`` and ``alpha``;
- HDF5: the scalars as attributes of the root, a group ``/runs`` with one group per run (read in
  the order they were written when the file tracks it, else by name), the channels as its data
  sets, ``kind`` and ``alpha`` as its attributes.

The balance's roll moment ``Mx`` is in N m: it becomes the format's ``mx_nm``, which the dataset
converts to ``cl = Mx / (q S b)`` with ``q = rho U_inf^2 / 2`` and the wing's area and span.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Union

import numpy as np
import pandas as pd

import rollest

#: The acquisition system's channel names and the dataset format's. Channels not named here (a
#: thermocouple, a trigger) are left out.
CHANNELS: Dict[str, str] = {
    "time": "t_s",
    "roll_deg": "phi_deg",
    "roll_cmd_deg": "phi_cmd_deg",
    "Cmu_L": "cmu_port",
    "Cmu_R": "cmu_stbd",
    "Cmu_L_cmd": "cmu_port_cmd",
    "Cmu_R_cmd": "cmu_stbd_cmd",
    **{f"p{tap:02d}": f"cp{tap:02d}" for tap in range(1, 13)},
    "Mx": "mx_nm",
}

PathLike = Union[str, Path]


def run_frame(channels: Mapping[str, Any]) -> pd.DataFrame:
    """One run's channels under the format's names, as a DataFrame (1-D arrays of one length)."""
    return pd.DataFrame(
        {CHANNELS[name]: np.asarray(values, dtype=np.float64).ravel() for name, values in channels.items() if name in CHANNELS}
    )


def to_dataset(
    runs: Mapping[str, Mapping[str, Any]],
    *,
    u_inf_mps: float,
    rho_kgm3: float,
    sample_hz: float,
    wing: Optional[Mapping[str, float]] = None,
) -> rollest.Dataset:
    """The campaign from each run's channels, ``kind`` and ``alpha`` by run name (``runs/NAME.csv``
    in the dataset); ``wing`` the paper's model when None."""
    frames = {f"runs/{name}.csv": run_frame(channels) for name, channels in runs.items()}
    return rollest.Dataset.from_pandas(
        frames,
        u_inf_mps=u_inf_mps,
        rho_kgm3=rho_kgm3,
        kind=[str(channels["kind"]) for channels in runs.values()],
        alpha_deg=[float(channels["alpha"]) for channels in runs.values()],
        sample_hz=sample_hz,
        wing=wing,
    )


def read_mat(path: PathLike, wing: Optional[Mapping[str, float]] = None) -> rollest.Dataset:
    """A MATLAB ``.mat`` recording (the layout of the module's docs) as a Dataset."""
    from scipy.io import loadmat

    contents = loadmat(path, simplify_cells=True)
    return to_dataset(
        contents["runs"],
        u_inf_mps=float(contents["U_inf"]),
        rho_kgm3=float(contents["rho"]),
        sample_hz=float(contents["fs"]),
        wing=wing,
    )


def read_hdf5(path: PathLike, wing: Optional[Mapping[str, float]] = None) -> rollest.Dataset:
    """An HDF5 recording (the layout of the module's docs) as a Dataset."""
    import h5py

    with h5py.File(path, "r") as file:
        runs = {
            name: {
                **{channel: data[()] for channel, data in group.items()},
                "kind": group.attrs["kind"],
                "alpha": group.attrs["alpha"],
            }
            for name, group in file["runs"].items()
        }
        return to_dataset(
            runs,
            u_inf_mps=float(file.attrs["U_inf"]),
            rho_kgm3=float(file.attrs["rho"]),
            sample_hz=float(file.attrs["fs"]),
            wing=wing,
        )


def read_recording(path: PathLike, wing: Optional[Mapping[str, float]] = None) -> rollest.Dataset:
    """A ``.mat`` or HDF5 (``.h5``, ``.hdf5``) recording as a Dataset, by its extension."""
    suffix = Path(path).suffix.lower()
    if suffix == ".mat":
        return read_mat(path, wing)
    if suffix in (".h5", ".hdf5"):
        return read_hdf5(path, wing)
    raise ValueError(f"{path}: expected a .mat, .h5 or .hdf5 recording")


def main(argv: list[str]) -> None:
    data = read_recording(argv[1])
    model = rollest.fit(data, argv[2] if len(argv) > 2 else None)
    print(f"{argv[1]}: {len(data)} runs fitted")
    model.print()


if __name__ == "__main__":
    main(sys.argv)
