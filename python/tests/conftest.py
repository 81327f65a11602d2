# Shared fixtures of the Python tests: the project's small beam model and its bend scenario, run with
# parameters that keep each solve to seconds (a coarse subspace and sampling; the method is the same).
import os
import pathlib

import pytest

import lidef

SOURCE_DIR = pathlib.Path(os.environ.get("LIDEF_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
BEAM = SOURCE_DIR / "data" / "models" / "beam"
BEAM_BEND = SOURCE_DIR / "data" / "scenarios" / "beam_bend.json"
# Coarse but complete: every accepted map is still certified on the voxels these give.
SMALL = {"reduced_dof": 60, "samples": 4000, "max_iterations": 30}


@pytest.fixture(scope="session")
def beam():
    return lidef.load_model(str(BEAM))


@pytest.fixture(scope="session")
def bend():
    return lidef.read_scenario(str(BEAM_BEND))


@pytest.fixture(scope="session")
def bend_result(beam, bend):
    return lidef.deform(beam, bend.sources, bend.targets, **SMALL)


@pytest.fixture(scope="session")
def cli():
    path = os.environ.get("LIDEF_CLI")
    if not path:
        pytest.skip("LIDEF_CLI (the lidef program) not set")
    return path
