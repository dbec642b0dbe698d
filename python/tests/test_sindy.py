"""rollest.sindy.STLSQ against PySINDy's own STLSQ inside ``pysindy.SINDy``, on PySINDy's
example systems (de Silva et al., JOSS 5(49), 2020; Kaptanoglu et al., JOSS 7(69), 2022): the
Lorenz system with measurement noise, the linear and the cubic damped oscillators and the Van
der Pol oscillator; and its errors on bad input.

Tests that compare with PySINDy skip without it (``pip install 'rollest[sindy]'``); the rest
need only the package.
"""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from functools import lru_cache
from types import ModuleType
from typing import Any, Callable, Dict, List, Sequence, Tuple

import numpy as np
import numpy.typing as npt
import pytest

import rollest
import rollest.sindy
from rollest import _rollest

Array = npt.NDArray[np.float64]

#: Largest coefficient difference allowed, relative to each target's largest coefficient. Both
#: sides solve the same least-squares problems with backward-stable methods (PySINDy: LAPACK's
#: SVD and a Cholesky ridge solve; the engine: Householder QR), so they may disagree by about
#: cond(Theta) * eps: 1.6e-10 for the worst-conditioned library below (Lorenz, degree 3,
#: cond 7.1e5). Measured on these cases: at most 3.0e-13.
RELATIVE_TOLERANCE = 1e-10

#: The seed of the measurement noise.
SEED = 20240611


@pytest.fixture(scope="module")
def pysindy() -> ModuleType:
    module: ModuleType = pytest.importorskip("pysindy")
    return module


def integrate(rhs: Callable[[float, Array], Sequence[float]], x0: Sequence[float], dt_s: float, t_end_s: float) -> Array:
    """A trajectory sampled every ``dt_s`` (SciPy's LSODA at 1e-12 tolerances, as PySINDy's
    examples integrate)."""
    from scipy.integrate import solve_ivp  # type: ignore[import-untyped]

    t_s = np.arange(0.0, t_end_s, dt_s)
    solution = solve_ivp(rhs, (t_s[0], t_s[-1]), x0, t_eval=t_s, rtol=1e-12, atol=1e-12, method="LSODA")
    trajectory: Array = solution.y.T
    return trajectory


def lorenz(_t: float, z: Array) -> List[float]:
    return [10.0 * (z[1] - z[0]), z[0] * (28.0 - z[2]) - z[1], z[0] * z[1] - 8.0 / 3.0 * z[2]]


def linear_oscillator(_t: float, z: Array) -> List[float]:
    return [-0.1 * z[0] + 2.0 * z[1], -2.0 * z[0] - 0.1 * z[1]]


def cubic_oscillator(_t: float, z: Array) -> List[float]:
    return [-0.1 * z[0] ** 3 + 2.0 * z[1] ** 3, -2.0 * z[0] ** 3 - 0.1 * z[1] ** 3]


def van_der_pol(_t: float, z: Array) -> List[float]:
    return [z[1], (1.0 - z[0] ** 2) * z[1] - z[0]]


@lru_cache(maxsize=None)
def system(name: str) -> Tuple[Array, float]:
    """A system's trajectory and its sample interval, s. Lorenz carries Gaussian noise of 1 % of
    each state's standard deviation (seeded)."""
    if name == "lorenz":
        x = integrate(lorenz, [-8.0, 8.0, 27.0], 0.002, 10.0)
        noise = np.random.default_rng(SEED).standard_normal(x.shape)
        return x + 0.01 * np.std(x, axis=0) * noise, 0.002
    rhs = {"linear": linear_oscillator, "cubic": cubic_oscillator, "van_der_pol": van_der_pol}[name]
    return integrate(rhs, [2.0, 0.0], 0.01, 25.0), 0.01


#: (system, library degree, STLSQ arguments, number of non-zero coefficients PySINDy finds).
CASES: List[Tuple[str, int, Dict[str, Any], int]] = [
    ("lorenz", 2, dict(threshold=0.5), 7),
    ("lorenz", 2, dict(threshold=0.5, unbias=False), 7),
    ("lorenz", 2, dict(threshold=400.0, normalize_columns=True), 14),
    ("lorenz", 2, dict(threshold=400.0, normalize_columns=True, unbias=False), 14),
    ("lorenz", 3, dict(threshold=0.1), 8),
    # One ridge solve only: the support is still shrinking (a ConvergenceWarning on both sides).
    ("lorenz", 3, dict(threshold=0.1, max_iter=1), 23),
    ("linear", 5, dict(threshold=0.05), 4),
    ("cubic", 5, dict(threshold=0.05, alpha=0.0), 4),
    ("van_der_pol", 3, dict(threshold=0.1), 4),
]


