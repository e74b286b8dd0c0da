"""Tests of the formats CAD/BIM tools write (iat.io.load with iat.io.dae, ifc, obj, gltf_primitives):
COLLADA, IFC, glTF triangle fans and strips, Draco, glTF 1.0, malformed accessors, UTF-16 OBJ,
concave and keyhole OBJ n-gons; and every new bad file is one line on the command line, exit 2.

Every model is written by the test itself (pycollada, ifcopenshell.api, pygltflib, DracoPy, text).
"""

from __future__ import annotations

import json
import logging
import sys

import numpy as np
import pygltflib
import pytest

from iat.io.load import load_scene
from tests.support.scene_files import QUAD, QUAD_TRIS, Gltf, assert_load_error, write


def _area(scene) -> float:
    return float(scene.patch_area.sum())


# -- COLLADA -----------------------------------------------------------------------------------------
def _collada_room(path, up_axis="Y_UP"):
    """A floor (4 x 3 m), a back wall (4 x 2.5 m) and an emissive ceiling panel (1 x 1 m, facing
    down) as three quads of a polylist in a node translated by (0, 1, 0); two materials."""
    import collada
    from collada import asset, geometry, material, scene, source

    c = collada.Collada()
    c.assetInfo.upaxis = getattr(asset.UP_AXIS, up_axis)
    plaster = material.Effect("plaster-fx", [], "lambert", diffuse=(0.8, 0.7, 0.6), emission=(0, 0, 0))
    lamp = material.Effect("lamp-fx", [], "lambert", diffuse=(0.1, 0.1, 0.1), emission=(5.0, 4.0, 3.0))
    mats = [material.Material("plaster", "plaster", plaster), material.Material("lamp", "lamp", lamp)]
    c.effects.extend([plaster, lamp])
    c.materials.extend(mats)
    walls = np.array(
        [[0, 0, 0], [0, 0, 3], [4, 0, 3], [4, 0, 0], [0, 0, 0], [4, 0, 0], [4, 2.5, 0], [0, 2.5, 0]], float
    )  # floor (+Y), back wall (+Z)
    light = np.array([[1.5, 2.4, 1], [2.5, 2.4, 1], [2.5, 2.4, 2], [1.5, 2.4, 2]], float)  # faces -Y
    geoms = []
    for name, verts, symbol in (("walls", walls, "plaster-ref"), ("light", light, "lamp-ref")):
        src = source.FloatSource(f"{name}-pos", verts.ravel(), ("X", "Y", "Z"))
        g = geometry.Geometry(c, f"{name}-geom", name, [src])
        inputs = source.InputList()
        inputs.addInput(0, "VERTEX", f"#{name}-pos")
        n = len(verts) // 4
        g.primitives.append(g.createPolylist(np.arange(len(verts)), np.full(n, 4), inputs, symbol))
        c.geometries.append(g)
        geoms.append(g)
    nodes = [
        scene.GeometryNode(geoms[0], [scene.MaterialNode("plaster-ref", mats[0], inputs=[])]),
        scene.GeometryNode(geoms[1], [scene.MaterialNode("lamp-ref", mats[1], inputs=[])]),
    ]
    root = scene.Node("room", children=nodes, transforms=[scene.TranslateTransform(0, 1, 0)])
    c.scenes.append(scene.Scene("s", [root]))
    c.scene = c.scenes[0]
    c.write(str(path))
    return path


def test_collada_room_loads_with_materials_transform_and_area(tmp_path):
    s = load_scene(_collada_room(tmp_path / "room.dae"))
    assert s.n_patches == 3 and s.patch_is_quad.all()
    assert _area(s) == pytest.approx(12 + 10 + 1, rel=1e-9)
    assert len(s.materials) == 2
    emissive = s.patch_emission.any(axis=1)
    assert emissive.sum() == 1
    np.testing.assert_allclose(s.patch_emission[emissive][0], [5, 4, 3])
    np.testing.assert_allclose(
        s.patch_albedo[~emissive], [[0.8, 0.7, 0.6]] * 2, atol=0.51 / 255
    )  # trimesh: uint8
    np.testing.assert_allclose(s.bounds, [[0, 1, 0], [4, 3.5, 3]])  # the node's translation applied
    normals = s.patch_normal
    np.testing.assert_allclose(normals[emissive][0], [0, -1, 0], atol=1e-12)


