"""Blind validation campaigns of the diagnosis over any :class:`concurrent.futures.Executor`
(:mod:`rollest.executors`): local processes on every core by default, or a cluster's (Dask
``distributed``: ``Client(...).get_executor()``; Ray's ``ray.util.multiprocessing.Pool``
through an executor adapter).

The coordinating process draws each case (this project's tunnel) or reads each case's recording
(a campaign written by another program), and sends the workers only the blind recording and the
model; the truths stay sealed in the coordinating process, and are read and scored only once
every diagnosis is back, with the command line's rules and report (``host-tools
validate-diagnosis``). A campaign that gives per-effect rates to within a few per cent needs
thousands of cases; one machine diagnoses about ten a minute.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, Iterator, List, Optional, Sequence, Tuple

from . import _rollest
from .dataset import Dataset, PathLike, load_dataset
from .executors import CampaignProgress, default_in_flight, local_executor, run_bounded

if TYPE_CHECKING:  # pragma: no cover
    import pandas

    from . import Model

@dataclass(frozen=True)
class Validation:
    """A scored campaign: ``results`` is ``validation.json`` as a dict (``summary`` with the
    acceptance figures, ``cases`` with every case's truth and diagnosis); the report folder and
    its page when one was written."""

    results: Dict[str, Any] = field(repr=False)
    folder: Optional[Path] = None
    page: Optional[Path] = None

    @property
    def summary(self) -> Dict[str, Any]:
        """The acceptance figures (as in the report's first table)."""
        summary: Dict[str, Any] = self.results["summary"]
        return summary

    def cases(self) -> "pandas.DataFrame":
        """Every case, one row each, indexed by its id (needs pandas)."""
        from .dataset import _pandas

        frame: "pandas.DataFrame" = _pandas().DataFrame(self.results["cases"]).set_index("id")
        return frame

    def _repr_html_(self) -> str:
        """A notebook shows how many cases were right, by class."""
        try:
            table = self.cases().groupby("class")["correct"].agg(["sum", "count"])
            body = table.to_html()
        except ImportError:  # pragma: no cover - without pandas
            body = ""
        right = sum(1 for case in self.results["cases"] if case["correct"])
        return f"<div><p><b>Blind validation</b>: {right} of {len(self.results['cases'])} cases right</p>{body}</div>"


def diagnose_case(dataset: Dataset, model: "Model") -> Tuple[str, float]:
    """What a worker runs: the diagnosis of one blind recording against its model, as
    ``diagnosis.json`` text, and the seconds it took. Only the recording and the model reach it."""
    started = time.perf_counter()
    text, _ = _rollest.diagnose(dataset._native, model._native, None, _rollest.DEFAULT_HOLDOUT_FRACTION, None)
    return text, time.perf_counter() - started


def validate_diagnosis(
    campaign: Optional[PathLike] = None,
    *,
    cases: int = 140,
    seed: int = 1,
    duration_s: float = 30.0,
    classes: Sequence[str] = (),
    only: Sequence[int] = (),
    executor: Optional[Executor] = None,
    report: Optional[PathLike] = None,
    max_in_flight: Optional[int] = None,
    progress: Optional[CampaignProgress] = None,
) -> Validation:
    """A blind validation campaign of the diagnosis (``host-tools validate-diagnosis``), its
    cases diagnosed over ``executor``.

    With ``campaign``, the folder of a campaign another program wrote (its clean recording is
    fitted here); else this project's tunnel: ``cases`` cases of ``duration_s`` s runs from the
    master ``seed`` (only ``classes`` and the case ids ``only`` when given), each drawn here as
    the command line draws it.

    ``executor`` runs :func:`diagnose_case` on each blind recording and its model; by default
    :func:`local_executor` (every core; shut down on return). Any
    :class:`concurrent.futures.Executor` serves: a Dask cluster's
    ``distributed.Client(...).get_executor()`` is used as given and left open. At most
    ``max_in_flight`` cases (twice the cores when None) are out at once, so the coordinating
    process holds only those recordings. The truths stay here until every diagnosis is back;
    then every case is scored, and with ``report`` the report folder is written.
    """
    own = executor is None
    pool: Executor = local_executor() if executor is None else executor
    in_flight = default_in_flight(max_in_flight)
    started = time.perf_counter()
    try:
        if campaign is not None:
            foreign = _rollest.ForeignCampaign(os.fspath(campaign))
            from . import Model

            model = Model(foreign.fit())
            listed = foreign.cases()
            work: Iterator[Tuple[int, Dataset, "Model"]] = ((id, load_dataset(path), model) for id, path in listed)
            diagnoses = _diagnose_all(pool, work, len(listed), in_flight, progress)
            described = (
                f"{len(listed)} cases of the campaign {os.fspath(campaign)} (master seed {foreign.seed}), written by "
                f"another program, diagnosed over {type(pool).__name__}; took {time.perf_counter() - started:.0f} s."
            )
            text, page = foreign.score(diagnoses, described, None if report is None else os.fspath(report))
        else:
            blind = _rollest.BlindCampaign(cases, seed, duration_s, list(classes), list(only))
            ids = blind.ids()
            diagnoses = _diagnose_all(pool, _drawn(blind, ids, in_flight), len(ids), in_flight, progress)
            described = (
                f"{len(diagnoses)} cases, master seed {seed}, runs of {duration_s} s at one angle of attack each "
                f"(roll, actuation, roll+actuation), diagnosed over {type(pool).__name__}; took "
                f"{time.perf_counter() - started:.0f} s."
            )
            text, page = blind.score(diagnoses, described, None if report is None else os.fspath(report))
    finally:
        if own:
            pool.shutdown()
    return Validation(
        results=json.loads(text),
        folder=None if report is None else Path(report),
        page=None if page is None else Path(page),
    )


def _drawn(blind: _rollest.BlindCampaign, ids: List[int], batch: int) -> Iterator[Tuple[int, Dataset, "Model"]]:
    """The campaign's cases, drawn a batch at a time (in parallel in the engine)."""
    from . import Model

    for start in range(0, len(ids), batch):
        for id, native_data, native_model in blind.draw(ids[start : start + batch]):
            yield id, Dataset(native_data), Model(native_model)


def _diagnose_all(
    pool: Executor,
    work: Iterator[Tuple[int, Dataset, "Model"]],
    total: int,
    in_flight: int,
    progress: Optional[CampaignProgress],
) -> List[Tuple[int, str, float]]:
    """Every case's diagnosis (id, ``diagnosis.json`` text, seconds), at most ``in_flight`` out."""
    units = ((id, diagnose_case, (dataset, model)) for id, dataset, model in work)
    return [(id, text, seconds) for id, (text, seconds) in run_bounded(pool, units, total, in_flight, progress)]
