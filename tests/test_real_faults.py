"""Faults of real BIM geometry the solver copes with (issue 36): a floor slab whose corners, edges and
centre all lie under walls."""

from iat.color import LUMINANCE_WEIGHTS
from iat.geometry import quadtree as qt
from iat.io.load import load_scene
from iat.lighting.daylight_default import DaylightRequest, apply_daylight
from iat.radiosity import SolveOptions, solve
from tests.support.two_room_ifc import write_two_room_ifc


def test_a_slab_under_the_walls_is_meshed_where_the_rooms_are(tmp_path):
    """The two-room IFC's floor slab runs under every wall, and its centre is under the partition:
    its nine split-test points are all inside walls and dark, so it stayed one black element. A
    large element dark at all its points is split: the living room's floor gets vertices, all lit
    by the overcast sky through the window."""
    scene = load_scene(write_two_room_ifc(tmp_path / "two.ifc"), cut="none")
    apply_daylight(scene, DaylightRequest(sky="overcast", sun="off"))
    sol = solve(scene, SolveOptions.preset("draft"))
    patch = qt.decode_key(sol.vert_key, sol.n)[0]
    x, y, z = sol.vert_position.T
    floor = (scene.patch_normal[patch][:, 1] > 0.9) & (y < 0.05)
    living = floor & (x > 0.3) & (x < 3.6) & (z < -0.3) & (z > -3.7)
    lum = sol.vert_radiance[living] @ LUMINANCE_WEIGHTS
    assert living.sum() >= 25
    assert (lum > 0).all() and lum.mean() > 0.5