def test_collada_z_up_is_turned_to_y_up(tmp_path):
    s = load_scene(_collada_room(tmp_path / "zup.dae", up_axis="Z_UP"))
    np.testing.assert_allclose(s.bounds, [[0, 0, -3.5], [4, 3, -1]], atol=1e-12)  # (x, y, z) -> (x, z, -y)
    assert _area(s) == pytest.approx(23, rel=1e-9)


def test_collada_zipped_zae_loads(tmp_path):
    import zipfile

    dae = _collada_room(tmp_path / "room.dae")
    zae = tmp_path / "room.zae"
    with zipfile.ZipFile(zae, "w") as z:
        z.write(dae, "room.dae")
        z.writestr("manifest.xml", "<dae_root>room.dae</dae_root>")
    assert load_scene(zae).n_patches == 3


# -- IFC ---------------------------------------------------------------------------------------------
def _ifc_building(path):
    """IFC4 in metres: a 5 m and a 4 m wall (3 m high, 0.2 m thick, plaster), a 1 x 1 m opening
    voiding the first, a 10 x 5 x 0.2 m slab (concrete) and a glass plate of transparency 0.8."""
    import ifcopenshell.api.aggregate
    import ifcopenshell.api.context
    import ifcopenshell.api.feature
    import ifcopenshell.api.geometry
    import ifcopenshell.api.project
    import ifcopenshell.api.root
    import ifcopenshell.api.spatial
    import ifcopenshell.api.style
    import ifcopenshell.api.unit

    api = ifcopenshell.api
    f = api.project.create_file(version="IFC4")
    project = api.root.create_entity(f, ifc_class="IfcProject", name="P")
    api.unit.assign_unit(f, units=[api.unit.add_si_unit(f, unit_type="LENGTHUNIT")])
    model = api.context.add_context(f, context_type="Model")
    body = api.context.add_context(
        f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
    )
    parent = project
    storey = None
    for cls in ("IfcSite", "IfcBuilding", "IfcBuildingStorey"):
        storey = api.root.create_entity(f, ifc_class=cls, name=cls)
        api.aggregate.assign_object(f, relating_object=parent, products=[storey])
        parent = storey

    def style(name, rgb, transparency=0.0):
        s = api.style.add_style(f, name=name)
        colour = {"Name": None, "Red": rgb[0], "Green": rgb[1], "Blue": rgb[2]}
        api.style.add_surface_style(
            f, style=s, attributes={"SurfaceColour": colour, "Transparency": transparency}
        )
        return s

    def product(cls, rep, st, x=0.0, z=0.0, contained=True):
        p = api.root.create_entity(f, ifc_class=cls, name=cls)
        api.geometry.assign_representation(f, product=p, representation=rep)
        m = np.eye(4)
        m[0, 3], m[2, 3] = x, z
        api.geometry.edit_object_placement(f, product=p, matrix=m)
        if contained:
            api.spatial.assign_container(f, relating_structure=storey, products=[p])
        if st is not None:
            api.style.assign_representation_styles(f, shape_representation=rep, styles=[st])
        return p

    def box(length, height, thickness):
        return api.geometry.add_wall_representation(
            f, context=body, length=length, height=height, thickness=thickness
        )

    plaster = style("plaster", (0.8, 0.7, 0.6))
    wall = product("IfcWall", box(5.0, 3.0, 0.2), plaster)
    product("IfcWall", box(4.0, 3.0, 0.2), plaster, x=6.0)
    opening = product("IfcOpeningElement", box(1.0, 1.0, 0.2), None, x=2.0, z=1.0, contained=False)
    api.feature.add_feature(f, feature=opening, element=wall)
    slab = api.geometry.add_slab_representation(
        f, context=body, depth=0.2, polyline=[(0, 0), (10, 0), (10, 5), (0, 5)]
    )
    product("IfcSlab", slab, style("concrete", (0.5, 0.5, 0.5)))
    product("IfcPlate", box(1.0, 1.0, 0.01), style("pane", (0.2, 0.3, 0.4), 0.8), x=2.0, z=1.0)
    f.write(str(path))
    return path


