"""Datasets: recorded campaigns in the contract format (``docs/spec/dataset-format.md``), read
from a folder or built in memory from a tunnel's arrays or DataFrames, and written back.

A researcher's recordings come from the acquisition system (MATLAB ``.mat``, HDF5, TDMS) into
NumPy or pandas; :meth:`Dataset.from_arrays` and :meth:`Dataset.from_pandas` take them as they
are, with the manifest's metadata as arguments, and check them as a folder is checked when
read: a :class:`DatasetError` names the run's file, the row (header = row 1), the column or the
manifest key.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _rollest

if TYPE_CHECKING:  # pragma: no cover
    import pandas

PathLike = Union[str, "os.PathLike[str]"]

#: The manifest's ``[wing]`` keys (``docs/spec/dataset-format.md``); the paper's model when absent.
WING_KEYS: Tuple[str, ...] = ("chord_m", "span_m", "area_m2", "ixx_kgm2", "mass_kg")
#: The run kinds of the format.
RUN_KINDS: Tuple[str, ...] = ("roll", "actuation", "roll+actuation", "static")
#: Columns of a long DataFrame (:meth:`Dataset.to_pandas`) that carry a run's metadata, not a channel.
_META_COLUMNS: Tuple[str, ...] = ("run", "kind", "run_alpha_deg", "run_sample_hz")


def _pandas() -> Any:
    try:
        import pandas
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("this needs pandas: pip install 'rollest[pandas]'") from error
    return pandas


@dataclass(frozen=True)
class Run:
    """One recorded run: its manifest entry and its channels as float64 arrays.

    ``arrays`` holds ``t_s``, ``phi_deg``, ``cmu_port``, ``cmu_stbd``, ``cp01`` .. ``cp12`` and
    ``cl`` (the roll-moment coefficient, converted from ``mx_nm`` when the file had that), and
    ``alpha_deg``, ``phi_cmd_deg``, ``cmu_port_cmd``, ``cmu_stbd_cmd`` when recorded. A missing
    sample is NaN. Columns the format does not define (a rig's ``temperature_c``, say) are
    ignored, as the format says; ``pandas.read_csv`` reads them.
    """

    file: str
    kind: str
    alpha_deg: float
    sample_hz: float
    extra: Dict[str, Any]
    arrays: Dict[str, np.ndarray] = field(repr=False)

    def __len__(self) -> int:
        return len(self.arrays["t_s"])

    def alpha_series(self) -> np.ndarray:
        """Angle of attack per sample, deg: the recorded column where finite, else the run's."""
        alpha = self.arrays.get("alpha_deg")
        if alpha is None:
            return np.full(len(self), self.alpha_deg)
        return np.where(np.isfinite(alpha), alpha, self.alpha_deg)

    def to_pandas(self) -> "pandas.DataFrame":
        """The channels as a DataFrame indexed by ``t_s`` (needs pandas)."""
        frame: "pandas.DataFrame" = _pandas().DataFrame(self.arrays).set_index("t_s")
        return frame


class Dataset:
    """A campaign in the contract format (``roll-dataset/1``): tunnel, wing, extra keys and runs
    in manifest order. Read one with :func:`load_dataset`, build one with :meth:`from_arrays`
    or :meth:`from_pandas`, write it with :meth:`write`."""

    def __init__(self, native: _rollest.Dataset) -> None:
        self._native = native
        manifest = json.loads(native.manifest_json())
        self.tunnel: Dict[str, float] = manifest["tunnel"]
        self.wing: Dict[str, float] = manifest["wing"]
        self.extra: Dict[str, Any] = manifest["extra"]
        self.runs: List[Run] = [
            Run(
                file=meta["file"],
                kind=meta["kind"],
                alpha_deg=meta["alpha_deg"],
                sample_hz=meta["sample_hz"],
                extra=meta["extra"],
                arrays=dict(native.run_arrays(index)),
            )
            for index, meta in enumerate(manifest["runs"])
        ]

    @staticmethod
    def from_arrays(
        runs: Sequence[Mapping[str, Any]],
        *,
        kind: Union[str, Sequence[str]],
        alpha_deg: Union[float, Sequence[float]],
        u_inf_mps: float,
        rho_kgm3: float,
        sample_hz: Union[None, float, Sequence[Optional[float]]] = None,
        wing: Optional[Mapping[str, float]] = None,
        files: Optional[Sequence[str]] = None,
        extra: Optional[Mapping[str, Any]] = None,
        run_extra: Optional[Sequence[Mapping[str, Any]]] = None,
    ) -> "Dataset":
        """A dataset from each run's columns (a mapping of the format's column names to 1-D
        arrays, e.g. ``{"t_s": t, "phi_deg": phi, "cmu_port": c, "cp01": ..., "cl": cl}``),
        with the manifest's metadata as arguments: ``kind`` and ``alpha_deg`` per run (one
        value for all, or one each), the tunnel's ``u_inf_mps`` and ``rho_kgm3``, and the
        ``wing`` keys (:data:`WING_KEYS`; the paper's model when None).

        ``sample_hz`` is taken from each run's ``t_s`` when None (the median step); the times
        must then lie on that uniform grid, as the format requires. ``files`` names the runs
        (``runs/run-001.csv`` .. when None): errors, and :meth:`write`, use them. ``extra`` and
        ``run_extra`` are the manifest's further keys. Other columns are ignored, as the format
        says; ``cmu_stbd`` is zero when absent; ``mx_nm`` (N m) is converted to ``cl`` when
        ``cl`` is absent.

        Raises :class:`DatasetError` naming the run's file, row, column or key, as reading a
        folder does.
        """
        n_runs = len(runs)
        files = list(files) if files is not None else [f"runs/run-{index + 1:03d}.csv" for index in range(n_runs)]
        kinds = _per_run("kind", kind, n_runs)
        alphas = _per_run("alpha_deg", alpha_deg, n_runs)
        rates = _per_run("sample_hz", sample_hz, n_runs)
        extras = list(run_extra) if run_extra is not None else [{} for _ in range(n_runs)]
        for name, values in (("files", files), ("run_extra", extras)):
            if len(values) != n_runs:
                raise _error(f"{name}: expected one entry per run ({n_runs}), found {len(values)}", key=name)
        columns: List[List[Tuple[str, np.ndarray]]] = []
        metadata_runs = []
        for index, run in enumerate(runs):
            arrays = [(str(name), _float_column(files[index], str(name), values)) for name, values in run.items()]
            rate = rates[index]
            if rate is None:
                rate = _rate_of(files[index], dict(arrays))
            columns.append(arrays)
            metadata_runs.append(
                {
                    "file": files[index],
                    "kind": str(kinds[index]),
                    "alpha_deg": float(alphas[index]),
                    "sample_hz": float(rate),
                    "extra": dict(extras[index]),
                }
            )
        metadata = {
            "tunnel": {"u_inf_mps": float(u_inf_mps), "rho_kgm3": float(rho_kgm3)},
            "wing": None if wing is None else {key: float(wing[key]) for key in WING_KEYS if key in wing},
            "extra": dict(extra or {}),
            "runs": metadata_runs,
        }
        if wing is not None:
            missing = [key for key in WING_KEYS if key not in wing]
            if missing:
                raise _error(
                    f"wing: expected the keys {', '.join(WING_KEYS)}, missing {', '.join(missing)}", key="wing"
                )
        return Dataset(_rollest.dataset_from_parts(json.dumps(metadata), columns))

    @staticmethod
    def from_pandas(
        frames: Union["pandas.DataFrame", Mapping[str, "pandas.DataFrame"], Sequence["pandas.DataFrame"]],
        *,
        u_inf_mps: float,
        rho_kgm3: float,
        kind: Union[None, str, Sequence[str]] = None,
        alpha_deg: Union[None, float, Sequence[float]] = None,
        sample_hz: Union[None, float, Sequence[Optional[float]]] = None,
        wing: Optional[Mapping[str, float]] = None,
        extra: Optional[Mapping[str, Any]] = None,
    ) -> "Dataset":
        """A dataset from DataFrames, one per run, with the format's column names (``t_s`` as a
        column or as the index, as :meth:`Run.to_pandas` gives it): a mapping of run file to
        frame, a sequence of frames, or one long frame with a ``run`` column (as
        :meth:`to_pandas` gives it; its ``kind`` and ``run_alpha_deg`` columns then give each
        run's metadata). ``kind`` and ``alpha_deg`` are per run (one value for all, or one each)
        where the frames do not carry them. The rest is :meth:`from_arrays`'s.
        """
        named = _frames_by_run(frames)
        files = [name if name.endswith(".csv") else f"{name}.csv" for name in named]
        runs = []
        kinds: List[Optional[str]] = []
        alphas: List[Optional[float]] = []
        for frame in named.values():
            if frame.index.name == "t_s" and "t_s" not in frame.columns:
                frame = frame.reset_index()
            kinds.append(_constant(frame, "kind"))
            alpha = _constant(frame, "run_alpha_deg")
            alphas.append(None if alpha is None else float(alpha))
            runs.append({str(name): frame[name].to_numpy() for name in frame.columns if name not in _META_COLUMNS})
        n_runs = len(runs)
        given_kinds = _per_run("kind", kind, n_runs) if kind is not None else [None] * n_runs
        given_alphas = _per_run("alpha_deg", alpha_deg, n_runs) if alpha_deg is not None else [None] * n_runs
        run_kinds = []
        run_alphas = []
        for index, file in enumerate(files):
            chosen_kind = given_kinds[index] if given_kinds[index] is not None else kinds[index]
            chosen_alpha = given_alphas[index] if given_alphas[index] is not None else alphas[index]
            if chosen_kind is None:
                raise _error(f"{file}: expected the run's kind (the kind argument or a 'kind' column)", file=file, key="kind")
            if chosen_alpha is None:
                raise _error(
                    f"{file}: expected the run's angle of attack (the alpha_deg argument or a 'run_alpha_deg' column)",
                    file=file,
                    key="alpha_deg",
                )
            run_kinds.append(str(chosen_kind))
            run_alphas.append(float(chosen_alpha))
        return Dataset.from_arrays(
            runs,
            kind=run_kinds,
            alpha_deg=run_alphas,
            u_inf_mps=u_inf_mps,
            rho_kgm3=rho_kgm3,
            sample_hz=sample_hz,
            wing=wing,
            files=files,
            extra=extra,
        )

    def __reduce__(self) -> Tuple[Any, Tuple[Any, ...]]:
        """Pickled as its metadata and arrays (a campaign sends recordings to other processes);
        unpickled, it is a dataset built in memory, checked again."""
        manifest = json.loads(self._native.manifest_json())
        metadata = {
            "tunnel": {key: manifest["tunnel"][key] for key in ("u_inf_mps", "rho_kgm3")},
            "wing": manifest["wing"],
            "extra": manifest["extra"],
            "runs": [
                {key: run[key] for key in ("file", "kind", "alpha_deg", "sample_hz", "extra")}
                for run in manifest["runs"]
            ],
        }
        columns = [list(run.arrays.items()) for run in self.runs]
        return (_unpickled, (json.dumps(metadata), columns))

    @property
    def path(self) -> Optional[Path]:
        """The folder (or manifest) it was read from; None when built in memory."""
        path = self._native.path
        return None if path is None else Path(path)

    def write(self, path: PathLike) -> None:
        """Writes the dataset as a folder of the format (``manifest.toml`` and a CSV file per
        run), completely or not at all; :func:`load_dataset` reads back the same values, bit
        for bit. An existing folder is replaced only when it is a dataset (or empty)."""
        self._native.write(os.fspath(path))

    def __len__(self) -> int:
        return len(self.runs)

    def __repr__(self) -> str:
        where = "in memory" if self.path is None else repr(str(self.path))
        return f"Dataset({where}, {len(self.runs)} runs)"

    def to_pandas(self) -> "pandas.DataFrame":
        """Every run in one long DataFrame, with ``run`` (file), ``kind`` and ``run_alpha_deg``
        columns (needs pandas); :meth:`from_pandas` takes it back."""
        pd = _pandas()
        frames = []
        for run in self.runs:
            frame = pd.DataFrame(run.arrays)
            frame.insert(0, "run_alpha_deg", run.alpha_deg)
            frame.insert(0, "kind", run.kind)
            frame.insert(0, "run", run.file)
            frames.append(frame)
        whole: "pandas.DataFrame" = pd.concat(frames, ignore_index=True)
        return whole


def _unpickled(metadata_json: str, columns: List[List[Tuple[str, np.ndarray]]]) -> Dataset:
    """A pickled :class:`Dataset`, built again."""
    aligned = [[(name, _float_column("", name, values)) for name, values in run] for run in columns]
    return Dataset(_rollest.dataset_from_parts(metadata_json, aligned))


def load_dataset(path: PathLike) -> Dataset:
    """Reads a dataset folder (or its ``manifest.toml``).

    Raises :class:`DatasetError` (with ``file``, ``row``, ``column`` and ``key`` attributes) on
    bad input, as the command line reports it.
    """
    return Dataset(_rollest.load_dataset(os.fspath(path)))


def as_dataset(data: Union[Dataset, PathLike]) -> Dataset:
    """``data`` itself, or the dataset folder it names, read."""
    return data if isinstance(data, Dataset) else load_dataset(data)


def _error(
    message: str, *, file: Optional[str] = None, column: Optional[str] = None, key: Optional[str] = None
) -> "_rollest.DatasetError":
    """A :class:`DatasetError` raised before the data reach the engine, with the attributes the
    engine's carry (``file``, ``row``, ``column``, ``key``)."""
    error = _rollest.DatasetError(message)
    error.file, error.row, error.column, error.key = file, None, column, key
    return error


def _per_run(name: str, value: Any, n_runs: int) -> List[Any]:
    """One value per run: ``value`` repeated, or its entries when it is a sequence of them."""
    if isinstance(value, (str, bytes)) or value is None or np.isscalar(value):
        return [value] * n_runs
    values = list(value)
    if len(values) != n_runs:
        raise _error(f"{name}: expected one value, or one per run ({n_runs}), found {len(values)}", key=name)
    return values


def _float_column(file: str, name: str, values: Any) -> np.ndarray:
    """A column as contiguous 1-D float64 (missing samples NaN), or an error naming it."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise _error(f"{file}: column {name!r}: expected numbers, found {error}", file=file, column=name) from None
    # The engine reads the samples in place: contiguous and aligned (an array unpickled from
    # out-of-band buffers, as Dask sends them, may be neither).
    array = np.require(array, dtype=np.float64, requirements=["C_CONTIGUOUS", "ALIGNED"])
    if array.ndim != 1:
        raise _error(
            f"{file}: column {name!r}: expected one value per sample, found shape {array.shape}", file=file, column=name
        )
    return array


def _rate_of(file: str, columns: Mapping[str, np.ndarray]) -> float:
    """The sample rate, Hz, of a run's ``t_s`` (its finite samples' span over their count), or
    an error naming the run; whether every time lies on that grid is the engine's check, which
    names the row."""
    t_s = columns.get("t_s")
    if t_s is None:
        raise _error(f"{file}: expected a column named 't_s', found none", file=file, column="t_s")
    finite = np.flatnonzero(np.isfinite(t_s))
    if len(finite) < 2 or t_s[finite[-1]] <= t_s[finite[0]]:
        raise _error(
            f"{file}: column 't_s': expected increasing sample times to take the sample rate from "
            "(or pass sample_hz)",
            file=file,
            column="t_s",
        )
    # Over the whole span, to nine significant digits: an acquisition system's rate is a round
    # number, and the steps' rounding in t_s would otherwise leave 1000.0000000001 Hz.
    rate = (finite[-1] - finite[0]) / float(t_s[finite[-1]] - t_s[finite[0]])
    return float(f"{rate:.9g}")


def _frames_by_run(frames: Any) -> Dict[str, "pandas.DataFrame"]:
    """Each run's frame by its name: from a mapping, a sequence, or a long frame's ``run`` column."""
    pd = _pandas()
    if isinstance(frames, pd.DataFrame):
        if "run" in frames.columns:
            return {str(name): group.reset_index(drop=True) for name, group in frames.groupby("run", sort=False)}
        return {"runs/run-001.csv": frames}
    if isinstance(frames, Mapping):
        return {str(name): frame for name, frame in frames.items()}
    return {f"runs/run-{index + 1:03d}.csv": frame for index, frame in enumerate(frames)}


def _constant(frame: "pandas.DataFrame", column: str) -> Optional[Any]:
    """The single value of a metadata column of a run's frame (None when absent), or an error."""
    if column not in frame.columns:
        return None
    values = frame[column].unique()
    if len(values) != 1:
        raise _error(f"column {column!r}: expected one value per run, found {len(values)}", column=column)
    return values[0]
