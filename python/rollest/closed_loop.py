"""The controller in closed loop with the synthetic tunnel (``host-tools sil``), one scenario in
process (:func:`sil`) or a sweep over many (:func:`sil_sweep`) spread over any
:class:`concurrent.futures.Executor` (:mod:`rollest.executors`): local processes on every core
by default, or a Dask or Ray cluster.

Each scenario is a :class:`SilPoint`: the command line's flags (scenario file, seed, duration,
effects, faults, gains). Its scenario file is read in the coordinating process and sent as text,
so a worker on another machine needs no file; each worker runs every controller mode at every
angle of attack of its scenario, seeded as ``host-tools sil`` runs it, so a sweep gives the
same numbers wherever it runs and whatever the order.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from . import _rollest
from .dataset import PathLike
from .executors import CampaignProgress, default_in_flight, local_executor, run_bounded

if TYPE_CHECKING:  # pragma: no cover
    import pandas

    from . import Model, Progress

#: The controller modes every scenario runs, in the record's order.
MODES: Tuple[str, ...] = ("none", "feedback", "feedforward", "ff_fb_linear", "ff_fb_coupled")

#: The metrics of a run a table keeps (``sil.json``'s ``metrics``; the per-jet ones left out).
_METRICS = (
    "rms_cl",
    "peak_cl",
    "rms_cl_balance",
    "max_cmu_cmd",
    "min_cmu_cmd",
    "saturated_fraction",
    "rms_disturbance_error",
    "n_samples",
)


@dataclass(frozen=True)
class SilPoint:
    """One scenario of a sweep, as ``host-tools sil``'s flags: ``scenario`` is a scenario TOML
    file (the paper's campaign at 20 s per run when None); ``seed``, ``duration_s`` and
    ``effects`` override it; ``faults`` are injected into every run (``dead:cp03@5s``);
    ``tune`` searches the gains on ``tune_seed`` first; ``causality_tau_s``, ``kp`` and ``ki``
    override the gains. ``label`` names the point in tables."""

    scenario: Optional[PathLike] = None
    seed: Optional[int] = None
    duration_s: Optional[float] = None
    effects: Sequence[str] = ()
    faults: Sequence[str] = ()
    tune: bool = False
    tune_seed: Optional[int] = None
    causality_tau_s: Optional[float] = None
    kp: Optional[float] = None
    ki: Optional[float] = None
    label: Optional[str] = None

    def flags(self) -> Dict[str, Any]:
        """The keyword arguments of the engine's call, the scenario file read here."""
        text = name = None
        if self.scenario is not None:
            name = os.fspath(self.scenario)
            text = Path(self.scenario).read_text(encoding="utf-8")
        return {
            "scenario_toml": text,
            "scenario_name": name,
            "seed": self.seed,
            "duration_s": self.duration_s,
            "effects": list(self.effects),
            "faults": list(self.faults),
            "tune": self.tune,
            "tune_seed": self.tune_seed,
            "causality_tau_s": self.causality_tau_s,
            "kp": self.kp,
            "ki": self.ki,
        }


@dataclass(frozen=True)
class SilResult:
    """One scenario in closed loop: ``record`` is ``sil.json`` as a dict (``results`` with
    every run's metrics, ``rms_reduction`` per alpha, ``tuning`` when the gains were searched)."""

    record: Dict[str, Any] = field(repr=False)

    @property
    def seed(self) -> int:
        """The master seed of the roll command and the noise."""
        seed: int = self.record["results"]["seed"]
        return seed

    def reduction(self, alpha_deg: float, mode: str) -> Optional[float]:
        """``1 - rms(mode) / rms(none)`` at ``alpha_deg`` (None when not defined)."""
        for row in self.record["rms_reduction"]:
            if row["alpha_deg"] == alpha_deg:
                value: Optional[float] = row[mode]
                return value
        raise KeyError(f"no run at alpha {alpha_deg} deg")

    def rows(self) -> List[Dict[str, Any]]:
        """Every run: alpha, mode, the metrics and the reduction against no control."""
        rows = []
        for run in self.record["results"]["runs"]:
            metrics = run["metrics"]
            row = {"alpha_deg": metrics["alpha_deg"], "mode": metrics["mode"]}
            row.update({name: metrics[name] for name in _METRICS})
            row["reduction"] = self.reduction(metrics["alpha_deg"], metrics["mode"])
            rows.append(row)
        return rows

    def frame(self) -> "pandas.DataFrame":
        """Every run, indexed by alpha and mode (needs pandas)."""
        from .dataset import _pandas

        frame: "pandas.DataFrame" = _pandas().DataFrame(self.rows()).set_index(["alpha_deg", "mode"])
        return frame

    def _repr_html_(self) -> str:
        """A notebook shows the RMS reduction per alpha and mode."""
        try:
            from .dataset import _pandas

            table = _pandas().DataFrame(self.record["rms_reduction"]).set_index("alpha_deg")[list(MODES)]
            body = table.to_html(float_format=lambda value: f"{value:.3g}", na_rep="")
        except ImportError:  # pragma: no cover - without pandas
            body = f"<pre>{json.dumps(self.record['rms_reduction'], indent=1)}</pre>"
        return (
            f"<div><p><b>SIL</b>, seed {self.seed}: {self.record['scenario']}; RMS reduction of C_l against no "
            f"control</p>{body}</div>"
        )


def sil(model: Optional["Model"] = None, point: Optional[SilPoint] = None, progress: Optional["Progress"] = None) -> SilResult:
    """One scenario (``point``; the paper's campaign at 20 s per run when None) in closed loop
    with ``model`` (the built-in tables when None), in this process, its runs over the engine's
    threads: what ``host-tools sil`` computes, without the report folder."""
    point = point or SilPoint()
    native = None if model is None else model._native
    return SilResult(json.loads(_rollest.sil(native, progress=progress, **point.flags())))


def run_point(model: Optional["Model"], flags: Mapping[str, Any]) -> Tuple[str, float]:
    """What a worker runs: one scenario's ``sil.json`` text, and the seconds it took."""
    started = time.perf_counter()
    native = None if model is None else model._native
    text = _rollest.sil(native, **flags)
    return text, time.perf_counter() - started


@dataclass(frozen=True)
class SilSweep:
    """A sweep: every point, its result, and the seconds each took on its worker."""

    points: Tuple[SilPoint, ...]
    results: Tuple[SilResult, ...] = field(repr=False)
    seconds: Tuple[float, ...] = field(repr=False)

    def rows(self) -> List[Dict[str, Any]]:
        """Every run of every point: the point's index, label and seed, then the run's row."""
        rows = []
        for index, (point, result) in enumerate(zip(self.points, self.results)):
            for row in result.rows():
                rows.append({"point": index, "label": point.label, "seed": result.seed, **row})
        return rows

    def frame(self) -> "pandas.DataFrame":
        """Every run of every point, indexed by point, alpha and mode (needs pandas)."""
        from .dataset import _pandas

        frame: "pandas.DataFrame" = _pandas().DataFrame(self.rows()).set_index(["point", "alpha_deg", "mode"])
        return frame

    def _repr_html_(self) -> str:
        """A notebook shows the coupled controller's reduction per point and alpha."""
        try:
            table = self.frame().xs("ff_fb_coupled", level="mode")[["label", "rms_cl", "reduction"]]
            body = table.to_html(float_format=lambda value: f"{value:.4g}")
        except ImportError:  # pragma: no cover - without pandas
            body = ""
        return f"<div><p><b>SIL sweep</b>: {len(self.points)} scenarios</p>{body}</div>"


def sil_sweep(
    points: Iterable[Union[SilPoint, Mapping[str, Any]]],
    model: Optional["Model"] = None,
    *,
    executor: Optional[Executor] = None,
    max_in_flight: Optional[int] = None,
    progress: Optional[CampaignProgress] = None,
) -> SilSweep:
    """Every scenario of ``points`` (:class:`SilPoint` or its keyword arguments) in closed loop
    with ``model`` (the built-in tables when None), one scenario per unit of work over
    ``executor``: by default :func:`~rollest.executors.local_executor` (every core; shut down on
    return); any :class:`concurrent.futures.Executor` serves, a Dask cluster's
    ``distributed.Client(...).get_executor()`` among them (used as given and left open). At most
    ``max_in_flight`` scenarios (twice the cores when None) are out at once. ``progress(done,
    total)`` is called here as each comes back."""
    chosen = tuple(point if isinstance(point, SilPoint) else SilPoint(**point) for point in points)
    own = executor is None
    pool: Executor = local_executor() if executor is None else executor
    try:
        units = ((index, run_point, (model, point.flags())) for index, point in enumerate(chosen))
        done = run_bounded(pool, units, len(chosen), default_in_flight(max_in_flight), progress)
    finally:
        if own:
            pool.shutdown()
    return SilSweep(
        points=chosen,
        results=tuple(SilResult(json.loads(text)) for _, (text, _) in done),
        seconds=tuple(seconds for _, (_, seconds) in done),
    )
