"""The Ray adapter: a campaign slice and a SIL sweep on a local Ray instance equal the local
processes'. Runs where Ray is installed (``pip install ray``); CI has no Ray."""

from __future__ import annotations

import pytest

import rollest
from rollest.executors import RayExecutor

ray = pytest.importorskip("ray")

SLICE = dict(cases=14, seed=5, duration_s=10.0, only=[1])
POINTS = [rollest.SilPoint(seed=seed, duration_s=1.5) for seed in (1, 2)]


@pytest.fixture(scope="module")
def ray_executor():
    ray.init(num_cpus=2, include_dashboard=False)
    yield RayExecutor()
    ray.shutdown()


def timeless(validation: rollest.Validation) -> list:
    return [{k: v for k, v in case.items() if k != "diagnosis_s"} for case in validation.results["cases"]]


def test_a_ray_cluster_gives_the_local_processes_campaign_and_sweep(ray_executor):
    on_ray = rollest.validate_diagnosis(**SLICE, executor=ray_executor)
    assert timeless(on_ray) == timeless(rollest.validate_diagnosis(**SLICE))
    sweep = rollest.sil_sweep(POINTS, executor=ray_executor)
    assert [r.record for r in sweep.results] == [r.record for r in rollest.sil_sweep(POINTS).results]
