"""rollest: roll-moment estimation for active flow control on a rolling delta wing.

The same engine as the ``host-tools`` command line, in-process: read a recorded campaign
(:func:`load_dataset`), record a synthetic one (:func:`simulate`), fit a model (:func:`fit`),
replay it (:meth:`Model.replay`), evaluate it (:func:`evaluate`), diagnose the sim-to-real gap
(:func:`diagnose`), and step the estimator that flies (:class:`Estimator`), bit for bit as the
firmware steps it.

Quick start::

    import rollest
    data = rollest.load_dataset("out/campaign")
    model = rollest.fit(data, "out/model")
    est = rollest.Estimator(model)
    outputs = est.run(data.runs[0])          # every stage's output, as arrays
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _rollest
from ._rollest import DatasetError, RollestError

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = [
    "DEFAULT_HOLDOUT_FRACTION",
    "Dataset",
    "DatasetError",
    "Diagnosis",
    "Estimator",
    "Evaluation",
    "Model",
    "Progress",
    "REPLAY_COLUMNS",
    "RollestError",
    "Run",
    "diagnose",
    "evaluate",
    "fit",
    "heldout_start",
    "load_dataset",
    "simulate",
]

PathLike = Union[str, "os.PathLike[str]"]
#: A progress callable of the long calls: ``progress(message, done, total)``. At each new stage
#: ``done`` is 0 and ``total`` the stage's number of steps (None when not counted); each step
#: done calls it again. It runs on the command's worker threads; an exception it raises is
#: raised when the call returns.
Progress = Callable[[str, int, Optional[int]], object]

#: Share of every run, at its end, held out from fitting (the command line's default).
DEFAULT_HOLDOUT_FRACTION: float = _rollest.DEFAULT_HOLDOUT_FRACTION
#: The columns of a replay (``host-tools replay`` files, :meth:`Model.replay`): the recorded
#: inputs and balance, every stage's estimate (``cl_est`` is the estimate of ``cl``) and health.
REPLAY_COLUMNS: List[str] = list(_rollest.REPLAY_COLUMNS)
#: Taps of the pressure model, ``cp01`` .. ``cp12``.
CP_COLUMNS: List[str] = [f"cp{tap:02d}" for tap in range(1, 13)]


def heldout_start(n_samples: int, holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION) -> int:
    """The first held-out sample of a run of ``n_samples`` (the split of fit, evaluate, diagnose)."""
    return _rollest.heldout_start(n_samples, holdout_fraction)


def _pandas() -> Any:
    try:
        import pandas
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("to_pandas() needs pandas: pip install 'rollest[pandas]'") from error
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
    """A dataset folder (``roll-dataset/1``): tunnel, wing, extra keys and runs in manifest order."""

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

    @property
    def path(self) -> Path:
        """The folder (or manifest) it was read from."""
        return Path(self._native.path)

    def __len__(self) -> int:
        return len(self.runs)

    def __repr__(self) -> str:
        return f"Dataset({str(self.path)!r}, {len(self.runs)} runs)"

    def to_pandas(self) -> "pandas.DataFrame":
        """Every run in one long DataFrame, with ``run`` (file), ``kind`` and ``run_alpha_deg``
        columns (needs pandas)."""
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


def load_dataset(path: PathLike) -> Dataset:
    """Reads a dataset folder (or its ``manifest.toml``).

    Raises :class:`DatasetError` (with ``file``, ``row``, ``column`` and ``key`` attributes) on
    bad input, as the command line reports it.
    """
    return Dataset(_rollest.load_dataset(os.fspath(path)))


def simulate(
    out: PathLike,
    scenario: Optional[PathLike] = None,
    *,
    seed: Optional[int] = None,
    duration_s: Optional[float] = None,
    effects: Sequence[str] = (),
    progress: Optional[Progress] = None,
) -> Dataset:
    """Records a synthetic-tunnel campaign into ``out`` (replaced atomically) and loads it.

    ``scenario`` is a scenario TOML file (the paper's campaign when None); ``seed`` and
    ``duration_s`` override it; ``effects`` switch unmodelled effects on, e.g.
    ``["actuator_delay:delay_s=0.03"]`` (as ``host-tools simulate --effect``). ``progress``
    is told how far it is (:data:`Progress`).
    """
    scenario_path = None if scenario is None else os.fspath(scenario)
    _rollest.simulate(os.fspath(out), scenario_path, seed, duration_s, list(effects), progress)
    return load_dataset(out)


def _data_path(data: Union[Dataset, PathLike]) -> str:
    return os.fspath(data.path if isinstance(data, Dataset) else data)


class Model:
    """A fitted model: the coefficient set with its model folder (blob, card, report, plots).

    Get one from :func:`fit`, :meth:`Model.load` or :meth:`Model.built_in`.
    """

    def __init__(self, native: _rollest.Model) -> None:
        self._native = native

    @staticmethod
    def load(path: PathLike) -> "Model":
        """Reads a model folder (or its ``model.bin``) written by ``fit``."""
        return Model(_rollest.Model.load(os.fspath(path)))

    @staticmethod
    def built_in() -> "Model":
        """The tables compiled into the estimator (``estimator_core::coeffs::DEFAULT``)."""
        return Model(_rollest.Model.built_in())

    @property
    def source(self) -> str:
        """Where the model came from."""
        return self._native.source

    @property
    def path(self) -> Optional[Path]:
        """The model folder (or blob file) it was read from, which ``host-tools --model`` takes;
        None for the built-in tables."""
        path = self._native.path
        return None if path is None else Path(path)

    @property
    def dt_s(self) -> float:
        """The estimator's fixed step, s."""
        return self._native.dt_s

    @property
    def coefficients(self) -> Dict[str, Any]:
        """Every coefficient table, by the core's field names (a copy)."""
        coefficients: Dict[str, Any] = json.loads(self._native.coefficients_json())
        return coefficients

    @property
    def card(self) -> Optional[str]:
        """The model card (``model.md``, Markdown), when the folder has one."""
        return self._native.card()

    @property
    def report(self) -> Optional[Dict[str, Any]]:
        """The fit's report (``model.json``'s ``report``: split, every block's fit, the
        held-out table as ``report["heldout"]["per_alpha"]``), when the folder has one."""
        text = self._native.model_json()
        return None if text is None else json.loads(text)["report"]

    def blob(self) -> bytes:
        """The postcard blob (``model.bin``; what the firmware and ``rollest_init_blob`` load)."""
        return self._native.blob()

    def save(self, path: PathLike) -> None:
        """Writes the model folder to ``path`` (complete or not at all); ``host-tools --model``
        and :meth:`Model.load` read it."""
        self._native.save(os.fspath(path))

    def replay(
        self, dataset: Dataset, *, faults: Sequence[str] = (), fault_seed: int = 1
    ) -> List[Dict[str, np.ndarray]]:
        """Replays every run of ``dataset`` as ``host-tools replay`` does (same outputs, bit for
        bit), with sensor ``faults`` (``--fault`` specs such as ``"stuck:cp07@10s"``) when given.

        Returns, per run in manifest order, the replay file's columns (:data:`REPLAY_COLUMNS`)
        as arrays: recorded float64, estimates float32, health uint16.
        """
        replayed = self._native.replay(dataset._native, list(faults), fault_seed)
        return [{name: run[name] for name in REPLAY_COLUMNS} for run in replayed]

    def __repr__(self) -> str:
        return f"Model({self.source!r})"

    def _repr_markdown_(self) -> str:
        """A notebook shows the model card."""
        return self.card or f"Model from {self.source} (no model card)"


def fit(
    data: Union[Dataset, PathLike],
    out: Optional[PathLike] = None,
    *,
    seed: int = 1,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Model:
    """Fits every coefficient on the training part of ``data`` (``host-tools fit``).

    The model folder goes to ``out`` (replaced atomically), or to a new temporary folder when
    None (save it with :meth:`Model.save`). ``progress`` is told how far it is
    (:data:`Progress`).
    """
    target = tempfile.mkdtemp(prefix="rollest-model-") if out is None else os.fspath(out)
    if out is None:
        os.rmdir(target)  # the fit writes the folder whole, or not at all
    return Model(_rollest.fit(_data_path(data), target, seed, holdout_fraction, progress))


def _model_path(model: Optional[Union[Model, PathLike]]) -> Optional[str]:
    if model is None:
        return None
    if isinstance(model, Model):
        return None if model.path is None else os.fspath(model.path)
    return os.fspath(model)


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate` wrote: ``results`` (``evaluation.json`` as a dict), the report
    folder and its page, and what the report left out."""

    results: Dict[str, Any]
    folder: Path
    page: Path
    warnings: List[str]


def evaluate(
    data: Union[Dataset, PathLike],
    report: PathLike,
    model: Optional[Union[Model, PathLike]] = None,
    *,
    seed: int = 1,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Evaluation:
    """The paper's analysis on the held-out part of ``data`` (``host-tools evaluate``): the
    report folder (HTML, Markdown, SVG figures, ``evaluation.json``) and its results. ``model``
    is the built-in tables when None."""
    page, warnings = _rollest.evaluate(
        _data_path(data), os.fspath(report), _model_path(model), seed, holdout_fraction, progress
    )
    folder = Path(report)
    results = json.loads((folder / "evaluation.json").read_text())
    return Evaluation(results=results, folder=folder, page=Path(page), warnings=list(warnings))


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` wrote: ``results`` (``diagnosis.json``, the contract of
    ``docs/spec/diagnosis.md``, as a dict), the report folder and its page."""

    results: Dict[str, Any]
    folder: Path
    page: Path

    @property
    def verdict(self) -> str:
        """``effect`` (an effect is named), ``none`` (the gap is at the noise floor) or
        ``unattributed`` (a real gap no effect explains): the words of docs/spec/diagnosis.md."""
        return str(self.results["verdict"])


def diagnose(
    real: Union[Dataset, PathLike],
    report: PathLike,
    model: Optional[Union[Model, PathLike]] = None,
    *,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Diagnosis:
    """The sim-to-real gap of ``real`` against ``model`` (``host-tools diagnose``): where the gap
    lies, which unmodelled effect causes it, how far it shrinks once that effect is added.
    ``model`` None fits nominal models on the data's training part."""
    page = _rollest.diagnose(_data_path(real), os.fspath(report), _model_path(model), holdout_fraction, progress)
    folder = Path(report)
    results = json.loads((folder / "diagnosis.json").read_text())
    return Diagnosis(results=results, folder=folder, page=Path(page))


def _column(columns: Any, name: str) -> np.ndarray:
    """One column (of a mapping or a DataFrame) as contiguous float64."""
    try:
        values = columns[name]
    except KeyError:
        raise KeyError(f"run(): expected a column named {name!r}, found none") from None
    return np.ascontiguousarray(np.asarray(values, dtype=np.float64))


class Estimator:
    """The estimator that flies (estimator-core, f32), stepped from Python.

    ``step`` takes one sample; ``run`` a whole run's arrays, stepped in Rust without the GIL.
    Both continue from the present state; ``reset`` starts afresh.
    """

    def __init__(self, model: Optional[Model] = None) -> None:
        """A fresh estimator over ``model``'s tables (the built-in tables when None)."""
        self._native = _rollest.Estimator(None if model is None else model._native)

    @property
    def dt_s(self) -> float:
        """The fixed step, s: one call of ``step`` per sample at ``1 / dt_s`` Hz."""
        return self._native.dt_s

    def reset(self) -> None:
        """Back to the state of a fresh estimator."""
        self._native.reset()

    def note_demand(self, cmu_port: float, cmu_stbd: float) -> None:
        """Notes the controller's demand after a step: a missing Cmu is then predicted from it."""
        self._native.note_demand(cmu_port, cmu_stbd)

    def step(
        self,
        phi_deg: float,
        alpha_deg: float,
        cmu_port: float,
        cmu_stbd: float,
        cp: Sequence[float],
        demand: Optional[Tuple[float, float]] = None,
    ) -> Dict[str, float]:
        """One step on one sample (NaN for a value not measured), then the ``demand``
        ``(port, stbd)`` noted when given. Returns every stage's estimate and the health fields
        by the replay file's names (``cl_est``, ``cl_roll``, ``health_flags``, ...)."""
        return self._native.step(phi_deg, alpha_deg, cmu_port, cmu_stbd, [float(v) for v in cp], demand)

    def run(
        self, columns: Union[Run, Mapping[str, Any], "pandas.DataFrame"], alpha_deg: Optional[float] = None
    ) -> Dict[str, np.ndarray]:
        """Steps over a whole run: a :class:`Run`, a DataFrame or a mapping of arrays with
        ``phi_deg``, ``cmu_port``, ``cmu_stbd`` and ``cp01`` .. ``cp12``; the angle of attack from
        an ``alpha_deg`` column, the ``alpha_deg`` argument, or both (the column where finite);
        ``cmu_port_cmd``/``cmu_stbd_cmd`` when recorded (noted after each step, as the replay).

        Returns every stage's estimate (float32) and the health fields (uint16), by the replay
        file's names; the same values, bit for bit, as ``host-tools replay``.
        """
        if isinstance(columns, Run):
            arrays: Any = columns.arrays
            alpha = columns.alpha_series()
        else:
            arrays = columns
            if "alpha_deg" in arrays:
                alpha = _column(arrays, "alpha_deg")
                if alpha_deg is not None:  # as the replay: the column where finite, else the run's
                    alpha = np.where(np.isfinite(alpha), alpha, float(alpha_deg))
            elif alpha_deg is not None:
                alpha = np.full(len(_column(arrays, "phi_deg")), float(alpha_deg))
            else:
                raise KeyError("run(): expected a column named 'alpha_deg' or the alpha_deg argument")
        cp = np.ascontiguousarray(np.column_stack([_column(arrays, name) for name in CP_COLUMNS]))
        commands = [_column(arrays, name) if name in arrays else None for name in ("cmu_port_cmd", "cmu_stbd_cmd")]
        return dict(
            self._native.run(
                _column(arrays, "phi_deg"),
                np.ascontiguousarray(alpha, dtype=np.float64),
                _column(arrays, "cmu_port"),
                _column(arrays, "cmu_stbd"),
                cp,
                commands[0],
                commands[1],
            )
        )