def _box_area(a, b, c):
    return 2 * (a * b + b * c + c * a)


def test_ifc_building_loads_y_up_with_opening_and_styles(tmp_path):
    pytest.importorskip("ifcopenshell", reason="ifcopenshell (the 'ifc' extra) is not installed")
    calls = []
    s = load_scene(_ifc_building(tmp_path / "b.ifc"), progress=lambda f, m: calls.append(f) or True)
    V = s.vertices
    assert np.isfinite(V).all()
    names = [m.name for m in s.materials]
    assert set(names) == {"plaster", "concrete", "glass: pane (transparency 0.8)"}, names
    by = {m.name: i for i, m in enumerate(s.materials)}
    np.testing.assert_allclose(s.materials[by["plaster"]].albedo, [0.8, 0.7, 0.6])
    np.testing.assert_allclose(s.materials[by["concrete"]].albedo, [0.5, 0.5, 0.5])
    area = {name: float(s.patch_area[s.patch_material == i].sum()) for name, i in by.items()}
    # walls: two boxes, less the opening's two faces, plus its four reveals (1 m x 0.2 m)
    walls = _box_area(5, 3, 0.2) + _box_area(4, 3, 0.2) - 2 * 1.0 + 4 * 1.0 * 0.2
    assert area["plaster"] == pytest.approx(walls, rel=0.01)
    assert area["concrete"] == pytest.approx(_box_area(10, 5, 0.2), rel=0.01)
    # Y up: the slab (z 0 to 0.2 in the file) has its top, 50 m^2, facing +Y at y = 0.2
    slab = s.patch_material == by["concrete"]
    up = s.patch_normal[slab][:, 1] > 1 - 1e-9
    assert float(s.patch_area[slab][up].sum()) == pytest.approx(50, rel=1e-9)
    top = s.corner_positions[slab][up]
    np.testing.assert_allclose(top[..., 1], 0.2, atol=1e-9)
    np.testing.assert_allclose(s.bounds, [[0, 0, -5], [10, 3, 0]], atol=1e-9)  # file y -> -z
    assert calls == sorted(calls) and calls[0] == 0.0 and calls[-1] == 1.0
    assert len(calls) >= 8


def test_ifc_without_ifcopenshell_names_the_extra(tmp_path, monkeypatch):
    p = write(tmp_path / "m.ifc", "ISO-10303-21;\nEND-ISO-10303-21;\n")
    monkeypatch.setitem(sys.modules, "ifcopenshell", None)
    assert_load_error(p, "reading IFC needs ifcopenshell: pip install 'iat[ifc]'")


# -- glTF: fans, strips, Draco, versions, accessors -------------------------------------------------
def _gltf_quad(path, mode, indexed, draco=None):
    """One quad as a single primitive of ``mode`` (5 strip, 6 fan), indexed or not; with ``draco``
    (bytes) the primitive is KHR_draco_mesh_compression of those bytes instead."""
    if mode == 5:
        V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    else:
        V = QUAD.astype(np.float32)
    blob = bytearray(V.tobytes() if draco is None else draco)
    blob += b"\0" * (-len(blob) % 4)
    views = [pygltflib.BufferView(buffer=0, byteOffset=0, byteLength=len(blob))]
    acc = [
        pygltflib.Accessor(
            bufferView=0 if draco is None else None,
            componentType=pygltflib.FLOAT,
            count=4,
            type="VEC3",
            min=V.min(0).tolist(),
            max=V.max(0).tolist(),
        )
    ]
    prim = pygltflib.Primitive(attributes=pygltflib.Attributes(POSITION=0), mode=mode)
    if indexed:
        idx = np.arange(4, dtype=np.uint16).tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(idx)))
        blob += idx + b"\0" * (-len(idx) % 4)
        acc.append(
            pygltflib.Accessor(bufferView=1, componentType=pygltflib.UNSIGNED_SHORT, count=4, type="SCALAR")
        )
        prim.indices = 1
    doc = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0"),
        scenes=[pygltflib.Scene(nodes=[0])],
        scene=0,
        nodes=[pygltflib.Node(mesh=0)],
        meshes=[pygltflib.Mesh(primitives=[prim])],
        accessors=acc,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
    )
    doc.set_binary_blob(bytes(blob))
    doc.save_binary(str(path))
    return path


