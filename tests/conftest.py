import numpy as np
import pytest
from hypothesis import settings

from support import mesh_path

# Seeded and bounded: the same examples on every run, no database written into the checkout.
settings.register_profile("rokeby", derandomize=True, database=None, deadline=None, max_examples=200)
settings.load_profile("rokeby")


@pytest.fixture(scope="session")
def spot():
    from rokeby.meshio import load_obj, vertex_normals

    v, f = load_obj(mesh_path("spot.obj"))
    return v, f, vertex_normals(v, f)


@pytest.fixture
def rng():
    return np.random.default_rng(20091001)
