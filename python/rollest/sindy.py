"""PySINDy's STLSQ optimizer on the workspace's SINDy engine.

Sequentially thresholded least squares (STLSQ) is the sparse regression of SINDy (Brunton,
Proctor & Kutz, PNAS 113(15), 2016). Its reference implementation is PySINDy's ``STLSQ``
(de Silva et al., JOSS 5(49), 2020; Kaptanoglu et al., JOSS 7(69), 2022). :class:`STLSQ` here
is a drop-in replacement for it, computed by the ``sindy`` crate::

    import pysindy
    import rollest.sindy

    model = pysindy.SINDy(optimizer=rollest.sindy.STLSQ(threshold=0.1))
    model.fit(x, t=dt)

The crate reproduces PySINDy 2.1.0's iteration, stopping and unbias rules (checked against
PySINDy's own fits by ``tests/tests/sindy.rs`` and ``python/tests/test_sindy.py``), but it
factors each target's ``[Theta | y]`` once and runs every ridge solve on the small triangular
factor, in Rust, without the GIL; ``python/benchmarks/stlsq.py`` measures the difference and
docs/results.md ("SINDy engine against PySINDy") records it.

PySINDy is an optional dependency (``pip install 'rollest[sindy]'``). With it installed,
:class:`STLSQ` is a ``pysindy.optimizers.BaseOptimizer`` (so a scikit-learn estimator, with
``get_params``, ``set_params``, ``predict`` and ``clone``); without it, it is a plain class with
the same constructor, ``fit``, ``predict``, ``get_params`` and ``set_params``, for libraries
built by hand. The class is made on first use (a module ``__getattr__``, PEP 562), so importing
this module does not import PySINDy, which takes about 1.5 s.
"""

from __future__ import annotations

import importlib
import inspect
import types
import warnings
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Tuple, Type, TypeVar

import numpy as np
import numpy.typing as npt

from . import _rollest

__all__ = ["STLSQ"]

Array = npt.NDArray[np.float64]


class _Standalone:
    """What :class:`STLSQ` uses of PySINDy's ``BaseOptimizer`` (and of scikit-learn's
    ``BaseEstimator`` under it), for when PySINDy is not installed."""

    coef_: Array
    intercept_: float

    def __init__(self, max_iter: int = 20, normalize_columns: bool = False, unbias: bool = True) -> None:
        if max_iter <= 0:
            raise ValueError("max_iter must be positive")
        self.max_iter = max_iter
        self.normalize_columns = normalize_columns
        self.unbias = unbias
        self.iters = 0

    @classmethod
    def _param_names(cls) -> List[str]:
        return [name for name in inspect.signature(cls.__init__).parameters if name != "self"]

    def get_params(self, deep: bool = True) -> Dict[str, Any]:
        """The constructor's arguments by name (scikit-learn's contract; ``deep`` changes
        nothing, as this estimator holds no other)."""
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params: Any) -> _Standalone:
        """Sets constructor arguments by name; an unknown name is a ``ValueError``."""
        valid = self._param_names()
        for name, value in params.items():
            if name not in valid:
                raise ValueError(f"invalid parameter {name!r} for {type(self).__name__}: expected one of {valid}")
            setattr(self, name, value)
        return self

    def predict(self, x: npt.ArrayLike) -> Array:
        """The fitted right-hand sides, ``x @ coef_.T`` (n_samples x n_targets)."""
        prediction: Array = np.asarray(x, dtype=np.float64) @ self.coef_.T + self.intercept_
        return prediction

    @property
    def complexity(self) -> int:
        """The number of non-zero coefficients."""
        return int(np.count_nonzero(self.coef_))


def _convergence_warning() -> Type[Warning]:
    """scikit-learn's ``ConvergenceWarning`` (what PySINDy's STLSQ issues) when installed."""
    try:
        exceptions = importlib.import_module("sklearn.exceptions")
    except ImportError:
        return UserWarning
    category: Type[Warning] = exceptions.ConvergenceWarning
    return category


# The type checker sees the standalone base, whose interface PySINDy's is a superset of; at run
# time the implementation is a mixin placed before the base the class is made with.
if TYPE_CHECKING:
    _MixinBase = _Standalone
else:
    _MixinBase = object


_Self = TypeVar("_Self", bound="_Stlsq")