@pytest.mark.parametrize("mode", [5, 6], ids=["strip", "fan"])
@pytest.mark.parametrize("indexed", [False, True], ids=["plain", "indexed"])
def test_gltf_triangle_strips_and_fans_load_as_one_quad(tmp_path, mode, indexed):
    s = load_scene(_gltf_quad(tmp_path / "q.glb", mode, indexed))
    assert s.n_patches == 1 and s.patch_is_quad.all()
    assert _area(s) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)


def _draco_glb(path, V, F):
    """A GLB whose one primitive is the Draco encoding of (V, F) (KHR_draco_mesh_compression)."""
    import DracoPy

    data = DracoPy.encode(V, F, quantization_bits=14)
    uid = next(a["unique_id"] for a in DracoPy.decode(data).attributes if a["attribute_type"] == 0)
    blob = data + b"\0" * (-len(data) % 4)
    ext = "KHR_draco_mesh_compression"
    doc = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0"),
        scenes=[pygltflib.Scene(nodes=[0])],
        scene=0,
        nodes=[pygltflib.Node(mesh=0)],
        extensionsUsed=[ext],
        extensionsRequired=[ext],
        meshes=[
            pygltflib.Mesh(
                primitives=[
                    pygltflib.Primitive(
                        attributes=pygltflib.Attributes(POSITION=0),
                        indices=1,
                        extensions={ext: {"bufferView": 0, "attributes": {"POSITION": uid}}},
                    )
                ]
            )
        ],
        accessors=[
            pygltflib.Accessor(
                componentType=pygltflib.FLOAT,
                count=len(V),
                type="VEC3",
                min=V.min(0).tolist(),
                max=V.max(0).tolist(),
            ),
            pygltflib.Accessor(componentType=pygltflib.UNSIGNED_INT, count=F.size, type="SCALAR"),
        ],
        bufferViews=[pygltflib.BufferView(buffer=0, byteOffset=0, byteLength=len(data))],
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
    )
    doc.set_binary_blob(blob)
    doc.save_binary(str(path))
    return path


def _grid(n=4):
    """An n x n grid of unit quads on z = 0 (2 n^2 triangles) and a tent roof above it."""
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    V = np.c_[x.ravel(), y.ravel(), 0.1 * x.ravel() * (n - x.ravel())]
    i = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    F = np.r_[np.c_[i, i + 1, i + n + 2], np.c_[i, i + n + 2, i + n + 1]]
    return V, F


def test_draco_gltf_loads_like_the_uncompressed_mesh(tmp_path, caplog):
    pytest.importorskip("DracoPy")
    V, F = _grid()
    plain = Gltf()
    plain.node(mesh=plain.mesh(V, F))
    ref = load_scene(plain.save(tmp_path / "plain.glb"))
    with caplog.at_level(logging.INFO):
        s = load_scene(_draco_glb(tmp_path / "draco.glb", V, F))
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert s.n_patches == ref.n_patches and len(F) == 32
    assert _area(s) == pytest.approx(_area(ref), rel=1e-3)  # 14-bit quantisation over 4 m
    np.testing.assert_allclose(np.sort(s.patch_area), np.sort(ref.patch_area), rtol=2e-3)
    np.testing.assert_allclose(s.bounds, ref.bounds, atol=1e-3)


def test_draco_without_dracopy_names_it(tmp_path, monkeypatch):
    pytest.importorskip("DracoPy")
    p = _draco_glb(tmp_path / "d.glb", *_grid(1))
    monkeypatch.setitem(sys.modules, "DracoPy", None)
    assert_load_error(p, "Draco-compressed (KHR_draco_mesh_compression): pip install DracoPy")