def fit_both(
    pysindy: ModuleType, name: str, degree: int, arguments: Dict[str, Any], **fit: Any
) -> Tuple[Array, Array, List[type], List[type]]:
    """PySINDy's and rollest's STLSQ in ``pysindy.SINDy`` on one system: both coefficient
    arrays and the warning categories each raised."""
    x, dt_s = system(name)
    results = []
    for optimizer in (pysindy.STLSQ(**arguments), rollest.sindy.STLSQ(**arguments)):
        model = pysindy.SINDy(optimizer=optimizer, feature_library=pysindy.PolynomialLibrary(degree=degree), **fit)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.fit(x, t=dt_s)
        results.append((np.asarray(model.coefficients()), [warning.category for warning in caught]))
    (theirs, their_warnings), (ours, our_warnings) = results
    return theirs, ours, their_warnings, our_warnings


def relative_difference(ours: Array, theirs: Array) -> float:
    """The largest coefficient difference of each target over its largest |coefficient|
    (absolute for a target fitted as all zero)."""
    scale = np.abs(theirs).max(axis=1)
    return float((np.abs(ours - theirs).max(axis=1) / np.where(scale > 0.0, scale, 1.0)).max())


@pytest.mark.parametrize("name, degree, arguments, n_terms", CASES)
def test_sindy_finds_pysindys_support_and_coefficients(
    pysindy: ModuleType, name: str, degree: int, arguments: Dict[str, Any], n_terms: int
) -> None:
    theirs, ours, their_warnings, our_warnings = fit_both(pysindy, name, degree, arguments)
    # The case is what it is meant to be: a sparse model, neither empty nor the whole library.
    assert np.count_nonzero(theirs) == n_terms
    np.testing.assert_array_equal(ours != 0.0, theirs != 0.0)
    difference = relative_difference(ours, theirs)
    print(f"{name} degree {degree} {arguments}: max relative difference {difference:.2e}")
    assert difference <= RELATIVE_TOLERANCE
    assert set(our_warnings) == set(their_warnings)


def test_samples_pysindy_leaves_out_are_left_out(pysindy: ModuleType) -> None:
    # FiniteDifference(drop_endpoints=True) gives NaN derivatives at both ends of the trajectory.
    differentiation = pysindy.FiniteDifference(drop_endpoints=True)
    theirs, ours, _, _ = fit_both(
        pysindy, "lorenz", 2, dict(threshold=0.5), differentiation_method=differentiation
    )
    assert np.count_nonzero(theirs) == 7
    np.testing.assert_array_equal(ours != 0.0, theirs != 0.0)
    assert relative_difference(ours, theirs) <= RELATIVE_TOLERANCE


def lorenz_problem(pysindy: ModuleType) -> Tuple[Array, Array]:
    """The noisy Lorenz system's degree-2 library and its derivatives (central differences)."""
    x, dt_s = system("lorenz")
    theta = np.asarray(pysindy.PolynomialLibrary(degree=2).fit_transform(x))
    x_dot: Array = np.gradient(x, dt_s, axis=0)
    return theta, x_dot


def test_sample_weights_weigh_as_in_pysindy(pysindy: ModuleType) -> None:
    theta, x_dot = lorenz_problem(pysindy)
    weights = np.random.default_rng(SEED).uniform(0.1, 2.0, size=theta.shape[0])
    theirs = pysindy.STLSQ(threshold=0.5).fit(theta, x_dot, sample_weight=weights).coef_
    ours = rollest.sindy.STLSQ(threshold=0.5).fit(theta, x_dot, sample_weight=weights).coef_
    unweighted = rollest.sindy.STLSQ(threshold=0.5).fit(theta, x_dot).coef_
    assert relative_difference(unweighted, theirs) > 1e-6, "the weights change the fit"
    np.testing.assert_array_equal(ours != 0.0, theirs != 0.0)
    assert relative_difference(ours, theirs) <= RELATIVE_TOLERANCE


def test_pysindys_base_fit_through_the_reduce_hook_gives_the_same_model(pysindy: ModuleType) -> None:
    # BaseOptimizer.fit normalises, calls _reduce, refits the support and rescales in Python;
    # STLSQ.fit leaves all of it to the engine.
    theta, x_dot = lorenz_problem(pysindy)
    cases: List[Dict[str, Any]] = [dict(threshold=0.5), dict(threshold=400.0, normalize_columns=True, unbias=False)]
    for arguments in cases:
        whole = rollest.sindy.STLSQ(**arguments).fit(theta, x_dot)
        hooked = rollest.sindy.STLSQ(**arguments)
        pysindy.optimizers.BaseOptimizer.fit(hooked, theta, x_dot)
        assert len(hooked.history_) == 2, "the least-squares guess and the reduced coefficients"
        np.testing.assert_array_equal(hooked.coef_ != 0.0, whole.coef_ != 0.0)
        assert relative_difference(hooked.coef_, whole.coef_) <= RELATIVE_TOLERANCE


