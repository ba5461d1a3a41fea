import os
import re

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.body.io import read_json, read_mesh, write_json, write_mesh


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


# ------------------------------------------------------------------------ refused reads, clean writes
def _write_raw(path, points, cells, point_data=None):
    import meshio

    meshio.write(str(path), meshio.Mesh(points, cells, point_data=point_data or {}))
    return path


SQ3 = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]])


def test_read_refuses_non_triangle_cells(tmp_path):
    p = _write_raw(tmp_path / "mixed.vtu", SQ3, [("triangle", np.array([[0, 1, 2], [0, 2, 3]])),
                                               ("quad", np.array([[1, 4, 5, 2]]))])
    with pytest.raises(ValueError, match=r"mixed\.vtu holds cells other than triangles \(1 quad\)"):
        read_mesh(p)
    p = _write_raw(tmp_path / "quads.vtk", SQ3, [("quad", np.array([[0, 1, 2, 3], [1, 4, 5, 2]]))])
    with pytest.raises(ValueError, match=r"other than triangles \(2 quad\)"):
        read_mesh(p)


def test_read_skips_gmsh_line_marks_with_a_warning(tmp_path):
    p = _write_raw(tmp_path / "marked.vtu", SQ3[:4], [("triangle", np.array([[0, 1, 2], [0, 2, 3]])),
                                                    ("line", np.array([[0, 1]]))])
    with pytest.warns(UserWarning, match="skipped 1 line cells"):
        back = read_mesh(p)
    assert back.mesh.n_triangles == 2


@pytest.mark.parametrize("field", ["displacement", "weight"])
def test_read_refuses_non_finite_point_data(tmp_path, field):
    v = np.zeros((4, 3)) if field == "displacement" else np.zeros(4)
    v[2] = np.nan
    p = _write_raw(tmp_path / "nan.vtu", SQ3[:4], [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))], {field: v})
    with pytest.raises(ValueError, match=rf"point data '{field}' contains NaN or inf \(first at node 2\)"):
        read_mesh(p)


def test_read_accepts_a_mesh_in_the_plane_z_1_and_names_a_tilted_one(tmp_path):
    pts = SQ3[:4] + [0, 0, 1.0]
    back = read_mesh(_write_raw(tmp_path / "z1.vtu", pts, [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]))
    assert np.array_equal(back.mesh.points, SQ3[:4, :2]) and back.mesh.area == pytest.approx(1.0)
    tilted = SQ3[:4].copy()
    tilted[:, 2] = tilted[:, 0]
    with pytest.raises(ValueError, match=r"not planar: z varies from 0 to 1; the body must lie in a plane"):
        read_mesh(_write_raw(tmp_path / "tilt.vtu", tilted, [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]))


def test_read_names_an_out_of_plane_displacement(tmp_path):
    u = np.zeros((4, 3))
    u[1, 2] = 0.5
    p = _write_raw(tmp_path / "uz.vtu", SQ3[:4], [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))],
                   {"displacement": u})
    with pytest.raises(ValueError, match=r"'displacement' moves nodes out of the plane"):
        read_mesh(p)


def test_write_onto_a_directory_is_refused_and_leaves_nothing(tmp_path, body):
    mesh, x = body
    target = tmp_path / "out.vtu"
    target.mkdir()
    with pytest.raises(ValueError, match=r"out\.vtu: it is a directory"):
        write_mesh(target, mesh, x=x)
    with pytest.raises(ValueError, match="it is a directory"):
        write_mesh(tmp_path, mesh, x=x)  # no extension: still named as a directory, not as a format
    (tmp_path / "afile").write_text("")
    with pytest.raises(ValueError, match=r"afile is a file, not a directory"):
        write_mesh(tmp_path / "afile" / "sub" / "m.vtu", mesh)
    assert sorted(os.listdir(tmp_path)) == ["afile", "out.vtu"]
    assert os.listdir(target) == []


