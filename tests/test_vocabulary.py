"""One vocabulary: the same keyword for the same idea; old spellings work for one release and warn."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, design, design_contractions, render_photo, solve_internal


@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    return mesh, NeoHookean(1.0, 0.3), [Muscle(range(0, 9))]


def test_solve_internal_model_is_muscle_model(strip):
    mesh, mat, mus = strip
    new = solve_internal(mesh, mat, mus, [0.2], muscle_model="springs")
    with pytest.warns(DeprecationWarning, match=r"model= is deprecated .* use muscle_model="):
        old = solve_internal(mesh, mat, mus, [0.2], model="springs")
    assert old.muscle_model == new.muscle_model == "springs"
    assert np.allclose(old.x, new.x, atol=1e-12)
    with pytest.raises(TypeError, match="got both model= .* and muscle_model="):
        solve_internal(mesh, mat, mus, [0.2], model="springs", muscle_model="cable")


def test_design_initial_is_initial_guess(strip):
    mesh, mat, mus = strip
    target = solve_internal(mesh, mat, mus, [0.2]).x
    with pytest.warns(DeprecationWarning, match="use initial_guess="):
        old = design_contractions(mesh, mat, mus, target, initial=[0.1])
    new = design_contractions(mesh, mat, mus, target, initial_guess=[0.1])
    assert old.contractions == pytest.approx(new.contractions, abs=1e-9)
    assert new.contractions[0] == pytest.approx(0.2, abs=1e-6)


def test_render_photo_resolution_is_image_size(strip):
    mesh = strip[0]
    with pytest.warns(DeprecationWarning, match="use image_size="):
        old = render_photo(mesh, resolution=(120, 80), seed=1)
    new = render_photo(mesh, image_size=(120, 80), seed=1)
    assert old.image.shape == new.image.shape == (80, 120, 3)
    assert np.array_equal(old.image, new.image)


def test_design_is_the_pipeline_function_not_a_module():
    import mdsr_opt.synthesis.pipeline  # noqa: F401  (importing the module must not shadow the function)
    from mdsr_opt import design as d

    assert callable(d) and d is design and d.__module__ == "mdsr_opt.synthesis.pipeline"