def test_is_a_scikit_learn_estimator_with_pysindys_defaults(pysindy: ModuleType) -> None:
    from sklearn.base import clone  # type: ignore[import-untyped]

    ours = rollest.sindy.STLSQ()
    assert isinstance(ours, pysindy.optimizers.BaseOptimizer)
    defaults = ours.get_params()
    assert defaults == {name: pysindy.STLSQ().get_params()[name] for name in defaults}
    copy = clone(ours.set_params(threshold=0.25, max_iter=7))
    assert copy.get_params() == dict(defaults, threshold=0.25, max_iter=7)
    theta, x_dot = lorenz_problem(pysindy)
    fitted = copy.fit(theta, x_dot)
    np.testing.assert_allclose(fitted.predict(theta), theta @ fitted.coef_.T)
    assert fitted.complexity == np.count_nonzero(fitted.coef_)


def test_without_pysindy_the_optimizer_still_fits() -> None:
    # A fresh interpreter in which importing pysindy or scikit-learn fails.
    program = """
import json
import sys
sys.modules["pysindy"] = None
sys.modules["sklearn"] = None
import numpy as np
import rollest.sindy
assert [base.__name__ for base in rollest.sindy.STLSQ.__mro__] == ["STLSQ", "_Stlsq", "_Standalone", "object"]
rng = np.random.default_rng(1)
theta = rng.standard_normal((200, 4))
y = theta @ np.array([[1.5, 0.0, -0.7, 0.0]]).T + 1e-3 * rng.standard_normal((200, 1))
optimizer = rollest.sindy.STLSQ(threshold=0.1).set_params(max_iter=5)
assert optimizer.get_params() == dict(threshold=0.1, alpha=0.05, max_iter=5, normalize_columns=False, unbias=True)
print(json.dumps(optimizer.fit(theta, y).coef_.tolist()))
"""
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    coef = np.array(json.loads(done.stdout))
    np.testing.assert_array_equal(coef != 0.0, [[True, False, True, False]])
    np.testing.assert_allclose(coef[0, [0, 2]], [1.5, -0.7], atol=1e-3)


def test_importing_the_module_leaves_pysindy_unimported_until_stlsq_is_used(pysindy: ModuleType) -> None:
    program = """
import sys
import rollest.sindy
assert "pysindy" not in sys.modules
from rollest.sindy import STLSQ
assert "pysindy" in sys.modules
import pickle
import pysindy
assert isinstance(STLSQ(), pysindy.optimizers.BaseOptimizer) and rollest.sindy.STLSQ is STLSQ
assert type(pickle.loads(pickle.dumps(STLSQ(threshold=0.3)))) is STLSQ
"""
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_rows_that_disagree_are_an_error_naming_both_counts() -> None:
    with pytest.raises(rollest.RollestError, match=r"y has 9 rows and theta 10: expected one row of y per sample"):
        rollest.sindy.STLSQ().fit(np.ones((10, 3)), np.ones((9, 2)))


def test_a_nan_inside_the_data_is_an_error_naming_its_row_and_column() -> None:
    rng = np.random.default_rng(2)
    theta, y = rng.standard_normal((50, 4)), rng.standard_normal((50, 2))
    theta[17, 2] = np.nan
    with pytest.raises(rollest.RollestError, match=r"theta has the value NaN at row 17, column 2: expected finite"):
        rollest.sindy.STLSQ().fit(theta, y)
    theta[17, 2] = 0.0
    y[3, 1] = np.inf
    with pytest.raises(rollest.RollestError, match=r"y has the value inf at row 3, column 1: expected finite"):
        rollest.sindy.STLSQ().fit(theta, y)


def test_bad_arguments_are_errors_naming_what_was_expected() -> None:
    with pytest.raises(ValueError, match="threshold cannot be negative"):
        rollest.sindy.STLSQ(threshold=-1.0)
    with pytest.raises(ValueError, match="max_iter must be positive"):
        rollest.sindy.STLSQ(max_iter=0)
    with pytest.raises(ValueError, match=r"x: expected a 2-D array \(n_samples x n_features\), found shape \(5,\)"):
        rollest.sindy.STLSQ().fit(np.ones(5), np.ones(5))
    theta = np.ones((6, 4))
    with pytest.raises(rollest.RollestError, match="theta: expected a C-contiguous float64 array"):
        _rollest.stlsq(
            theta[:, ::2], np.ones((6, 1)), threshold=0.1, alpha=0.05, max_iter=20, normalize_columns=False, unbias=True
        )
    with pytest.raises(rollest.RollestError, match="max_iter must be a positive integer, found -3"):
        _rollest.stlsq(theta, np.ones((6, 1)), threshold=0.1, alpha=0.05, max_iter=-3, normalize_columns=False, unbias=True)
    with pytest.raises(rollest.RollestError, match="invalid configuration: alpha must be finite and non-negative"):
        _rollest.stlsq(
            theta, np.ones((6, 1)), threshold=0.1, alpha=np.nan, max_iter=20, normalize_columns=False, unbias=True
        )
