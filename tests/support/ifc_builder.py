"""The ifcopenshell.api calls the test models need (:class:`IfcBuilder`), and prisms for them.

Deterministic: GlobalIds from the entity order, relationships' members sorted, a fixed time stamp.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np


class IfcBuilder:
    """The ifcopenshell.api calls of a building, on one IFC4 file (storeys made on demand)."""

    def __init__(self, name: str):
        import ifcopenshell
        import ifcopenshell.api

        self.run = ifcopenshell.api.run
        self.f = ifcopenshell.file(schema="IFC4")
        run, f = self.run, self.f
        project = run("root.create_entity", f, ifc_class="IfcProject", name=name)
        metre = run("unit.add_si_unit", f, unit_type="LENGTHUNIT")
        run("unit.assign_unit", f, units=[metre])
        model = run("context.add_context", f, context_type="Model")
        self.body = run(
            "context.add_context",
            f,
            context_type="Model",
            context_identifier="Body",
            target_view="MODEL_VIEW",
            parent=model,
        )
        site = run("root.create_entity", f, ifc_class="IfcSite", name="site")
        self.building = run("root.create_entity", f, ifc_class="IfcBuilding", name="house")
        run("aggregate.assign_object", f, products=[site], relating_object=project)
        run("aggregate.assign_object", f, products=[self.building], relating_object=site)
        self.storeys: list = []
        self.styles: dict[str, object] = {}

    def storey(self, k: int):
        while len(self.storeys) <= k:
            st = self.run(
                "root.create_entity",
                self.f,
                ifc_class="IfcBuildingStorey",
                name=f"storey {len(self.storeys)}",
            )
            self.run("aggregate.assign_object", self.f, products=[st], relating_object=self.building)
            self.storeys.append(st)
        return self.storeys[k]

    def style(self, name: str, rgb) -> object:
        if name not in self.styles:
            st = self.run("style.add_style", self.f, name=name)
            r, g, b = (float(c) for c in rgb)
            self.run(
                "style.add_surface_style",
                self.f,
                style=st,
                ifc_class="IfcSurfaceStyleShading",
                attributes={"SurfaceColour": {"Name": None, "Red": r, "Green": g, "Blue": b}},
            )
            self.styles[name] = st
        return self.styles[name]

    def place(self, el, xyz, rot_deg: float = 0.0) -> None:
        c, s = np.cos(np.radians(rot_deg)), np.sin(np.radians(rot_deg))
        m = np.eye(4)
        m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        m[:3, 3] = xyz
        self.run("geometry.edit_object_placement", self.f, product=el, matrix=m)

    def product(self, ifc_class, name, rep, xyz, rot_deg=0.0, style=None, predefined=None, storey=None):
        kw = {"predefined_type": predefined} if predefined else {}
        el = self.run("root.create_entity", self.f, ifc_class=ifc_class, name=name, **kw)
        if storey is not None:
            self.run(
                "spatial.assign_container", self.f, products=[el], relating_structure=self.storey(storey)
            )
        self.place(el, xyz, rot_deg)
        self.run("geometry.assign_representation", self.f, product=el, representation=rep)
        if style is not None:
            self.run("style.assign_representation_styles", self.f, shape_representation=rep, styles=[style])
        return el

    def box_rep(self, length: float, height: float, thickness: float):
        """A box: ``length`` along local x, ``thickness`` along local +y, ``height`` up."""
        return self.run(
            "geometry.add_wall_representation",
            self.f,
            context=self.body,
            length=float(length),
            height=float(height),
            thickness=float(thickness),
        )

    def void(self, element, name, xyz, rot_deg, length, height, thickness) -> None:
        op = self.product("IfcOpeningElement", name, self.box_rep(length, height, thickness), xyz, rot_deg)
        self.run("feature.add_feature", self.f, feature=op, element=element)

    def wall(self, name, storey, start, end, z, height, thickness, style, openings=()):
        """A wall from ``start`` to ``end`` (x, y) at height ``z``, its thickness to the left of that
        axis (as the kernel extrudes it); ``openings`` are ``(u0, u1, z0, z1)``
        along it, voided with IfcOpeningElements."""
        start, end = np.asarray(start, float), np.asarray(end, float)
        d = end - start
        length = float(np.hypot(*d))
        rot = float(np.degrees(np.arctan2(d[1], d[0])))
        wall = self.product(
            "IfcWall",
            name,
            self.box_rep(length, height, thickness),
            (start[0], start[1], z),
            rot,
            style,
            storey=storey,
        )
        t = d / length
        nrm = np.array([t[1], -t[0]])  # to the right of the axis, 0.1 m out
        for k, (u0, u1, z0, z1) in enumerate(openings):
            at = start + t * u0 + nrm * 0.1
            self.void(
                wall, f"{name} opening {k}", (at[0], at[1], z + z0), rot, u1 - u0, z1 - z0, thickness + 0.2
            )
        return wall

    def slab(self, name, storey, polyline, z, depth, style, ifc_class="IfcSlab", predefined=None):
        rep = self.run(
            "geometry.add_slab_representation",
            self.f,
            context=self.body,
            depth=float(depth),
            polyline=[tuple(map(float, p)) for p in polyline],
        )
        return self.product(ifc_class, name, rep, (0.0, 0.0, z), 0.0, style, predefined, storey=storey)

    def mesh(self, name, verts, faces, style, ifc_class="IfcSlab", predefined=None, storey=None):
        rep = self.run(
            "geometry.add_mesh_representation",
            self.f,
            context=self.body,
            vertices=[[tuple(map(float, v)) for v in verts]],
            faces=[[list(fc) for fc in faces]],
        )
        return self.product(ifc_class, name, rep, (0.0, 0.0, 0.0), 0.0, style, predefined, storey=storey)

    def write(self, path: Path, tag: str) -> None:
        import ifcopenshell.guid

        # the API keeps some relationships' members in sets: write them in entity order
        for rel in self.f.by_type("IfcRelContainedInSpatialStructure"):
            rel.RelatedElements = sorted(rel.RelatedElements, key=lambda e: e.id())
        for rel in self.f.by_type("IfcRelAggregates"):
            rel.RelatedObjects = sorted(rel.RelatedObjects, key=lambda e: e.id())
        for k, el in enumerate(sorted(self.f.by_type("IfcRoot"), key=lambda e: e.id())):
            el.GlobalId = ifcopenshell.guid.compress(hashlib.md5(f"{tag}-{k}".encode()).hexdigest())
        self.f.header.file_name.time_stamp = "2026-01-01T00:00:00"
        self.f.write(str(path))


def prism(profile_yz, x0: float, x1: float) -> tuple[list, list]:
    """A prism along x over a convex polygon in the (y, z) plane: vertices and faces, each wound so
    that its normal points out of the prism."""
    n = len(profile_yz)
    verts = [(x0, y, z) for y, z in profile_yz] + [(x1, y, z) for y, z in profile_yz]
    faces = [list(range(n)), list(range(n, 2 * n))]
    faces += [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    v = np.array(verts)
    centre = v.mean(axis=0)
    for k, fc in enumerate(faces):
        p = v[fc]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        if np.dot(normal, p.mean(axis=0) - centre) < 0:
            faces[k] = fc[::-1]
    return verts, faces
