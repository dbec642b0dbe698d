"""rollest: roll-moment estimation for active flow control on a rolling delta wing.

The same engine as the ``host-tools`` command line, in-process: read a recorded campaign
(:func:`load_dataset`), record a synthetic one (:func:`simulate`), fit a model (:func:`fit`),
replay it (:meth:`Model.replay`), evaluate it (:func:`evaluate`), diagnose the sim-to-real gap
(:func:`diagnose`), and step the estimator that flies (:class:`Estimator`), bit for bit as the
firmware steps it.

Everything runs in memory: a :class:`Dataset` built from arrays or DataFrames
(:meth:`Dataset.from_pandas`) is fitted, evaluated and diagnosed without being written, and a
report folder is written only when one is asked for.

Quick start::

    import rollest
    data = rollest.load_dataset("out/campaign")   # or rollest.Dataset.from_pandas(frames, ...)
    model = rollest.fit(data)                     # in memory; model.save("out/model") to keep it
    est = rollest.Estimator(model)
    outputs = est.run(data.runs[0])               # every stage's output, as arrays
    print(rollest.diagnose(data, model=model).verdict)
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _rollest
from ._rollest import DatasetError, RollestError
from . import sindy
from .campaign import Validation, validate_diagnosis
from .dataset import Dataset, PathLike, Run, as_dataset, load_dataset
from .diagnosis import Diagnosis
from .closed_loop import SilPoint, SilResult, SilSweep, sil, sil_sweep

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = [
    "DEFAULT_HOLDOUT_FRACTION",
    "__version__",
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
    "SilPoint",
    "SilResult",
    "SilSweep",
    "Validation",
    "diagnose",
    "evaluate",
    "fit",
    "heldout_start",
    "load_dataset",
    "sil",
    "sil_sweep",
    "simulate",
    "validate_diagnosis",
]

#: A progress callable of the long calls: ``progress(message, done, total)``. At each new stage
#: ``done`` is 0 and ``total`` the stage's number of steps (None when not counted); each step
#: done calls it again. It runs on the command's worker threads; an exception it raises is
#: raised when the call returns.
Progress = Callable[[str, int, Optional[int]], object]

#: The package's version (the workspace's).
__version__: str = _rollest.__version__

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
        """Every coefficient table by the core's field names, its numbers as NumPy arrays (a
        copy): ``model.coefficients["plant"][0]["model"]``, say."""
        coefficients: Dict[str, Any] = _arrays(json.loads(self._native.coefficients_json()))
        return coefficients

    def equations(self, precision: int = 3) -> Dict[str, str]:
        """Each sparse model of the fit as an equation with its terms' names, as PySINDy's
        ``SINDy.print()`` writes them (coefficients to ``precision`` decimals): the plant of
        each jet (paper eq. 5) and the coupling operator (eqs. 9-12), by block.

        Needs the fit's report (a model fitted here, or a model folder written by ``fit``); the
        built-in tables are ``models/default``'s, whose folder has it."""
        report = self.report
        if report is None:
            raise RollestError(
                f"{self.source}: expected a fit report (model.json) to name the sparse models' terms; "
                "load the model folder written by fit (the built-in tables are models/default's)"
            )

        def equation(lhs: str, fit: Optional[Dict[str, Any]]) -> Optional[str]:
            if fit is None:
                return None
            terms = [(str(name), float(value)) for name, value in fit["terms"] if float(value) != 0.0]
            rhs = " ".join(
                f"{'-' if value < 0 else '+'} {abs(value):.{precision}f} {name}" for name, value in terms
            ).lstrip("+ ")
            return f"{lhs} = {rhs or '0'}"

        blocks = {
            "plant_port": equation("C_l,AFC,port[k+1]", report["plant"][0]),
            "plant_starboard": equation("C_l,AFC,stbd[k+1]", report["plant"][1]),
            "coupling": equation("C_l - C_l,roll - C_l,AFC", report.get("coupling")),
        }
        return {block: text for block, text in blocks.items() if text is not None}

    def print(self, precision: int = 3) -> None:
        """Prints :meth:`equations`, one line per sparse model, as PySINDy's ``print()``."""
        for text in self.equations(precision).values():
            print(text)

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
        self, dataset: Union[Dataset, PathLike], *, faults: Sequence[str] = (), fault_seed: int = 1, frame: bool = False
    ) -> List[Any]:
        """Replays every run of ``dataset`` as ``host-tools replay`` does (same outputs, bit for
        bit), with sensor ``faults`` (``--fault`` specs such as ``"stuck:cp07@10s"``) when given.

        Returns, per run in manifest order, the replay file's columns (:data:`REPLAY_COLUMNS`)
        as arrays: recorded float64, estimates float32, health uint16; with ``frame``, as a
        DataFrame indexed by ``t_s`` (needs pandas).
        """
        replayed = self._native.replay(as_dataset(dataset)._native, list(faults), fault_seed)
        runs = [{name: run[name] for name in REPLAY_COLUMNS} for run in replayed]
        if not frame:
            return runs
        from .dataset import _pandas

        return [_pandas().DataFrame(run).set_index("t_s") for run in runs]

    def __reduce__(self) -> Tuple[Any, Tuple[Any, ...]]:
        """Pickled as its model folder's files (a campaign sends models to other processes)."""
        path = self._native.path
        return (_model_from_files, (self.source, self._native.files(), path))

    def __repr__(self) -> str:
        return f"Model({self.source!r})"

    def _repr_markdown_(self) -> str:
        """A notebook shows the model card."""
        return self.card or f"Model from {self.source} (no model card)"

    def _repr_html_(self) -> str:
        """A notebook shows where the model came from, its sparse models as equations, and its
        held-out table."""
        import html

        parts = [f"<div><p><b>Model</b> from {html.escape(self.source)}; step {self.dt_s:g} s</p>"]
        report = self.report
        if report is not None:
            parts.append("<pre>" + html.escape("\n".join(self.equations().values())) + "</pre>")
            rows = report.get("heldout", {}).get("per_alpha", [])
            if rows:
                columns = [key for key, value in rows[0].items() if not isinstance(value, (dict, list))]
                head = "".join(f"<th>{html.escape(column)}</th>" for column in columns)
                body = "".join(
                    "<tr>" + "".join(f"<td>{_cell(row[column])}</td>" for column in columns) + "</tr>" for row in rows
                )
                parts.append(f"<p>Held-out RMS of C_l</p><table><tr>{head}</tr>{body}</table>")
        parts.append("</div>")
        return "".join(parts)


