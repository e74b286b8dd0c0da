"""Faults of real BIM geometry (issue 36): a floor slab whose corners, edges and centre all lie under
walls."""

import pytest

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt
from iat.io.load import load_scene
from iat.lighting.daylight_default import DaylightRequest, apply_daylight
from iat.radiosity import SolveOptions, solve
from tests.support.two_room_ifc import write_two_room_ifc

SLAB_UNDER_WALLS = (
    "the slab's nine split-test points all lie under walls, so it stays one black element unless "
    "contacts are cut (measured: 0 vertices on the living room's floor with cut='crossings')"
)


@pytest.mark.parametrize(
    "cut", ["all", pytest.param("crossings", marks=pytest.mark.xfail(strict=True, reason=SLAB_UNDER_WALLS))]
)
def test_a_slab_under_the_walls_is_meshed_where_the_rooms_are(tmp_path, cut):
    """The two-room IFC's floor slab runs under every wall, and its centre is under the partition.
    Cut where the walls stand on it (``cut="all"``), the room's part of the slab is a patch of its own:
    the living room's floor gets vertices (98), all lit by the overcast sky through the window."""
    scene = load_scene(write_two_room_ifc(tmp_path / "two.ifc"), cut=cut)
    apply_daylight(scene, DaylightRequest(sky="overcast", sun="off"))
    sol = solve(scene, SolveOptions.preset("draft"))
    patch = qt.decode_key(sol.vert_key, sol.n)[0]
    x, y, z = sol.vert_position.T
    floor = (scene.patch_normal[patch][:, 1] > 0.9) & (y < 0.05)
    living = floor & (x > 0.3) & (x < 3.6) & (z < -0.3) & (z > -3.7)
    lum = sol.vert_radiance[living] @ LUMINANCE_WEIGHTS
    assert living.sum() >= 25
    assert (lum > 0).all() and lum.mean() > 0.5
