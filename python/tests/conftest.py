"""Fixtures of the rollest test suite: a short synthetic campaign, a model fitted on it, and
the ``host-tools`` command line the package is compared with."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

import rollest

WORKSPACE = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def host_tools() -> Path:
    """The command line (``ROLLEST_HOST_TOOLS``, else the workspace's release build, built if
    absent)."""
    given = os.environ.get("ROLLEST_HOST_TOOLS")
    if given:
        return Path(given)
    binary = WORKSPACE / "target" / "release" / "host-tools"
    if not binary.exists():
        subprocess.run(["cargo", "build", "--release", "-p", "host-tools"], cwd=WORKSPACE, check=True)
    return binary


def cli(host_tools: Path, *args: object) -> str:
    """Runs a ``host-tools`` subcommand; its standard output."""
    done = subprocess.run([str(host_tools), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, f"host-tools {args}: {done.stderr}"
    return done.stdout


@pytest.fixture(scope="session")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> rollest.Dataset:
    """Three kinds of run at three angles of attack, 20 s each, seed 7."""
    return rollest.simulate(tmp_path_factory.mktemp("data") / "campaign", seed=7, duration_s=20.0)


@pytest.fixture(scope="session")
def model(campaign: rollest.Dataset, tmp_path_factory: pytest.TempPathFactory) -> rollest.Model:
    """The model fitted on the campaign, in-process."""
    return rollest.fit(campaign, tmp_path_factory.mktemp("models") / "model")


@pytest.fixture(scope="session")
def dask_executor():
    """The executor of a Dask ``LocalCluster`` with two worker processes, one thread each
    (started once: the campaign and the SIL sweep tests share it)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            yield client.get_executor()


def rebuilt(dataset: rollest.Dataset, runs: list, **changes: object) -> rollest.Dataset:
    """``dataset`` built again in memory from ``runs`` (its arrays, changed or not) and its
    metadata, with ``changes`` to the arguments of ``Dataset.from_arrays``."""
    arguments: dict = dict(
        kind=[run.kind for run in dataset.runs],
        alpha_deg=[run.alpha_deg for run in dataset.runs],
        u_inf_mps=dataset.tunnel["u_inf_mps"],
        rho_kgm3=dataset.tunnel["rho_kgm3"],
        wing=dataset.wing,
        files=[run.file for run in dataset.runs],
    )
    arguments.update(changes)
    return rollest.Dataset.from_arrays(runs, **arguments)