def _gltf1(path, asset=True):
    doc = {"meshes": {"m": {"primitives": [{"attributes": {"POSITION": "a"}}]}}, "accessors": {"a": {}}}
    if asset:
        doc["asset"] = {"version": "1.0"}
    return write(path, json.dumps(doc))


def _gltf_version(path, version):
    return write(path, json.dumps({"asset": {"version": version}, "meshes": []}))


def _malformed_uv(path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, uv=QUAD[:3, :2]))
    return g.save(path)


def _malformed_extent(path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS))
    g.doc.accessors[0].count = 10
    return g.save(path)


def _malformed_index(path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, [[0, 1, 2], [2, 3, 9]]))
    return g.save(path)


def _points_only(path, mode):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, [0, 1, 2, 3]))
    g.doc.meshes[0].primitives[0].mode = mode
    return g.save(path)


def _obj_text(path, text, encoding, bom=b""):
    path.write_bytes(bom + text.encode(encoding))
    return path


OBJ_QUAD = "# caf\u00e9 \u2603\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"


@pytest.mark.parametrize(
    "encoding, bom",
    [("utf-16-le", b"\xff\xfe"), ("utf-16-be", b"\xfe\xff"), ("utf-8", b"\xef\xbb\xbf")],
    ids=["utf16le", "utf16be", "utf8bom"],
)
def test_obj_in_utf16_and_utf8_with_bom_loads(tmp_path, encoding, bom):
    s = load_scene(_obj_text(tmp_path / "u.obj", OBJ_QUAD.replace("\n", "\r\n"), encoding, bom))
    assert s.n_patches == 1 and _area(s) == pytest.approx(1.0)


# -- OBJ n-gons -------------------------------------------------------------------------------------
def _polygon_area(P):
    """Shoelace area of a polygon (n, 2)."""
    x, y = P[:, 0], P[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def test_obj_keyhole_annulus_keeps_its_hole(tmp_path):
    """One face: outer circle (33 points), bridge, inner circle (33 points, reversed), back along
    the bridge. trimesh's fan fills the hole (a disk of 3.1 m^2)."""
    t = np.linspace(0, 2 * np.pi, 33, endpoint=False)
    outer = np.c_[np.cos(t), np.sin(t)]
    inner = 0.5 * outer[::-1]
    ring = np.r_[outer, inner]
    lines = [f"v {x:.17g} {y:.17g} 0" for x, y in ring]
    corners = [*range(1, 34), 1, 34, *range(35, 67), 34]  # the bridge: 1 -> 34 and back
    lines.append("f " + " ".join(map(str, corners)))
    s = load_scene(write(tmp_path / "annulus.obj", "\n".join(lines) + "\n"))
    expected = _polygon_area(outer) - _polygon_area(inner)
    assert abs(_area(s) / expected - 1) < 1e-9, (_area(s), expected)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (s.n_patches, 1)), atol=1e-9)


def test_obj_concave_l_hexagon_is_exact_with_uvs_and_negative_indices(tmp_path):
    L = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    text = "".join(f"v {x} 0 {-y}\nvt {x / 2} {y / 2}\n" for x, y in L)  # in the y = 0 plane, facing +Y
    text += "vn 0 1 0\nf " + " ".join(f"{i}/{i}/1" for i in range(-6, 0)) + "\n"
    s = load_scene(write(tmp_path / "L.obj", text))
    assert _area(s) == pytest.approx(3.0, rel=1e-12)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 1.0, 0], (s.n_patches, 1)), atol=1e-12)


def test_obj_non_convex_quad_is_not_fanned_through_its_reflex_corner(tmp_path):
    text = "v 0 0 0\nv 2 0 0\nv 1 1 0\nv 1 3 0\nf 2 3 4 1\n"  # reflex at corner 3 (index 2 of the face)
    s = load_scene(write(tmp_path / "dart.obj", text))
    assert _area(s) == pytest.approx(_polygon_area(np.array([[2, 0], [1, 1], [1, 3], [0, 0.0]])), rel=1e-12)


