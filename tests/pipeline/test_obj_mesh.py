"""``pipeline.io.obj_mesh.read_obj_mesh``: the one OBJ mesh reader of the tiling's base surface and the btf
method's ``--set mesh``, against meshes written here whose answers are known by construction."""
import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.io.obj_mesh import read_obj_mesh

# two triangles of a unit quad (a polygon, fanned), uv split at one corner, a normal per corner
QUAD = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
vn 0 0 1
vn 0 1 1
f 1/1/1 2/2/1 3/3/2 4/4/1
f 1/5/2 3/3/1 4/4/1
"""


def _write(tmp_path, text, name="m.obj"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_vertices_split_where_uv_differ_and_normals_are_the_corner_means(tmp_path):
    m = read_obj_mesh(_write(tmp_path, QUAD), "cfg.toml", normals=True)
    # corners (v, vt) in first-seen order: (1,1) (2,2) (3,3) (1,3)... fanned: 1-2-3, 1-3-4, then 1/5-3-4
    assert m.F.tolist() == [[0, 1, 2], [0, 2, 3], [4, 2, 3]]
    assert m.V.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]]
    assert m.UV.tolist() == [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]]
    # vertex (3, vt 3) is a corner of three triangles: normals 2, 2 (first face fanned twice) and 1
    want = np.array([0.0, 2.0, 2.0]) + np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(m.N[2], want / np.linalg.norm(want), rtol=0, atol=1e-15)
    np.testing.assert_allclose(m.N[4], np.array([0, 1, 1]) / np.sqrt(2.0), atol=1e-15)
    assert np.allclose(np.linalg.norm(m.N, axis=1), 1.0)
    # without normals asked for: the same mesh, no N
    plain = read_obj_mesh(_write(tmp_path, QUAD), "cfg.toml")
    assert plain.N is None and np.array_equal(plain.F, m.F) and np.array_equal(plain.V, m.V)


def test_a_corner_without_a_normal_leaves_the_mesh_without_normals(tmp_path):
    text = QUAD.replace("f 1/5/2 3/3/1 4/4/1", "f 1/5 3/3/1 4/4/1")
    m = read_obj_mesh(_write(tmp_path, text), "cfg.toml", normals=True)
    assert m.N is None and len(m.F) == 3


def test_bad_normals_are_refused_only_when_normals_are_read(tmp_path):
    p = _write(tmp_path, QUAD.replace("vn 0 1 1", "vn 0 one 1"))
    with pytest.raises(LoomError) as e:
        read_obj_mesh(p, "cfg.toml", normals=True)
    assert e.value.place == "line 11" and "unreadable normal" in e.value.message
    assert read_obj_mesh(p, "cfg.toml").N is None       # the tiling reads no normals: the line is ignored
    p = _write(tmp_path, QUAD.replace("3/3/2 4/4/1\n", "3/3/7 4/4/1\n"), "range.obj")
    with pytest.raises(LoomError) as e:
        read_obj_mesh(p, "cfg.toml", normals=True)
    assert e.value.place == "line 12" and e.value.message == "face normal index out of range"


def test_missing_uv_is_refused_naming_who_needs_it(tmp_path):
    p = _write(tmp_path, QUAD.replace("f 1/5/2", "f 1//2"))
    with pytest.raises(LoomError) as e:
        read_obj_mesh(p, "cfg.toml", uv_for="the btf method places its texture by the mesh's uv")
    assert e.value.place == "line 13"
    assert e.value.message == ("face corner without a texture coordinate (v/vt): the btf method places its "
                               "texture by the mesh's uv")
    p = _write(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "nouv.obj")
    with pytest.raises(LoomError, match="shell mapping needs uv"):
        read_obj_mesh(p, "cfg.toml")


def test_without_uv_faces_index_the_files_vertices(tmp_path):
    """``uv_for=None`` (a scene's meshes): corners ``v``, ``v/vt``, ``v//vn`` and negative indices all name the
    file's own vertices (no split where uv differ: the quad above keeps 4 vertices), UV is None, a polygon is
    fanned; a vertex line short of a coordinate or not finite is refused by its line, a missing file by the key."""
    m = read_obj_mesh(_write(tmp_path, QUAD), "cfg.toml", uv_for=None)
    assert m.UV is None and len(m.V) == 4 and len(m.F) == 3
    np.testing.assert_array_equal(m.V[m.F[0]], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    text = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nf 1//1 2 -2/7 -1\n"
    m = read_obj_mesh(_write(tmp_path, text), "cfg.toml", uv_for=None)
    np.testing.assert_array_equal(m.V[m.F], [[[0, 0, 0], [2, 0, 0], [2, 2, 0]], [[0, 0, 0], [2, 2, 0], [0, 2, 0]]])
    for bad, line in (("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "line 2"), ("v 0 0 0\nv 1 0 nan\nf 1 2 1\n", "line 2")):
        with pytest.raises(LoomError, match=line):
            read_obj_mesh(_write(tmp_path, bad), "cfg.toml", uv_for=None)
    with pytest.raises(LoomError) as e:
        read_obj_mesh(tmp_path / "none.obj", "scene.toml", uv_for=None, place="meshes[2].file")
    assert e.value.file == "scene.toml" and e.value.place == "meshes[2].file"
