"""The generated two-storey furnished IFC house (issue 41's real-sized test model,
``tests/support/large_ifc.py``): written by ifcopenshell's API, more than 25 k triangles, furniture
as real tools write it (closed solids and open sheets), read by the loader as such."""

from __future__ import annotations

import pytest

pytest.importorskip("ifcopenshell")

from iat.io.load import load_scene  # noqa: E402
from tests.support.large_ifc import large_ifc_house  # noqa: E402
from tests.support.real_models import ifc_triangles  # noqa: E402


def test_two_storeys_of_five_by_five_rooms_are_over_25k_triangles(tmp_path):
    t = ifc_triangles(large_ifc_house(tmp_path / "h.ifc", 2, 5, 3, furnished=True))
    assert t["triangles"] == 27_628 and t["per_class"]["IfcFurniture"] == 22_776  # the bytes are fixed


def test_the_loader_sees_the_furnitures_solids_and_sheets(tmp_path):
    bare = load_scene(large_ifc_house(tmp_path / "bare.ifc", 2, 2, 2)).sides
    full = load_scene(large_ifc_house(tmp_path / "full.ifc", 2, 2, 2, furnished=True)).sides
    rooms = 3  # the 2 x 2 rooms' unskewed row on two storeys, less the upper stair's room
    # per room, measured: 6 open sheets (the sofa, the lamp's shade, and the 4 chairs, whose backs meet
    # two legs along an edge: non-manifold, as real furniture often is) and 12 closed solids (the table's
    # top and pedestal, the lamp's pole, the cabinet, and the 2 legs of each chair that meet the rest at
    # a corner only), none inside out
    assert full.open_sheets - bare.open_sheets == 6 * rooms
    assert full.closed_solids - bare.closed_solids == 12 * rooms
    assert full.inside_out == bare.inside_out == 0