def test_obj_self_intersecting_polygon_falls_back_to_a_fan_with_a_warning(tmp_path, caplog):
    text = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 3 1 0\nf 1 2 4 3 5\n"
    with caplog.at_level(logging.WARNING):
        load_scene(write(tmp_path / "x.obj", text))
    assert any("self-intersecting" in r.getMessage() for r in caplog.records)


# -- bad files: one line, exit 2 ---------------------------------------------------------------------
IFC_HEADER = (
    "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('ViewDefinition [CoordinationView]'),'2;1');\n"
    "FILE_NAME('e.ifc','2024-01-01T00:00:00',(''),(''),'','','');\nFILE_SCHEMA(('IFC4'));\nENDSEC;\n"
)
BAD_FILES = {
    "gltf1.gltf": (lambda p: _gltf1(p), "glTF 1.0 is not supported (this IAT reads glTF 2.0); convert it"),
    "gltf1_no_asset.gltf": (lambda p: _gltf1(p, asset=False), "glTF 1.0 is not supported"),
    "gltf3.gltf": (lambda p: _gltf_version(p, "3.0"), "glTF version 3.0 is not supported"),
    "uv_count.glb": (
        _malformed_uv,
        "malformed glTF: mesh 0 primitive 0: TEXCOORD_0 has 3 elements, POSITION has 4",
    ),
    "beyond_view.glb": (
        _malformed_extent,
        "malformed glTF: accessor 0 (POSITION of mesh 0 primitive 0) needs 120 bytes of buffer view 0, "
        "which has 48",
    ),
    "index_range.glb": (_malformed_index, "malformed glTF: mesh 0 primitive 0: face index out of range (9, "),
    "points.glb": (lambda p: _points_only(p, 0), "no triangles (point cloud only)"),
    "lines.glb": (lambda p: _points_only(p, 1), "no triangles (lines only)"),
    "truncated.ifc": (
        lambda p: write(p, "ISO-10303-21;\nHEADER;\nFILE_SCHEMA(('IFC4'));\nENDSEC;\nDATA;\n#1=IFCWALL("),
        "cannot read IFC file (truncated file): no END-ISO-10303-21 at the end",
    ),
    "junk.ifc": (lambda p: write(p, "hello, not an IFC file\n"), "not an IFC-SPF file"),
    "empty_model.ifc": (
        lambda p: write(p, IFC_HEADER + "DATA;\nENDSEC;\nEND-ISO-10303-21;\n"),
        "no triangles (no IFC element with geometry)",
    ),
    "utf16_junk.obj": (
        lambda p: p.write_bytes(b"\xff\xfe" + b"\x00\xd8v 0") or p,  # an unpaired surrogate
        "cannot read OBJ file (utf-16-le with a BOM)",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_new_bad_files_are_one_line_and_exit_2(tmp_path, name, capsys, caplog, monkeypatch):
    from iat.cli.commands import main

    if name.endswith(".ifc"):
        pytest.importorskip("ifcopenshell")
    make, words = BAD_FILES[name]
    path = tmp_path / name
    make(path)
    capsys.readouterr()
    rc = main(["info", str(path)])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(err) == 1, err
    assert err[0].startswith(f"iat info: error: {path}: "), err
    assert words in err[0], err
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.parametrize("missing", ["DracoPy", "ifcopenshell"])
def test_missing_optional_readers_are_one_line_and_exit_2(tmp_path, missing, capsys, monkeypatch):
    from iat.cli.commands import main

    pytest.importorskip("DracoPy")
    if missing == "DracoPy":
        path, words = _draco_glb(tmp_path / "d.glb", *_grid(1)), "pip install DracoPy"
    else:
        path = write(tmp_path / "m.ifc", "ISO-10303-21;\nEND-ISO-10303-21;\n")
        words = "reading IFC needs ifcopenshell: pip install 'iat[ifc]'"
    monkeypatch.setitem(sys.modules, missing, None)
    capsys.readouterr()
    rc = main(["info", str(path)])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert (
        rc == 2 and len(err) == 1 and err[0].startswith(f"iat info: error: {path}: ") and words in err[0]
    ), err
