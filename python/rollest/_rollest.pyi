"""Type stubs of the extension module ``rollest._rollest`` (python/src/*.rs).

Use the wrappers of the ``rollest`` package; this module is their engine.
"""

from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt
from typing_extensions import final

__all__ = [
    "BlindCampaign",
    "DEFAULT_HOLDOUT_FRACTION",
    "ForeignCampaign",
    "__version__",
    "DatasetError",
    "Dataset",
    "ESTIMATE_COLUMNS",
    "HEALTH_COLUMNS",
    "Estimator",
    "Model",
    "REPLAY_COLUMNS",
    "RollestError",
    "dataset_from_parts",
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
__version__: str

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
    def path(self) -> Optional[str]: ...
    def __len__(self) -> int: ...
    def write(self, path: str) -> None: ...
    def manifest_json(self) -> str: ...
    def run_arrays(self, index: int) -> Dict[str, npt.NDArray[np.float64]]: ...

@final
class Model:
    @staticmethod
    def load(path: str) -> Model: ...
    @staticmethod
    def built_in() -> Model: ...
    @staticmethod
    def from_files(source: str, files: Sequence[Tuple[str, bytes]], path: Optional[str] = ...) -> Model: ...
    def files(self) -> List[Tuple[str, bytes]]: ...
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

_Diagnoses = Sequence[Tuple[int, str, float]]

@final
class BlindCampaign:
    def __new__(
        cls,
        cases: int = ...,
        seed: int = ...,
        duration_s: float = ...,
        classes: Sequence[str] = ...,
        only: Sequence[int] = ...,
    ) -> BlindCampaign: ...
    def ids(self) -> List[int]: ...
    def draw(self, ids: Sequence[int]) -> List[Tuple[int, Dataset, Model]]: ...
    def score(
        self, diagnoses: _Diagnoses, described: str, report: Optional[str] = ...
    ) -> Tuple[str, Optional[str]]: ...

@final
class ForeignCampaign:
    def __new__(cls, dir: str) -> ForeignCampaign: ...
    @property
    def seed(self) -> int: ...
    def fit(self) -> Model: ...
    def cases(self) -> List[Tuple[int, str]]: ...
    def score(
        self, diagnoses: _Diagnoses, described: str, report: Optional[str] = ...
    ) -> Tuple[str, Optional[str]]: ...

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
def dataset_from_parts(
    metadata_json: str, runs: Sequence[Sequence[Tuple[str, npt.NDArray[np.float64]]]]
) -> Dataset: ...
def fit(
    dataset: Dataset,
    out: Optional[str] = ...,
    seed: int = ...,
    holdout_fraction: float = ...,
    progress: Optional[_Progress] = ...,
) -> Model: ...
def evaluate(
    dataset: Dataset,
    model: Optional[Model] = ...,
    report: Optional[str] = ...,
    seed: int = ...,
    holdout_fraction: float = ...,
    progress: Optional[_Progress] = ...,
) -> Tuple[str, Optional[str], List[str]]: ...
def diagnose(
    dataset: Dataset,
    model: Optional[Model] = ...,
    report: Optional[str] = ...,
    holdout_fraction: float = ...,
    progress: Optional[_Progress] = ...,
) -> Tuple[str, Optional[str]]: ...

# python/src/sil.rs: one scenario in closed loop (rollest.sil and rollest.sil_sweep wrap it).
__all__ += ["sil"]

def sil(
    model: Optional[Model] = ...,
    scenario_toml: Optional[str] = ...,
    scenario_name: Optional[str] = ...,
    seed: Optional[int] = ...,
    duration_s: Optional[float] = ...,
    effects: List[str] = ...,
    faults: List[str] = ...,
    tune: bool = ...,
    tune_seed: Optional[int] = ...,
    causality_tau_s: Optional[float] = ...,
    kp: Optional[float] = ...,
    ki: Optional[float] = ...,
    progress: Optional[_Progress] = ...,
) -> str: ...

# python/src/sindy.rs: PySINDy's STLSQ on the SINDy engine (rollest.sindy.STLSQ wraps it).
__all__ += ["stlsq"]

def stlsq(
    theta: npt.NDArray[np.float64],
    y: npt.NDArray[np.float64],
    *,
    threshold: float,
    alpha: float,
    max_iter: int,
    normalize_columns: bool,
    unbias: bool,
) -> Tuple[npt.NDArray[np.float64], List[int], List[bool]]: ...
