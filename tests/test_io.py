import os

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.io import read_json, read_mesh, write_json, write_mesh


@pytest.fixture(scope="module")
def body():
    mesh = Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=0.05)
    x = mesh.points @ np.array([[1.1, 0.2], [0.0, 0.9]]).T + [0.3, 0.1]
    return mesh, x


@pytest.mark.parametrize("ext", [".vtk", ".vtu", ".xdmf", ".msh"])
def test_round_trip_keeps_mesh_state_and_data(tmp_path, body, ext):
    mesh, x = body
    mat = NeoHookean(1.0, 0.3)
    path = write_mesh(tmp_path / f"state{ext}", mesh, x=x, material=mat,
                      point_data={"weight": np.arange(mesh.n_nodes, dtype=float)})
    back = read_mesh(path)
    assert np.array_equal(back.mesh.triangles, mesh.triangles)
    assert np.abs(back.mesh.points - mesh.points).max() < 1e-12
    assert np.abs(back.x - x).max() < 1e-12
    assert np.allclose(back.cell_data["J"], mesh.jacobians(x))
    assert np.allclose(back.cell_data["energy_density"], mat.psi(mesh.deformation_gradients(x)))
    assert np.allclose(back.point_data["weight"], np.arange(mesh.n_nodes))
    assert os.listdir(tmp_path) == [f"state{ext}"]  # no temporary files left


def test_failed_writes_leave_nothing(tmp_path, body):
    mesh, x = body
    with pytest.raises(ValueError, match="needs .* rows"):
        write_mesh(tmp_path / "a.vtu", mesh, x=x, point_data={"w": np.ones(3)})
    with pytest.raises(ValueError, match="shape"):
        write_mesh(tmp_path / "a.vtu", mesh, x=x[:-1])
    with pytest.raises(ValueError, match="NaN"):
        write_mesh(tmp_path / "a.vtu", mesh, x=np.full_like(x, np.nan))
    with pytest.raises(ValueError, match="unsupported mesh file extension '.stl'"):
        write_mesh(tmp_path / "a.stl", mesh)
    with pytest.raises(ValueError, match="NaN"):
        write_json(tmp_path / "r.json", {"bad": float("nan")})
    assert os.listdir(tmp_path) == []


def test_read_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such mesh file"):
        read_mesh(tmp_path / "missing.vtu")
    (tmp_path / "junk.vtu").write_text("not a mesh")
    with pytest.raises(ValueError, match="cannot read"):
        read_mesh(tmp_path / "junk.vtu")


def test_json_round_trip(tmp_path):
    data = {"x": np.arange(3.0), "n": np.int64(4), "ok": True}
    write_json(tmp_path / "r.json", data)
    assert read_json(tmp_path / "r.json") == {"x": [0.0, 1.0, 2.0], "n": 4, "ok": True}


def test_written_files_get_normal_permissions(tmp_path, body):
    """Atomic writes go through mkstemp (mode 0600); the final file must get the usual umask mode."""
    import stat

    umask = os.umask(0)
    os.umask(umask)
    want = 0o666 & ~umask
    mesh, x = body
    for path in (write_json(tmp_path / "r.json", {"a": 1}), write_mesh(tmp_path / "m.vtu", mesh, x=x)):
        assert stat.S_IMODE(os.stat(path).st_mode) == want
