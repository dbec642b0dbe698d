"""PySINDy's STLSQ against rollest's (the workspace's SINDy engine), side by side in one run.

    target/python-venv/bin/python python/benchmarks/stlsq.py [--repeat 5]

Prints one Markdown table (median wall time of --repeat fits, this machine): both optimizers'
``fit(Theta, x_dot)`` on polynomial libraries of a Lorenz trajectory (noise-free, derivatives by
central differences; with the 1 % noise of python/tests/test_sindy.py, the derivatives' noise
over 400 s hides whole equations from both) at several numbers of samples and library degrees, with the same arguments (``threshold=0.5``, PySINDy's defaults
otherwise: ``alpha=0.05``, ``max_iter=20``, ``unbias=True``); then the whole ``pysindy.SINDy.fit``
(library, derivatives and regression) with each optimizer. The two fits of a row alternate, so
both see the same machine load; each row also checks that both find the same support and
reports their largest coefficient difference, relative to each target's largest coefficient
(absolute for a target both fit as all zero).
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from typing import Any, Callable, List

import numpy as np
import numpy.typing as npt

import rollest.sindy

Array = npt.NDArray[np.float64]

#: The sample interval of the trajectory, s.
DT_S = 0.002
#: The STLSQ threshold of every fit (the Lorenz coefficients are 1 to 28).
THRESHOLD = 0.5


def lorenz_trajectory(n_samples: int) -> Array:
    """The Lorenz system (sigma 10, rho 28, beta 8/3) from (-8, 8, 27), sampled every DT_S."""
    from scipy.integrate import solve_ivp  # type: ignore[import-untyped]

    def lorenz(_t: float, z: Array) -> List[float]:
        return [10.0 * (z[1] - z[0]), z[0] * (28.0 - z[2]) - z[1], z[0] * z[1] - 8.0 / 3.0 * z[2]]

    t_s = np.arange(n_samples) * DT_S
    solution = solve_ivp(lorenz, (0.0, t_s[-1]), [-8.0, 8.0, 27.0], t_eval=t_s, rtol=1e-10, atol=1e-10)
    x: Array = solution.y.T
    return x


def timed_s(work: Callable[[], Any]) -> float:
    """The wall time of one call, s."""
    started = time.perf_counter()
    work()
    return time.perf_counter() - started


def alternating(repeat: int, first: Callable[[], Any], second: Callable[[], Any]) -> List[float]:
    """The median wall time of each of two calls, s, over ``repeat`` rounds that make them in
    turn."""
    rounds = [(timed_s(first), timed_s(second)) for _ in range(repeat)]
    return [statistics.median(times) for times in zip(*rounds)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--samples", default="2000,20000,200000", help="numbers of samples, comma-separated")
    parser.add_argument("--degrees", default="2,3,4", help="library degrees, comma-separated")
    args = parser.parse_args()
    import pysindy as ps  # type: ignore[import-untyped]

    samples = [int(n) for n in args.samples.split(",")]
    degrees = [int(d) for d in args.degrees.split(",")]
    x_all = lorenz_trajectory(max(samples))
    warnings.simplefilter("ignore")

    print(f"pysindy {ps.__version__}, numpy {np.__version__}; median of {args.repeat}, wall time, ms\n")
    print("| fit | samples x features | PySINDy STLSQ, ms | rollest STLSQ, ms | ratio | terms | same support | max rel. difference |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for degree in degrees:
        for n in samples:
            x = x_all[:n]
            theta = np.asarray(ps.PolynomialLibrary(degree=degree).fit_transform(x))
            x_dot = np.gradient(x, DT_S, axis=0)
            theirs = ps.STLSQ(threshold=THRESHOLD)
            ours = rollest.sindy.STLSQ(threshold=THRESHOLD)
            their_s, our_s = alternating(args.repeat, lambda: theirs.fit(theta, x_dot), lambda: ours.fit(theta, x_dot))
            row(f"`STLSQ.fit`, degree {degree}", theta.shape, their_s, our_s, theirs.coef_, ours.coef_)
    n = max(samples)
    for degree in degrees:
        models = [
            ps.SINDy(optimizer=optimizer, feature_library=ps.PolynomialLibrary(degree=degree))
            for optimizer in (ps.STLSQ(threshold=THRESHOLD), rollest.sindy.STLSQ(threshold=THRESHOLD))
        ]
        their_s, our_s = alternating(
            args.repeat, lambda: models[0].fit(x_all[:n], t=DT_S), lambda: models[1].fit(x_all[:n], t=DT_S)
        )
        n_features = len(models[0].get_feature_names())
        row(
            f"`SINDy.fit` (whole), degree {degree}",
            (n, n_features),
            their_s,
            our_s,
            models[0].coefficients(),
            models[1].coefficients(),
        )


def row(what: str, shape: Any, their_s: float, our_s: float, theirs: Array, ours: Array) -> None:
    same = bool(np.array_equal(theirs != 0.0, ours != 0.0))
    # Relative to each target's largest |coefficient|; absolute for a target fitted as all zero.
    scale = np.abs(theirs).max(axis=1)
    difference = float((np.abs(ours - theirs).max(axis=1) / np.where(scale > 0.0, scale, 1.0)).max())
    print(
        f"| {what} | {shape[0]:,} x {shape[1]} | {their_s * 1e3:.3g} | {our_s * 1e3:.3g} | "
        f"{their_s / our_s:.1f} | {np.count_nonzero(theirs)} | {'yes' if same else 'no'} | {difference:.1e} |"
    )


if __name__ == "__main__":
    main()
