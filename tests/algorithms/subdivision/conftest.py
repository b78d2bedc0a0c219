"""Shared fixtures of the subdivision tests."""

import pytest


@pytest.fixture(scope="module")
def spot_coarse_samples(tmp_path_factory):
    """``make(n)``: ``n`` coarse meshes (60-80 vertices) of spot_lowres with their successive
    self-parameterization, cached in a fresh folder (the training tests' data)."""
    from algorithms.mesh import read_mesh
    from algorithms.subdivision.data import DataParams, generate_dataset

    def make(n: int):
        m = read_mesh("tests/data/spot_lowres.obj")
        return generate_dataset([(m.V, m.F)], DataParams(coarse_meshes=n, min_vertices=60,
                                                         max_vertices=80),
                                workers=1, cache_dir=tmp_path_factory.mktemp("cache"))

    return make