def _model_from_files(source: str, files: List[Tuple[str, bytes]], path: Optional[str]) -> Model:
    """A pickled :class:`Model`, built again from its files."""
    return Model(_rollest.Model.from_files(source, files, path))


def _cell(value: Any) -> str:
    """A table cell: numbers to four significant digits."""
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _arrays(value: Any) -> Any:
    """A JSON value with every list of numbers (of any nesting) as a float64 array."""
    if isinstance(value, dict):
        return {key: _arrays(item) for key, item in value.items()}
    if isinstance(value, list):
        if value and all(isinstance(item, (int, float)) and not isinstance(item, bool) for item in value):
            return np.asarray(value, dtype=np.float64)
        converted = [_arrays(item) for item in value]
        if converted and all(isinstance(item, np.ndarray) for item in converted):
            shapes = {item.shape for item in converted}
            if len(shapes) == 1:
                return np.stack(converted)
        return converted
    return value


def fit(
    data: Union[Dataset, PathLike],
    out: Optional[PathLike] = None,
    *,
    seed: int = 1,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Model:
    """Fits every coefficient on the training part of ``data`` (``host-tools fit``): a
    :class:`Dataset` (in memory or read) or a dataset folder.

    The model is held in memory; with ``out``, its model folder is also written there
    (replaced atomically), as ``host-tools fit --out`` writes it. Nothing else is written.
    ``progress`` is told how far it is (:data:`Progress`).
    """
    dataset = as_dataset(data)
    target = None if out is None else os.fspath(out)
    return Model(_rollest.fit(dataset._native, target, seed, holdout_fraction, progress))


def _as_model(model: Optional[Union[Model, PathLike]]) -> Optional[Model]:
    if model is None or isinstance(model, Model):
        return model
    return Model.load(model)


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate` found: ``results`` (``evaluation.json`` as a dict), what the
    report left out, and the report folder and its page when one was written."""

    results: Dict[str, Any]
    warnings: List[str]
    folder: Optional[Path] = None
    page: Optional[Path] = None

    def heldout_per_alpha(self) -> "pandas.DataFrame":
        """Table 1 of the paper on the held-out part, one row per angle of attack (needs
        pandas): the estimate's error over the roll moment's mean and spread."""
        return _frame(self.results["evaluation"]["table1"], "alpha_deg")

    def coupling_per_alpha(self) -> "pandas.DataFrame":
        """Tables 2 and 3 on the held-out part, one row per angle of attack (needs pandas): the
        coupling operator's error against the linear superposition's."""
        return _frame(self.results["evaluation"]["coupling"], "alpha_deg")

    def _repr_html_(self) -> str:
        """A notebook shows the held-out tables."""
        parts = ["<div><p><b>Evaluation on the held-out part</b></p>"]
        try:
            parts.append(self.heldout_per_alpha().to_html(float_format=lambda value: f"{value:.4g}"))
            parts.append(self.coupling_per_alpha().to_html(float_format=lambda value: f"{value:.4g}"))
        except ImportError:  # pragma: no cover - without pandas
            parts.append(f"<pre>{json.dumps(self.results['evaluation']['table1'], indent=1)}</pre>")
        parts.extend(f"<p>{warning}</p>" for warning in self.warnings)
        parts.append("</div>")
        return "".join(parts)


def _frame(rows: List[Dict[str, Any]], index: str) -> "pandas.DataFrame":
    """Rows of scalars as a DataFrame indexed by ``index`` (nested values left out)."""
    from .dataset import _pandas

    flat = [{key: value for key, value in row.items() if not isinstance(value, (dict, list))} for row in rows]
    frame: "pandas.DataFrame" = _pandas().DataFrame(flat).set_index(index)
    return frame


def evaluate(
    data: Union[Dataset, PathLike],
    report: Optional[PathLike] = None,
    model: Optional[Union[Model, PathLike]] = None,
    *,
    seed: int = 1,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Evaluation:
    """The paper's analysis on the held-out part of ``data`` (``host-tools evaluate``), with
    ``model`` (a :class:`Model` or a model folder; the built-in tables when None). The results
    are returned; the report folder (HTML, Markdown, SVG figures, ``evaluation.json``) is
    written only with ``report``."""
    dataset = as_dataset(data)
    chosen = _as_model(model)
    folder = None if report is None else os.fspath(report)
    text, page, warnings = _rollest.evaluate(
        dataset._native, None if chosen is None else chosen._native, folder, seed, holdout_fraction, progress
    )
    return Evaluation(
        results=json.loads(text),
        warnings=list(warnings),
        folder=None if report is None else Path(report),
        page=None if page is None else Path(page),
    )


def diagnose(
    real: Union[Dataset, PathLike],
    report: Optional[PathLike] = None,
    model: Optional[Union[Model, PathLike]] = None,
    *,
    holdout_fraction: float = DEFAULT_HOLDOUT_FRACTION,
    progress: Optional[Progress] = None,
) -> Diagnosis:
    """The sim-to-real gap of ``real`` against ``model`` (``host-tools diagnose``): where the gap
    lies, which unmodelled effect causes it, how far it shrinks once that effect is added.
    ``model`` None fits nominal models on the data's training part. The typed result is
    returned; the report folder is written only with ``report``."""
    dataset = as_dataset(real)
    chosen = _as_model(model)
    folder = None if report is None else os.fspath(report)
    text, page = _rollest.diagnose(
        dataset._native, None if chosen is None else chosen._native, folder, holdout_fraction, progress
    )
    return Diagnosis.from_results(
        json.loads(text), folder=None if report is None else Path(report), page=None if page is None else Path(page)
    )


def _column(columns: Any, name: str) -> np.ndarray:
    """One column (of a mapping or a DataFrame) as contiguous float64."""
    try:
        values = columns[name]
    except KeyError:
        raise KeyError(f"run(): expected a column named {name!r}, found none") from None
    # Contiguous and aligned, as the engine reads it in place.
    return np.require(np.asarray(values, dtype=np.float64), requirements=["C_CONTIGUOUS", "ALIGNED"])


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
        self,
        columns: Union[Run, Mapping[str, Any], "pandas.DataFrame"],
        alpha_deg: Optional[float] = None,
        *,
        frame: bool = False,
    ) -> Any:
        """Steps over a whole run: a :class:`Run`, a DataFrame or a mapping of arrays with
        ``phi_deg``, ``cmu_port``, ``cmu_stbd`` and ``cp01`` .. ``cp12``; the angle of attack from
        an ``alpha_deg`` column, the ``alpha_deg`` argument, or both (the column where finite);
        ``cmu_port_cmd``/``cmu_stbd_cmd`` when recorded (noted after each step, as the replay).

        Returns every stage's estimate (float32) and the health fields (uint16), by the replay
        file's names; the same values, bit for bit, as ``host-tools replay``. With ``frame``, a
        DataFrame indexed by the input's ``t_s`` (its index when it is a frame indexed so; else
        ``k * dt_s``), needs pandas.
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
        outputs = dict(
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
        if not frame:
            return outputs
        from .dataset import _pandas

        pd = _pandas()
        if "t_s" in arrays:
            t_s = _column(arrays, "t_s")
        elif isinstance(arrays, pd.DataFrame) and arrays.index.name == "t_s":
            t_s = np.asarray(arrays.index, dtype=np.float64)
        else:
            t_s = np.arange(len(cp)) * self.dt_s
        return pd.DataFrame(outputs, index=pd.Index(t_s, name="t_s"))
