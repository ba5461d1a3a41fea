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


# ------------------------------------------------------------------------------ output folder: out=
@pytest.fixture(scope="module")
def one_muscle():
    from mdsr_opt import get_problem

    return get_problem("one_muscle", resolution="coarse")


def test_export_fabrication_folder_is_out(strip, tmp_path):
    from mdsr_opt import export_fabrication

    mesh, _, mus = strip
    with pytest.warns(DeprecationWarning, match=r"export_fabrication\(\): the keyword folder= .* use out="):
        old = export_fabrication(mesh, None, folder=tmp_path / "old", muscles=mus, name="p")
    new = export_fabrication(mesh, None, out=tmp_path / "new", muscles=mus, name="p")
    assert old["csv"] == str(tmp_path / "old" / "p_muscles.csv")
    assert (tmp_path / "old" / "p_muscles.csv").read_text().splitlines()[1].startswith("m1,")  # unnamed: m1
    assert (tmp_path / "old" / "p.svg").read_text() == (tmp_path / "new" / "p.svg").read_text()
    with pytest.raises(TypeError, match="got both folder= .* and out="):
        export_fabrication(mesh, None, folder=tmp_path, out=tmp_path, muscles=mus)


def test_write_case_folder_is_out(one_muscle, tmp_path):
    from mdsr_opt.scenes.runner import run_case, write_case

    run = run_case(one_muscle, "a20", photo=False)
    with pytest.warns(DeprecationWarning, match=r"write_case\(\): the keyword folder= .* use out="):
        files = write_case(one_muscle, run, folder=tmp_path / "a20")
    assert "a20/target.vtu" in files and (tmp_path / "a20" / "design.png").stat().st_size > 0


def test_save_scene_folder_is_out(tmp_path):
    from mdsr_opt import get_problem
    from mdsr_opt.author.export import save_scene
    from mdsr_opt.author.session import Session

    s = Session.from_scene(get_problem("tentacle", resolution="coarse"))
    with pytest.warns(DeprecationWarning, match=r"save_scene\(\): the keyword folder= .* use out="):
        files = save_scene(s, folder=tmp_path, name="t1")
    assert files == [str(tmp_path / "t1.json"), str(tmp_path / "t1.mesh.vtu")]


def test_pipeline_result_save_directory_is_out_and_load_directory_is_path(strip, tmp_path):
    from mdsr_opt.synthesis.pipeline import PipelineResult

    mesh, mat, mus = strip
    left = [i for i, (x, _) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.2, y - 0.3) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    res = design(mesh, mat, left, right, muscles=mus)
    with pytest.warns(DeprecationWarning, match=r"save\(\): the keyword directory= .* use out="):
        path = res.save(directory=tmp_path / "old")
    assert path == str(tmp_path / "old" / "design.json")
    with pytest.warns(DeprecationWarning, match=r"load\(\): the keyword directory= .* use path="):
        back = PipelineResult.load(directory=tmp_path / "old")
    assert np.array_equal(back.design.contractions, res.design.contractions)
    assert np.array_equal(PipelineResult.load(path=tmp_path / "old").design.x, res.design.x)


# ------------------------------------------------------------------------------ photo size: photo_size=
def test_run_case_photo_resolution_is_photo_size(one_muscle):
    from mdsr_opt.scenes.runner import run_case

    with pytest.warns(DeprecationWarning, match=r"run_case\(\): the keyword photo_resolution= .* use photo_size="):
        run = run_case(one_muscle, "a20", photo_resolution=(240, 200))
    assert run.report.photo["image_size"] == [240, 200] and run.photo.image.shape == (200, 240, 3)


@pytest.mark.parametrize("which", ["run_scene", "write_scene"])
def test_run_scene_photo_resolution_is_photo_size(one_muscle, tmp_path, which):
    import json

    from mdsr_opt.scenes import runscene

    fn = getattr(runscene, which)
    with pytest.warns(DeprecationWarning, match=rf"{which}\(\): the keyword photo_resolution= .* use photo_size="):
        rep = fn(one_muscle, tmp_path, cases=["a20"], photo_resolution=(240, 200), prototype=False, figures=False,
                 animations=False, log=None)
    assert rep.success
    assert json.loads((tmp_path / "summary.json").read_text())["cases"][0]["photo"]["image_size"] == [240, 200]


def test_prototype_photo_resolution_is_photo_size(one_muscle):
    from mdsr_opt.scenes.prototype import VirtualPrototype

    with pytest.warns(DeprecationWarning, match=r"for_scene\(\): the keyword photo_resolution= .* use photo_size="):
        old = VirtualPrototype.for_scene(one_muscle, refine=1.5, photo_resolution=(320, 240))
    new = VirtualPrototype.for_scene(one_muscle, refine=1.5, photo_size=(320, 240))
    assert old.camera["image_size"] == new.camera["image_size"] == (320, 240)


def test_photograph_command_resolution_is_photo_size(strip, tmp_path, capsys):
    from mdsr_opt import write_mesh
    from mdsr_opt.cli.main import main
    from mdsr_opt.photos.images import load_image

    mesh = strip[0]
    write_mesh(tmp_path / "states" / "s.vtu", mesh)
    assert main(["photograph", str(tmp_path / "states"), "--out", str(tmp_path / "old"), "--resolution", "240x160"]) == 0
    assert "--resolution is deprecated and will be removed in the next release; use --photo-size" in \
        capsys.readouterr().err
    assert main(["photograph", str(tmp_path / "states"), "--out", str(tmp_path / "new"), "--photo-size", "240x160"]) == 0
    old, new = load_image(tmp_path / "old" / "s.png"), load_image(tmp_path / "new" / "s.png")
    assert old.shape == (160, 240, 3) and np.array_equal(old, new)
