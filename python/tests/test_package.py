"""The package as installed: its version and the ABI its extension is built for."""

from __future__ import annotations

from pathlib import Path

import rollest

WORKSPACE = Path(__file__).resolve().parents[2]


def test_the_version_is_the_workspaces():
    manifest = (WORKSPACE / "Cargo.toml").read_text()
    version = next(line.split('"')[1] for line in manifest.splitlines() if line.startswith("version = "))
    assert rollest.__version__ == version


def test_the_extension_is_built_for_the_stable_abi():
    # One wheel for every CPython from 3.9 on: the module is named for the stable ABI (PEP 384).
    assert rollest._rollest.__file__.endswith(".abi3.so"), rollest._rollest.__file__


def test_the_installed_wheel_is_tagged_for_the_stable_abi():
    from importlib.metadata import distribution

    wheel = distribution("rollest").read_text("WHEEL") or ""
    tags = [line.split(":", 1)[1].strip() for line in wheel.splitlines() if line.startswith("Tag:")]
    assert tags and all(tag.startswith("cp39-abi3-") for tag in tags), tags
