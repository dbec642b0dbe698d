#!/usr/bin/env python3
"""Benchmark: the same STLSQ threshold sweep in PySINDy and in the workspace's SINDy engine (the sindy crate).

Usage (from the workspace root):

    pip install -r tools/pysindy/requirements.txt   # pysindy==2.1.0, numpy==2.4.6
    python3 tools/pysindy/bench_sweep.py [--n 100000] [--thresholds 30] [--repeats 3]

The problem is the paper's plant library (variables [cl_afc, cmu, dcmu, alpha], all products
up to degree 2 without cl_afc^2: 14 columns) on N samples of the first-order lag of
make_fixtures.py with a little process noise. Theta and y are written to a temporary binary
file. PySINDy runs a fresh `STLSQ(threshold=t, alpha, max_iter=20, normalize_columns=True,
unbias=True).fit(Theta, y)` per threshold on the precomputed Theta, as a user would; the Rust
side (`cargo run --release -p sindy --example sindy_sweep`) factors [Theta | y] once and
runs the sweep on R. Both exclude file I/O and the library construction. The thresholds are
log-spaced from 1e-4 to 1 times the largest |normalised least-squares coefficient|. The script
prints a timing table and checks that both engines select the same support at every threshold.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np
import pysindy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_fixtures import polynomial_terms, theta  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
ALPHA = 1e-3


def plant_problem(n, rng):
    """The plant of make_fixtures.py at length n (vectorised inputs, sequential lag)."""
    levels = 0.01 * np.array([0, 0.25, 0.5, 0.75, 1.0])
    holds = rng.integers(5, 41, size=n // 5 + 1)
    cmu = np.repeat(rng.choice(levels, size=holds.size, p=[0.3] + [0.175] * 4), holds)[:n]
    alpha_holds = rng.integers(100, 201, size=n // 100 + 1)
    alpha = np.repeat(np.deg2rad(rng.choice([0.0, 10.0, 20.0], size=alpha_holds.size)), alpha_holds)[:n]
    dcmu = np.diff(cmu, prepend=0.0)
    drive = 0.6 * cmu + 8.0 * cmu**2 + 0.5 * alpha * cmu + 2e-5 * rng.standard_normal(n)
    cl = np.zeros(n + 1)
    for k in range(n):
        cl[k + 1] = 0.92 * cl[k] + drive[k]
    x = np.column_stack([cl[:n], cmu, dcmu, alpha])
    terms = [t for t in polynomial_terms(4, 2) if t != (2, 0, 0, 0)]
    return theta(x, terms), cl[1:]


def write_problem(path, matrix, y):
    n, p = matrix.shape
    with open(path, "wb") as f:
        f.write(b"SINDYBIN")
        f.write(np.array([n, p], dtype="<u8").tobytes())
        f.write(np.asfortranarray(matrix).astype("<f8").tobytes(order="F"))
        f.write(y.astype("<f8").tobytes())


def pysindy_sweep(matrix, y, thresholds):
    """One fresh STLSQ fit per threshold; returns (seconds, supports)."""
    supports = []
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for t in thresholds:
            opt = pysindy.STLSQ(threshold=t, alpha=ALPHA, max_iter=20, normalize_columns=True, unbias=True)
            opt.fit(matrix, y)
            supports.append([bool(c != 0.0) for c in opt.coef_[0]])
    return time.perf_counter() - start, supports


def rust_sweep(problem_path, thresholds_path, repeats):
    subprocess.run(
        ["cargo", "build", "--release", "-q", "-p", "sindy", "--example", "sindy_sweep"], cwd=ROOT, check=True
    )
    binary = os.path.join(ROOT, "target", "release", "examples", "sindy_sweep")
    args = [binary, problem_path, thresholds_path, "--alpha", repr(ALPHA), "--normalize", "l2"]
    out = subprocess.run(args + ["--repeats", str(repeats), "--dense"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000)
    parser.add_argument("--thresholds", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    matrix, y = plant_problem(args.n, np.random.default_rng(7))
    normed = matrix / np.linalg.norm(matrix, axis=0)
    c_max = np.abs(np.linalg.lstsq(normed, y, rcond=None)[0]).max()
    thresholds = c_max * np.logspace(-4, 0, args.thresholds)
    with tempfile.TemporaryDirectory() as tmp:
        problem_path = os.path.join(tmp, "problem.bin")
        thresholds_path = os.path.join(tmp, "thresholds.txt")
        write_problem(problem_path, matrix, y)
        with open(thresholds_path, "w") as f:
            f.write("\n".join(repr(float(t)) for t in thresholds) + "\n")
        runs = [pysindy_sweep(matrix, y, thresholds) for _ in range(args.repeats)]
        ours = rust_sweep(problem_path, thresholds_path, max(args.repeats, 5))
    py_seconds = statistics.median(run[0] for run in runs)
    py_supports = runs[0][1]
    same = [a == b for a, b in zip(py_supports, ours["supports"])]
    distinct = len({tuple(s) for s in py_supports})
    print(f"plant library: N = {matrix.shape[0]}, p = {matrix.shape[1]}, {len(thresholds)} thresholds "
          f"({distinct} distinct supports), alpha = {ALPHA}, normalize_columns = True, unbias = True")
    print(f"pysindy {pysindy.__version__}, numpy {np.__version__}; Rust threads {ours['threads']}; "
          f"medians of {args.repeats} (PySINDy) and {ours['repeats']} (ours) runs")
    rows = [
        ("PySINDy STLSQ, fresh fit per threshold", py_seconds),
        ("ours: QR of [Theta|y] + sweep on R", ours["total_seconds"]),
        ("  of which QR (once)", ours["qr_seconds"]),
        ("  of which sweep on R", ours["sweep_seconds"]),
        ("ours: same sweep on full Theta (stls_dense)", ours["dense_seconds"]),
    ]
    print(f"{'engine':<46} {'seconds':>10} {'PySINDy / this':>15}")
    for name, seconds in rows:
        print(f"{name:<46} {seconds:>10.4f} {py_seconds / seconds:>15.1f}")
    print(f"same support at every threshold: {all(same)} ({sum(same)}/{len(same)})")
    if not all(same):
        sys.exit(1)


if __name__ == "__main__":
    main()
