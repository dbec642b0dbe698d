"""SIL sweeps over executors: each scenario's record is the command line's ``sil.json``, and a
sweep gives the same numbers on local processes and on a Dask cluster."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import rollest

from conftest import cli

SCENARIO = """\
seed = 4
duration_s = 1.5
alphas_deg = [5.0, 15.0]
"""


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sil") / "two_alphas.toml"
    path.write_text(SCENARIO)
    return path


@pytest.fixture(scope="module")
def points(scenario_file: Path) -> list:
    """A default campaign, a scenario file with an effect, and one with faults and gains."""
    return [
        rollest.SilPoint(seed=3, duration_s=1.5, label="default"),
        rollest.SilPoint(scenario=scenario_file, effects=["actuator_delay:delay_s=0.03"], label="delay"),
        dict(scenario=scenario_file, seed=9, faults=["dead:cp03@0.5s"], kp=0.5, ki=5.0, label="fault"),
    ]


@pytest.fixture(scope="module")
def local_sweep(points: list) -> rollest.SilSweep:
    return rollest.sil_sweep(points, max_in_flight=2)


def test_each_point_of_a_sweep_is_the_command_lines_sil_record(local_sweep, scenario_file, host_tools, tmp_path):
    cli(host_tools, "sil", "--scenario", scenario_file, "--seed", 9, "--fault", "dead:cp03@0.5s", "--kp", 0.5,
        "--ki", 5.0, "--report", tmp_path / "cli")  # fmt: skip
    expected = json.loads((tmp_path / "cli" / "sil.json").read_text())
    assert local_sweep.results[2].record == expected
    cli(host_tools, "sil", "--seed", 3, "--duration-s", 1.5, "--report", tmp_path / "default")
    assert local_sweep.results[0].record == json.loads((tmp_path / "default" / "sil.json").read_text())


def test_a_sweep_runs_every_mode_at_every_alpha_of_each_point(local_sweep):
    frame = local_sweep.frame()
    assert len(frame) == 5 * (3 + 2 + 2)
    assert list(frame.loc[1].index.get_level_values("alpha_deg").unique()) == [5.0, 15.0]
    assert set(frame.index.get_level_values("mode")) == set(rollest.closed_loop.MODES)
    assert (frame.xs("none", level="mode")["reduction"] == 0.0).all()
    # The delayed valves and the dead tap change the loop; the scenarios are not the same runs.
    assert frame.loc[(1, 5.0, "ff_fb_linear"), "rms_cl"] != frame.loc[(2, 5.0, "ff_fb_linear"), "rms_cl"]
    assert "SIL sweep" in local_sweep._repr_html_()


def test_a_dask_cluster_gives_every_point_as_the_local_processes(local_sweep, points, dask_executor):
    sweep = rollest.sil_sweep(points, executor=dask_executor)
    assert [result.record for result in sweep.results] == [result.record for result in local_sweep.results]


def test_one_point_in_process_is_the_sweeps(local_sweep, points):
    one = rollest.sil(point=points[0])
    assert one.record == local_sweep.results[0].record
    assert "ff_fb_coupled" in one._repr_html_()


def test_a_bad_fault_or_scenario_is_named(tmp_path):
    with pytest.raises(rollest.RollestError, match='fault "dead:cp99'):
        rollest.sil(point=rollest.SilPoint(duration_s=1.0, faults=["dead:cp99@1s"]))
    bad = tmp_path / "bad.toml"
    bad.write_text("seed = 'one'\n")
    with pytest.raises(rollest.RollestError, match="bad.toml"):
        rollest.sil_sweep([rollest.SilPoint(scenario=bad)], executor=None, max_in_flight=1)
