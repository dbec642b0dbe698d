"""A SIL sweep three ways, side by side on one machine: the command line (``host-tools sil``
once per scenario, each over the engine's threads), ``rollest.sil_sweep`` over local processes
(one scenario per process), and over a Dask ``LocalCluster`` of one process per core. Prints a
Markdown table: wall time, and whether every scenario's record equals the command line's
``sil.json``.

    python python/benchmarks/sil_sweep.py [HOST_TOOLS] [--seeds 4] [--duration-s 20] [--no-dask]

The sweep: ``--seeds`` master seeds times three valve delays (0, 20 and 40 ms), the paper's
three angles of attack and five controller modes each. On one machine the three share the same
cores, so the table shows what distributing costs, not what a cluster gains.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import rollest

DELAYS_S = (0.0, 0.02, 0.04)


def command_line(host_tools: str, point: rollest.SilPoint, folder: Path) -> Dict[str, Any]:
    """``host-tools sil`` of one point: its ``sil.json``."""
    args = [host_tools, "sil", "--seed", str(point.seed), "--duration-s", str(point.duration_s), "--report", str(folder)]
    for effect in point.effects:
        args += ["--effect", effect]
    subprocess.run(args, check=True, capture_output=True)
    record: Dict[str, Any] = json.loads((folder / "sil.json").read_text())
    return record


def main(argv: Optional[List[str]] = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("host_tools", nargs="?", default="target/release/host-tools")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--no-dask", action="store_true", help="leave out the Dask cluster")
    args = parser.parse_args(argv)
    points = [
        rollest.SilPoint(seed=seed, duration_s=args.duration_s, effects=[f"actuator_delay:delay_s={delay}"])
        for seed in range(1, args.seeds + 1)
        for delay in DELAYS_S
    ]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        expected = [command_line(args.host_tools, point, Path(scratch) / f"p{i}") for i, point in enumerate(points)]
        rows.append(("command line, one scenario at a time (engine threads)", time.perf_counter() - started, True))
    started = time.perf_counter()
    local = rollest.sil_sweep(points)
    equal = [result.record for result in local.results] == expected
    rows.append((f"local processes ({os.cpu_count()})", time.perf_counter() - started, equal))
    if not args.no_dask:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, dashboard_address=None) as cluster:
            with Client(cluster) as client:
                started = time.perf_counter()
                dask = rollest.sil_sweep(points, executor=client.get_executor())
                equal = [result.record for result in dask.results] == expected
                rows.append(("Dask LocalCluster", time.perf_counter() - started, equal))
    print(f"{len(points)} scenarios ({args.seeds} seeds x {len(DELAYS_S)} valve delays), runs of {args.duration_s} s\n")
    print("| run | wall time | every scenario's record equals `sil.json` |\n| --- | --- | --- |")
    for name, seconds, same in rows:
        print(f"| {name} | {seconds:.1f} s | {'yes' if same else 'NO'} |")


if __name__ == "__main__":
    main()
