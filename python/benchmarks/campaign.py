"""A blind validation campaign three ways, side by side on one machine: the command line
(``host-tools validate-diagnosis``, the engine's own threads), ``rollest.validate_diagnosis``
over local processes, and over a Dask cluster (a ``LocalCluster`` of one process per core).
Prints a Markdown table: wall time, and whether every case's score equals the command line's.

    python python/benchmarks/campaign.py [HOST_TOOLS] [--cases 14] [--seed 21] [--duration-s 30] [--no-dask]

On one machine the three share the same cores, so the table shows what distributing costs
(drawing in this process, pickling, spawning), not what a cluster gains; a cluster's workers
add their cores.
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

SCORED = ("class", "truth_sha256", "verdict", "named", "named_channels", "correct")


def command_line(host_tools: str, cases: int, seed: int, duration_s: float, folder: Path) -> Dict[int, Any]:
    """The command line's records by case id."""
    subprocess.run(
        [host_tools, "validate-diagnosis", "--cases", str(cases), "--seed", str(seed), "--duration-s", str(duration_s),
         "--report", str(folder)],
        check=True, capture_output=True,
    )  # fmt: skip
    return {case["id"]: case for case in json.loads((folder / "validation.json").read_text())["cases"]}


def same(records: List[Dict[str, Any]], expected: Dict[int, Any]) -> bool:
    """Every case scored as the command line scored it."""
    return len(records) == len(expected) and all(
        all(case[key] == expected[case["id"]][key] for key in SCORED) for case in records
    )


def main(argv: Optional[List[str]] = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("host_tools", nargs="?", default="target/release/host-tools")
    parser.add_argument("--cases", type=int, default=14)
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--duration-s", type=float, default=30.0)
    parser.add_argument("--no-dask", action="store_true", help="leave out the Dask cluster")
    args = parser.parse_args(argv)
    common = dict(cases=args.cases, seed=args.seed, duration_s=args.duration_s)
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        expected = command_line(args.host_tools, args.cases, args.seed, args.duration_s, Path(scratch) / "cli")
        rows.append(("command line (engine threads)", time.perf_counter() - started, True))
        started = time.perf_counter()
        local = rollest.validate_diagnosis(**common)  # type: ignore[arg-type]
        rows.append((f"local processes ({os.cpu_count()})", time.perf_counter() - started, same(local.results["cases"], expected)))
        if not args.no_dask:
            from distributed import Client, LocalCluster

            with LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, dashboard_address=None) as cluster:
                with Client(cluster) as client:
                    started = time.perf_counter()
                    dask = rollest.validate_diagnosis(**common, executor=client.get_executor())  # type: ignore[arg-type]
                    equal = same(dask.results["cases"], expected)
                    rows.append(("Dask LocalCluster", time.perf_counter() - started, equal))
    print(f"{len(expected)} cases, seed {args.seed}, runs of {args.duration_s} s\n")
    print("| run | wall time | every case scored as the command line |\n| --- | --- | --- |")
    for name, seconds, equal in rows:
        print(f"| {name} | {seconds:.0f} s | {'yes' if equal else 'NO'} |")


if __name__ == "__main__":
    main()