def test_interrupted_write_leaves_no_temporary_file(tmp_path, body, monkeypatch):
    import meshio

    mesh, x = body

    def interrupted(path, *args, **kwargs):
        with open(path, "wb") as fh:
            fh.write(b"<VTKFile partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(meshio, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_mesh(tmp_path / "m.vtu", mesh, x=x)
    assert os.listdir(tmp_path) == []


def test_failing_rename_leaves_no_temporary_file(tmp_path):
    from mdsr_opt.body.io import atomic_path

    target = tmp_path / "r.json"
    with pytest.raises(OSError):
        with atomic_path(target) as tmp:
            with open(tmp, "w") as fh:
                fh.write("{}")
            target.mkdir()  # the target turns into a directory before the rename
            (target / "keep").write_text("")
    assert os.listdir(tmp_path) == ["r.json"] and os.listdir(target) == ["keep"]


# ------------------------------------------------------------------------------------ data names
#: names each format writes and reads back unchanged
KEPT = {
    ".vtk": ["weight_1", "a'b", "a>b", "Dehnung_é", "応力", "a/b:c"],
    ".vtu": ["a b", " lead", "a'b", "a>b", "Dehnung_é", "応力", "a\u2028b"],
    ".xdmf": ["a<b&c\"d", "a b", "a'b", "Dehnung_é", "応力", "a]]>b"],
    ".msh": ["a<b&c", "a b", "a'b", "Dehnung_é", "応力"],
}
#: names each format cannot carry, with what the message says
REFUSED = {
    ".vtk": [("a b", r"holds ' ': a \.vtk file cannot carry whitespace .* or write \.vtu, \.xdmf, \.msh"),
             ("a\u00a0b", r"holds '\\xa0': a \.vtk file cannot carry whitespace")],
    ".vtu": [("a<b", r"holds '<': a \.vtu file cannot carry '<', '&' or '\"' .* or write \.vtk, \.xdmf, \.msh"),
             ("a&b", r"holds '&'"), ('a"b', r"holds '\"'.*or write \.vtk, \.xdmf$")],
    ".xdmf": [],
    ".msh": [('a"b', r"holds '\"': a \.msh file cannot carry '\"' .* or write \.vtk, \.xdmf$")],
}


@pytest.mark.parametrize("ext", [".vtk", ".vtu", ".xdmf", ".msh"])
def test_data_names_round_trip_or_are_refused_at_the_door(tmp_path, body, ext):
    """meshio writes VTU names into XML attributes unescaped ('<', '&', '"' make the file unreadable), Gmsh
    names between quotes ('"' is dropped) and VTK names as words (whitespace splits them): each writer takes
    exactly the names its format gives back, and refuses the rest before writing anything."""
    mesh, x = body
    names = KEPT[ext]
    pdata = {n: np.arange(mesh.n_nodes, dtype=float) + k for k, n in enumerate(names)}
    cdata = {n: np.arange(mesh.n_triangles, dtype=float) - k for k, n in enumerate(names)}
    back = read_mesh(write_mesh(tmp_path / f"m{ext}", mesh, x=x, point_data=pdata, cell_data=cdata))
    assert set(names) <= set(back.point_data) and set(names) <= set(back.cell_data)
    for k, n in enumerate(names):
        np.testing.assert_array_equal(back.point_data[n], np.arange(mesh.n_nodes) + k)
        np.testing.assert_array_equal(back.cell_data[n], np.arange(mesh.n_triangles) - k)
    common = [("a\x01b", r"holds the control character '\\x01', which no mesh format keeps"),
              ("a\tb", r"holds the control character '\\t'"), ("a\nb", r"holds the control character '\\n'"),
              ("", "empty name"), ("gmsh:tag", r"names starting with 'gmsh:' are Gmsh's own tags")]
    for name, match in REFUSED[ext] + common:
        for data in ("point_data", "cell_data"):
            n = mesh.n_nodes if data == "point_data" else mesh.n_triangles
            with pytest.raises(ValueError, match=rf"{data}\[{re.escape(repr(name))}\]:? {match}"
                               if name else rf"{data} has an empty name"):
                write_mesh(tmp_path / f"bad{ext}", mesh, **{data: {name: np.zeros(n)}})
    assert sorted(os.listdir(tmp_path)) == [f"m{ext}"]  # nothing written by the refusals


def test_data_names_clashing_with_written_fields_or_not_strings_are_refused(tmp_path, body):
    mesh, x = body
    mat = NeoHookean(1.0, 0.3)
    with pytest.raises(ValueError, match=r"point_data\['displacement'\] would overwrite the 'displacement'"):
        write_mesh(tmp_path / "a.vtu", mesh, x=x, point_data={"displacement": np.zeros((mesh.n_nodes, 2))})
    with pytest.raises(ValueError, match=r"cell_data\['energy_density'\] would overwrite"):
        write_mesh(tmp_path / "a.vtu", mesh, x=x, material=mat, cell_data={"energy_density": np.zeros(mesh.n_triangles)})
    with pytest.raises(TypeError, match=r"point_data names must be strings, got int 3"):
        write_mesh(tmp_path / "a.vtu", mesh, point_data={3: np.zeros(mesh.n_nodes)})
    assert os.listdir(tmp_path) == []
    # without a state, 'displacement' is the state itself (read back as x), and 'J' is free
    u = np.full((mesh.n_nodes, 2), 0.25)
    back = read_mesh(write_mesh(tmp_path / "u.vtu", mesh, point_data={"displacement": u},
                                cell_data={"J": np.ones(mesh.n_triangles)}))
    np.testing.assert_allclose(back.x, mesh.points + 0.25, atol=1e-12)
    np.testing.assert_array_equal(back.cell_data["J"], 1.0)
