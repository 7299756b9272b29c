"""Shared fixtures: where the reference vectors and the project's .proto files are."""

import pathlib

import pytest

HERE = pathlib.Path(__file__).resolve().parent
# The workspace root is two levels up (python/tests); the shared reference
# data lies beside the workspace, as CI lays it out.
WORKSPACE = HERE.parent.parent
# ../shared beside the workspace when present, else the copy committed with
# the dccl crate's tests.
VECTORS = WORKSPACE.parent / "shared" / "dccl-vectors"
if not VECTORS.is_dir():
    VECTORS = WORKSPACE / "dccl" / "tests" / "data" / "dccl-vectors"
PROTOS = WORKSPACE / "protos" / "proto"


@pytest.fixture(scope="session")
def vectors_dir():
    if not (VECTORS / "vectors.jsonl").is_file():
        pytest.skip("SKIPPED: reference vectors absent (%s): lay ../shared beside the workspace" % VECTORS)
    return VECTORS


@pytest.fixture(scope="session")
def protos_dir():
    return PROTOS
