"""Type stubs of the extension module ``rollest._rollest`` (python/src/*.rs).

Use the wrappers of the ``rollest`` package; this module is their engine.
"""

from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt
from typing_extensions import final

__all__ = [
    "DEFAULT_HOLDOUT_FRACTION",
    "DatasetError",
    "Dataset",
    "ESTIMATE_COLUMNS",
    "HEALTH_COLUMNS",
    "Estimator",
    "Model",
    "REPLAY_COLUMNS",
    "RollestError",
    "diagnose",
    "evaluate",
    "fit",
    "heldout_start",
    "load_dataset",
    "simulate",
]

_Progress = Callable[[str, int, Optional[int]], object]

REPLAY_COLUMNS: List[str]
ESTIMATE_COLUMNS: List[str]
HEALTH_COLUMNS: List[str]
DEFAULT_HOLDOUT_FRACTION: float

class RollestError(Exception):
    """A rollest call failed; the message names the file, flag or run, and why."""

class DatasetError(RollestError):
    """A dataset could not be read or written."""

    file: Optional[str]
    row: Optional[int]
    column: Optional[str]
    key: Optional[str]

@final
class Dataset:
    @property
    def path(self) -> str: ...
    def __len__(self) -> int: ...
    def manifest_json(self) -> str: ...
    def run_arrays(self, index: int) -> Dict[str, npt.NDArray[np.float64]]: ...

@final
class Model:
    @staticmethod
    def load(path: str) -> Model: ...
    @staticmethod
    def built_in() -> Model: ...
    @property
    def source(self) -> str: ...
    @property
    def path(self) -> Optional[str]: ...
    @property
    def dt_s(self) -> float: ...
    def save(self, path: str) -> None: ...
    def coefficients_json(self) -> str: ...
    def card(self) -> Optional[str]: ...
    def model_json(self) -> Optional[str]: ...
    def blob(self) -> bytes: ...
    def replay(
        self, dataset: Dataset, faults: Sequence[str] = ..., fault_seed: int = ...
    ) -> List[Dict[str, np.ndarray]]: ...

@final
class Estimator:
    def __new__(cls, model: Optional[Model] = ...) -> Estimator: ...
    @property
    def dt_s(self) -> float: ...
    def reset(self) -> None: ...
    def note_demand(self, cmu_port: float, cmu_stbd: float) -> None: ...
    def step(
        self,
        phi_deg: float,
        alpha_deg: float,
        cmu_port: float,
        cmu_stbd: float,
        cp: Sequence[float],
        demand: Optional[Tuple[float, float]] = ...,
    ) -> Dict[str, float]: ...
    def run(
        self,
        phi_deg: npt.NDArray[np.float64],
        alpha_deg: npt.NDArray[np.float64],
        cmu_port: npt.NDArray[np.float64],
        cmu_stbd: npt.NDArray[np.float64],
        cp: npt.NDArray[np.float64],
        cmu_port_cmd: Optional[npt.NDArray[np.float64]] = ...,
        cmu_stbd_cmd: Optional[npt.NDArray[np.float64]] = ...,
    ) -> Dict[str, np.ndarray]: ...

def load_dataset(path: str) -> Dataset: ...
def heldout_start(n_samples: int, holdout_fraction: float) -> int: ...
def simulate(
    out: str,
    scenario: Optional[str] = ...,
    seed: Optional[int] = ...,
    duration_s: Optional[float] = ...,
    effects: Sequence[str] = ...,
    progress: Optional[_Progress] = ...,
) -> int: ...
def fit(
    data: str, out: str, seed: int = ..., holdout_fraction: float = ..., progress: Optional[_Progress] = ...
) -> Model: ...
def evaluate(
    data: str,
    report: str,
    model: Optional[str] = ...,
    seed: int = ...,
    holdout_fraction: float = ...,
    progress: Optional[_Progress] = ...,
) -> Tuple[str, List[str]]: ...
def diagnose(
    real: str,
    report: str,
    model: Optional[str] = ...,
    holdout_fraction: float = ...,
    progress: Optional[_Progress] = ...,
) -> str: ...
