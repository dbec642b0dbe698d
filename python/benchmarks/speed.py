"""How fast the rollest package steps a campaign, against the command line and PySINDy.

    target/python-venv/bin/python python/benchmarks/speed.py [--data out/campaign]

Prints one table (best of --repeat, wall time, this machine):

* ``Estimator.run``: every run of the campaign stepped from Python, one thread, with the
  package's column handling (the call a notebook makes);
* the same with the arrays already prepared (the Rust loop and the output arrays alone);
* ``Model.replay``: every run through the command line's replay function
  (``model_fit::replay::replay_run``), outputs as arrays, on one core and in parallel over runs;
* ``host-tools replay``: the command line on the same data and model, on one core
  (``RAYON_NUM_THREADS=1``) and on all, reading the CSVs and writing the replay CSVs;
* PySINDy's ``predict`` called once per step (how a PySINDy model is stepped in a control
  loop), on a discrete-time model of the same actuation run, when pysindy is installed.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from typing import Callable, List, Tuple

import numpy as np

import rollest


def best_of(repeat: int, work: Callable[[], object]) -> float:
    """The shortest wall time of ``repeat`` calls, s."""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return min(times)


def pysindy_steps_per_s(run: rollest.Run, steps: int) -> Tuple[float, str]:
    """PySINDy's predict, once per step, of a discrete-time cubic model of an actuation run's
    roll moment driven by both jets (the plant's structure), fitted on the run."""
    import pysindy as ps  # type: ignore[import-untyped]

    x = run.arrays["cl"].reshape(-1, 1)
    u = np.column_stack([run.arrays["cmu_port"], run.arrays["cmu_stbd"]])
    model = ps.DiscreteSINDy(feature_library=ps.PolynomialLibrary(degree=3), optimizer=ps.STLSQ(threshold=1e-6))
    model.fit(x, t=1.0 / run.sample_hz, u=u)
    state = x[:1]
    started = time.perf_counter()
    for k in range(steps):
        state = model.predict(state, u=u[k : k + 1])
    elapsed = time.perf_counter() - started
    return steps / elapsed, f"pysindy {ps.__version__}, {len(model.get_feature_names())} candidate terms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="out/campaign", help="dataset folder (default: the default campaign)")
    parser.add_argument("--model", default="models/default", help="model folder")
    parser.add_argument("--host-tools", default="target/release/host-tools", help="the command line binary")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--pysindy-steps", type=int, default=2000)
    args = parser.parse_args()

    data = rollest.load_dataset(args.data)
    model = rollest.Model.load(args.model)
    n = sum(len(run) for run in data.runs)
    rows: List[Tuple[str, float, str]] = []

    def run_all() -> None:
        for run in data.runs:
            rollest.Estimator(model).run(run)

    rows.append(("Estimator.run, every run, one thread", best_of(args.repeat, run_all), "from Run objects"))

    prepared = []
    for run in data.runs:
        a = run.arrays
        cp = np.ascontiguousarray(np.column_stack([a[name] for name in rollest.CP_COLUMNS]))
        commands = [a.get("cmu_port_cmd"), a.get("cmu_stbd_cmd")]
        prepared.append((a["phi_deg"], run.alpha_series(), a["cmu_port"], a["cmu_stbd"], cp, *commands))

    def run_prepared() -> None:
        for arrays in prepared:
            rollest.Estimator(model)._native.run(*arrays)

    rows.append(("Estimator.run, arrays prepared", best_of(args.repeat, run_prepared), "Rust loop + output arrays"))
    rows.append(("Model.replay, all cores", best_of(args.repeat, lambda: model.replay(data)), "parallel over runs"))
    # The command line's replay function (model_fit::replay::replay_run) on one thread: rayon's
    # pool is sized once per process, so in a child process.
    child = (
        "import sys, time, rollest\n"
        "data, model = rollest.load_dataset(sys.argv[1]), rollest.Model.load(sys.argv[2])\n"
        "times = []\n"
        "for _ in range(int(sys.argv[3])):\n"
        "    started = time.perf_counter(); model.replay(data); times.append(time.perf_counter() - started)\n"
        "print(min(times))\n"
    )
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-c", child, args.data, args.model, str(args.repeat)],
        check=True, env=env, capture_output=True, text=True,
    )
    rows.append(("Model.replay, one core", float(done.stdout), "host-tools' replay_run, outputs as arrays"))

    with tempfile.TemporaryDirectory() as scratch:
        for threads in ("1", None):
            env = dict(os.environ)
            if threads is not None:
                env["RAYON_NUM_THREADS"] = threads
            command = [args.host_tools, "replay", "--data", args.data, "--model", args.model]

            def replay() -> None:
                out = os.path.join(scratch, f"replay-{time.perf_counter_ns()}")
                subprocess.run([*command, "--out", out], check=True, env=env, capture_output=True)

            cores = "one core" if threads else f"{os.cpu_count()} cores"
            rows.append((f"host-tools replay, {cores}", best_of(args.repeat, replay), "reads and writes CSV"))

    print(f"{len(data.runs)} runs, {n} samples ({args.data}, model {args.model})")
    print(f"{'what':<42} {'time, s':>9} {'steps/s':>12}  note")
    for name, seconds, note in rows:
        print(f"{name:<42} {seconds:>9.3f} {n / seconds:>12.3e}  {note}")
    actuation = next((run for run in data.runs if run.kind == "actuation"), None)
    try:
        if actuation is None:
            raise ImportError("no actuation run")
        rate, described = pysindy_steps_per_s(actuation, args.pysindy_steps)
        print(f"{'PySINDy predict, once per step':<42} {n / rate:>9.3f} {rate:>12.3e}  {described}; time for {n} steps")
    except ImportError as missing:
        print(f"PySINDy left out: {missing}")


if __name__ == "__main__":
    main()