class _Stlsq(_MixinBase):
    """Sequentially thresholded least squares: PySINDy's ``STLSQ`` computed by the ``sindy``
    crate.

    Minimises ``|y - X w|^2 + alpha |w|^2`` by repeated ridge regression, zeroing the
    coefficients of magnitude below ``threshold`` (of the columns divided by their L2 norms
    when ``normalize_columns``) after each solve, until the support no longer changes or
    ``max_iter`` solves have been made; with ``unbias`` the final support is refitted by
    ordinary least squares. The arguments and their defaults are PySINDy 2.1.0's.

    PySINDy's ``ridge_kw``, ``initial_guess``, ``sparse_ind``, ``verbose`` and ``copy_X`` are
    not supported. Where the attributes differ from PySINDy's:

    * ``history_`` holds the final coefficients only: the engine does not keep its iterates;
    * ``iters`` is the number of ridge solves summed over the targets, each target counted
      until its own support settled (PySINDy iterates the targets together, so a target can
      count more solves there; the extra ones repeat a settled solve and change nothing);
    * ``ind_`` is the support of the final coefficients;
    * ``Theta_`` is the library as fitted: weighted, with the left-out samples zeroed.

    Samples in which every library value or every target is NaN are left out, as PySINDy
    leaves them out (the endpoints ``FiniteDifference(drop_endpoints=True)`` leaves); any other
    NaN or infinity is an error naming its row and column.
    """

    threshold: float
    alpha: float
    coef_: Array
    ind_: npt.NDArray[np.bool_]
    history_: List[Array]
    intercept_: float
    iters: int
    Theta_: Array

    def __init__(
        self,
        threshold: float = 0.1,
        alpha: float = 0.05,
        max_iter: int = 20,
        normalize_columns: bool = False,
        unbias: bool = True,
    ) -> None:
        super().__init__(max_iter=max_iter, normalize_columns=normalize_columns, unbias=unbias)
        if threshold < 0:
            raise ValueError("threshold cannot be negative")
        if alpha < 0:
            raise ValueError("alpha cannot be negative")
        self.threshold = threshold
        self.alpha = alpha

    def set_params(self: _Self, **params: Any) -> _Self:
        """Sets constructor arguments by name and returns the estimator, as scikit-learn's
        contract has it (PySINDy 2.1.0's ``BaseOptimizer.set_params`` returns None)."""
        super().set_params(**params)
        return self

    def fit(self: _Self, x_: npt.ArrayLike, y: npt.ArrayLike, sample_weight: Optional[npt.ArrayLike] = None) -> _Self:
        """Fits the coefficients of every column of ``y`` (n_samples or n_samples x n_targets)
        on the library ``x_`` (n_samples x n_features); ``coef_`` is n_targets x n_features.

        ``sample_weight`` (a scalar or one per sample) weights each sample's squared residual,
        as in PySINDy (its rows are scaled by the square root).
        """
        theta, targets = _as_problem(x_, y)
        if sample_weight is not None:
            root = np.sqrt(np.broadcast_to(np.asarray(sample_weight, dtype=np.float64), (theta.shape[0],)))
            theta = theta * root[:, np.newaxis]
            targets = targets * root[:, np.newaxis]
        coef, iterations, converged = _rollest.stlsq(
            np.ascontiguousarray(theta),
            np.ascontiguousarray(targets),
            threshold=self.threshold,
            alpha=self.alpha,
            max_iter=self.max_iter,
            normalize_columns=self.normalize_columns,
            unbias=self.unbias,
        )
        self.Theta_ = theta
        self.iters = sum(iterations)
        self.history_ = [coef]
        self._set_coefficients(coef, converged)
        self.intercept_ = 0.0
        return self

    def _reduce(self, x: Array, y: Array) -> None:
        """The thresholding iterations alone, on the columns ``BaseOptimizer.fit`` has already
        normalised; that ``fit`` then refits the support and rescales. :meth:`fit` does not
        use this: it leaves all of it to the engine."""
        coef, iterations, converged = _rollest.stlsq(
            np.ascontiguousarray(x, dtype=np.float64),
            np.ascontiguousarray(y, dtype=np.float64),
            threshold=self.threshold,
            alpha=self.alpha,
            max_iter=self.max_iter,
            normalize_columns=False,
            unbias=False,
        )
        self.iters += sum(iterations)
        self.history_.append(coef)
        self._set_coefficients(coef, converged)

    def _set_coefficients(self, coef: Array, converged: List[bool]) -> None:
        """Stores the coefficients and warns as PySINDy's STLSQ does."""
        self.coef_ = coef
        self.ind_ = coef != 0.0
        if not all(converged):
            warnings.warn(
                f"STLSQ did not converge after {self.max_iter} iterations.", _convergence_warning(), stacklevel=3
            )
        if not self.ind_.any(axis=1).all():
            warnings.warn(
                f"Sparsity parameter is too big ({self.threshold}) and eliminated all coefficients",
                stacklevel=3,
            )


if TYPE_CHECKING:

    class STLSQ(_Stlsq):
        pass

else:

    def __getattr__(name: str) -> Any:
        """Makes :class:`STLSQ` on first use, on PySINDy's ``BaseOptimizer`` when PySINDy is
        installed, else on :class:`_Standalone`."""
        if name != "STLSQ":
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
        try:
            base = importlib.import_module("pysindy.optimizers").BaseOptimizer
        except ImportError:
            base = _Standalone
        namespace = {"__module__": __name__, "__doc__": _Stlsq.__doc__}
        made = types.new_class("STLSQ", (_Stlsq, base), exec_body=lambda body: body.update(namespace))
        globals()["STLSQ"] = made
        return made


def _as_problem(x: npt.ArrayLike, y: npt.ArrayLike) -> Tuple[Array, Array]:
    """The library and the targets as 2-D float64 arrays, without the samples that are NaN in
    every library value or in every target (PySINDy's ``drop_nan_samples``).

    Those samples are zeroed rather than removed: a zero row adds nothing to any of the least
    squares problems or to the columns' norms, and the row numbers in the engine's errors stay
    those of the caller's arrays. A row count that differs is the engine's error to report.
    """
    theta = np.asarray(x, dtype=np.float64)
    targets = np.asarray(y, dtype=np.float64)
    if targets.ndim == 1:
        targets = targets.reshape(-1, 1)
    for name, array, shape in (("x", theta, "n_samples x n_features"), ("y", targets, "n_samples x n_targets")):
        if array.ndim != 2:
            raise ValueError(f"{name}: expected a 2-D array ({shape}), found shape {array.shape}")
    if theta.shape[0] == targets.shape[0]:
        missing = np.asarray(np.isnan(theta).all(axis=1) | np.isnan(targets).all(axis=1))
        if missing.any():
            theta = np.where(missing[:, np.newaxis], 0.0, theta)
            targets = np.where(missing[:, np.newaxis], 0.0, targets)
    return theta, targets
