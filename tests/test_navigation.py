"""Walkthrough navigation (viewer/navigation.py): pure camera logic, no window."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.errors import LoadError
from viewer.navigation import (
    CameraPath,
    InputState,
    NavConfig,
    Navigator,
    PathPlayer,
    PathRecorder,
    load_paths,
    navigation_speed,
    paths_file,
    save_paths,
)

DT = 1.0 / 60.0


def start_camera() -> Camera:
    # at the origin, looking down -Z, 60 degree field of view
    return Camera(eye=[0.0, 1.0, 0.0], target=[0.0, 1.0, -2.0], yfov=60.0, znear=0.05, zfar=50.0)


def run(nav: Navigator, inp: InputState, seconds: float) -> Camera:
    cam = nav.camera
    for _ in range(round(seconds / DT)):
        cam = nav.update(DT, inp)
    return cam


def yaw_deg(cam: Camera) -> float:
    f = cam.forward
    return math.degrees(math.atan2(-f[0], -f[2]))


def test_starting_pose_is_the_given_camera():
    nav = Navigator(start_camera(), speed=2.0)
    cam = nav.update(DT, InputState())
    np.testing.assert_allclose(cam.eye, [0, 1, 0])
    np.testing.assert_allclose(cam.forward, [0, 0, -1], atol=1e-12)
    assert cam.yfov == 60.0 and cam.znear == 0.05 and cam.zfar == 50.0


def test_keys_walk_strafe_rise_at_the_set_speed():
    nav = Navigator(start_camera(), speed=2.0)
    cam = run(nav, InputState(keys={"w"}), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 1, -2], atol=1e-9)  # 2 units/s forward (-Z)
    cam = run(nav, InputState(keys={"d"}), 0.5)
    np.testing.assert_allclose(cam.eye, [1, 1, -2], atol=1e-9)  # strafe right (+X)
    cam = run(nav, InputState(keys={"e"}), 0.5)
    np.testing.assert_allclose(cam.eye, [1, 2, -2], atol=1e-9)  # E rises
    cam = run(nav, InputState(keys={"q", "down"}), 0.5)
    np.testing.assert_allclose(cam.eye, [1, 1, -1], atol=1e-9)  # Q falls, Down walks back
    np.testing.assert_allclose(cam.forward, [0, 0, -1], atol=1e-12)  # no turning from moves


def test_shift_is_four_times_faster_and_diagonals_are_not_faster():
    nav = Navigator(start_camera(), speed=1.0)
    cam = run(nav, InputState(keys={"up", "shift"}), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 1, -4], atol=1e-9)
    nav.reset()
    cam = run(nav, InputState(keys={"w", "d"}), 1.0)
    assert np.linalg.norm(cam.eye - [0, 1, 0]) == pytest.approx(1.0, abs=1e-9)


def test_arrow_keys_turn_at_the_turn_rate_and_walking_follows_the_view():
    nav = Navigator(start_camera(), speed=1.0, config=NavConfig(turn_rate=90.0))
    cam = run(nav, InputState(keys={"left"}), 1.0)
    assert yaw_deg(cam) == pytest.approx(90.0, abs=1e-6)  # now facing -X
    np.testing.assert_allclose(cam.eye, [0, 1, 0], atol=1e-12)  # turning does not move
    cam = run(nav, InputState(keys={"w"}), 1.0)
    np.testing.assert_allclose(cam.eye, [-1, 1, 0], atol=1e-9)
    cam = run(nav, InputState(keys={"right"}), 2.0)
    assert yaw_deg(cam) == pytest.approx(-90.0, abs=1e-6)


def test_gamepad_left_stick_moves_and_turns_right_stick_looks():
    cfg = NavConfig(turn_rate=90.0, look_rate=120.0, deadzone=0.15)
    nav = Navigator(start_camera(), speed=2.0, config=cfg)
    # left stick pushed fully up (GLFW y = -1): walk forward at the speed
    cam = run(nav, InputState(gamepad_axes=(0, -1, 0, 0, 0, 0)), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 1, -2], atol=1e-9)
    # half tilt outside the dead zone is proportionally slower: (0.575 - 0.15) / 0.85 = 0.5
    nav.reset()
    cam = run(nav, InputState(gamepad_axes=(0, -0.575, 0, 0, 0, 0)), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 1, -1], atol=1e-9)
    # inside the dead zone nothing happens
    nav.reset()
    cam = run(nav, InputState(gamepad_axes=(0.1, -0.1, 0.1, 0.1, 0, 0)), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 1, 0])
    np.testing.assert_allclose(cam.forward, [0, 0, -1], atol=1e-12)
    # left stick right: turn right at the turn rate
    nav.reset()
    cam = run(nav, InputState(gamepad_axes=(1, 0, 0, 0, 0, 0)), 0.5)
    assert yaw_deg(cam) == pytest.approx(-45.0, abs=1e-6)
    np.testing.assert_allclose(cam.eye, [0, 1, 0], atol=1e-12)
    # right stick up: look up at the look rate, the eye stays
    nav.reset()
    cam = run(nav, InputState(gamepad_axes=(0, 0, 0, -1, 0, 0)), 0.25)
    assert math.degrees(math.asin(cam.forward[1])) == pytest.approx(30.0, abs=1e-6)
    # looking up does not make walking climb: walking stays horizontal
    cam = run(nav, InputState(keys={"w"}), 1.0)
    assert cam.eye[1] == pytest.approx(1.0, abs=1e-12)
    # right stick right: look right
    nav.reset()
    cam = run(nav, InputState(gamepad_axes=(0, 0, 1, 0, 0, 0)), 0.5)
    assert yaw_deg(cam) == pytest.approx(-60.0, abs=1e-6)


def test_gamepad_triggers_rise_and_fall():
    nav = Navigator(start_camera(), speed=2.0)
    cam = run(nav, InputState(gamepad_axes=(0, 0, 0, 0, 0, 1)), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 3, 0], atol=1e-9)
    cam = run(nav, InputState(gamepad_axes=(0, 0, 0, 0, 0.5, 0)), 1.0)
    np.testing.assert_allclose(cam.eye, [0, 2, 0], atol=1e-9)


def test_gamepad_a_cycles_speed_gears_on_press_not_while_held():
    nav = Navigator(start_camera(), speed=1.0, config=NavConfig(gears=(1.0, 4.0, 0.25)))
    held = InputState(gamepad_buttons={"a"})
    nav.update(DT, held)
    assert nav.effective_gear == 4.0
    for _ in range(10):  # holding A does not keep changing gears
        nav.update(DT, held)
    assert nav.effective_gear == 4.0
    cam = run(nav, InputState(keys={"w"}), 1.0)  # A released
    assert cam.eye[2] == pytest.approx(-4.0, abs=1e-9)
    nav.update(DT, held)
    assert nav.effective_gear == 0.25
    nav.update(DT, InputState())
    nav.update(DT, held)
    assert nav.effective_gear == 1.0


def test_wheel_changes_speed_and_reset_restores_pose_and_speed():
    nav = Navigator(start_camera(), speed=1.0, config=NavConfig(wheel_factor=1.25))
    nav.update(DT, InputState(wheel=2))
    assert nav.speed == pytest.approx(1.5625)
    nav.update(DT, InputState(wheel=-4))
    assert nav.speed == pytest.approx(1.25**-2)
    run(nav, InputState(keys={"w", "left"}, mouse_dx=3.0), 0.5)
    cam = nav.update(DT, InputState(gamepad_buttons={"start"}))
    np.testing.assert_allclose(cam.eye, [0, 1, 0])
    np.testing.assert_allclose(cam.forward, [0, 0, -1], atol=1e-12)
    assert nav.speed == 1.0


def test_mouse_drag_looks_and_pitch_is_clamped():
    nav = Navigator(start_camera(), config=NavConfig(mouse_sensitivity=0.2, max_pitch=89.0))
    cam = nav.update(DT, InputState(mouse_dx=100.0))  # drag right: look 20 degrees right
    assert yaw_deg(cam) == pytest.approx(-20.0, abs=1e-9)
    cam = nav.update(DT, InputState(mouse_dy=-100.0))  # drag up: look 20 degrees up
    assert math.degrees(math.asin(cam.forward[1])) == pytest.approx(20.0, abs=1e-9)
    cam = nav.update(DT, InputState(mouse_dy=-10000.0))
    assert math.degrees(math.asin(cam.forward[1])) == pytest.approx(89.0, abs=1e-9)
    assert np.isfinite(cam.view_from_world()).all()


def test_navigation_speed_scales_with_the_model():
    assert navigation_speed(np.array([[0, 0, 0], [3, 4, 0]])) == pytest.approx(1.25)
    assert navigation_speed(np.zeros((2, 3))) == 1.0


def test_recorded_path_plays_back_to_the_same_poses():
    nav = Navigator(start_camera(), speed=1.5)
    rec = PathRecorder("demo")
    script = [({"w"}, 30), ({"left", "w"}, 20), ({"e"}, 10), (set(), 5), ({"d", "right"}, 25)]
    t = 0.0
    seen = []
    for keys, n in script:
        for _ in range(n):
            cam = nav.update(DT, InputState(keys=keys, mouse_dy=0.5))
            rec.add(cam, t)
            seen.append(cam)
            t += DT
    path = rec.path()
    assert len(path) == len(seen) == 90
    # by frames: one recorded pose per frame, exactly
    player = PathPlayer(path)
    played = []
    while (cam := player.next()) is not None:
        played.append(cam)
    assert len(played) == len(seen) and player.done
    for a, b in zip(seen, played, strict=True):
        np.testing.assert_array_equal(a.eye, b.eye)
        np.testing.assert_array_equal(a.target, b.target)
    # by time: the pose at a recorded time is the recorded pose; between two it is between them
    timed = PathPlayer(path)
    for k in (0, 17, 44, 89):
        cam = timed.pose_at(path.times[k])
        np.testing.assert_allclose(cam.eye, seen[k].eye, atol=1e-12)
        np.testing.assert_allclose(cam.target, seen[k].target, atol=1e-12)
    mid = timed.pose_at(0.5 * (path.times[10] + path.times[11]))
    np.testing.assert_allclose(mid.eye, 0.5 * (seen[10].eye + seen[11].eye), atol=1e-12)


def test_fixed_frame_playback_spans_the_path():
    cams = [Camera(eye=[x, 1, 0], target=[x, 1, -1]) for x in (0.0, 1.0, 2.0)]
    path = CameraPath("keys", cams)  # no times: evenly spaced key poses
    player = PathPlayer(path, frames=5)
    xs = [player.frame(k).eye[0] for k in range(5)]
    np.testing.assert_allclose(xs, [0, 0.5, 1, 1.5, 2])
    frames = []
    while (c := player.next()) is not None:
        frames.append(c)
    assert len(frames) == 5
    # as many frames as poses, evenly spaced: exactly the poses
    exact = PathPlayer(path, frames=3)
    for k in range(3):
        np.testing.assert_array_equal(exact.frame(k).eye, cams[k].eye)
    with pytest.raises(ValueError, match="empty"):
        PathPlayer(CameraPath("none", []))


def test_json_round_trip(tmp_path):
    model = tmp_path / "room.glb"
    file = paths_file(model)
    assert file == tmp_path / "room.paths.json"
    rec = PathRecorder("walk")
    nav = Navigator(start_camera(), speed=1.0)
    for k in range(12):
        rec.add(nav.update(DT, InputState(keys={"w", "left"})), k * DT)
    keys = CameraPath("keys", [start_camera(), Camera(eye=[1, 2, 3], target=[0, 0, 0], yfov=45.0, name="b")])
    save_paths(file, {"walk": rec.path(), "keys": keys})
    doc = json.loads(file.read_text())
    assert set(doc) == {"walk", "keys"}
    assert set(doc["walk"][0]) >= {"eye", "target", "up", "yfov", "t"}
    assert "t" not in doc["keys"][0]
    back = load_paths(file)
    assert back["keys"].times is None
    np.testing.assert_allclose(back["walk"].times, rec.path().times)
    for name, orig in (("walk", rec.path()), ("keys", keys)):
        for a, b in zip(orig.cameras, back[name].cameras, strict=True):
            np.testing.assert_array_equal(a.eye, b.eye)
            np.testing.assert_array_equal(a.target, b.target)
            np.testing.assert_array_equal(a.up, b.up)
            assert (a.yfov, a.znear, a.zfar, a.name) == (b.yfov, b.znear, b.zfar, b.name)
    assert load_paths(tmp_path / "missing.paths.json") == {}


def test_damaged_paths_file_names_the_file(tmp_path):
    bad = tmp_path / "bad.paths.json"
    bad.write_text("[1, 2")
    with pytest.raises(LoadError, match="bad.paths.json"):
        load_paths(bad)
    bad.write_text('{"walk": 3}')
    with pytest.raises(LoadError, match="not a list"):
        load_paths(bad)


def test_walls_stop_the_walk_and_the_walk_slides_along_them():
    """Walking into the Cornell box's back wall (z = 0.559) stops a radius in front of it; walking at
    it at 45 degrees slides along it into the corner; with walls off you pass through."""
    from iat.io.load import load_scene
    from viewer.collision import collision_radius
    from viewer.navigation import walker

    scene = load_scene(Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb")
    hi = scene.bounds[1]
    radius = collision_radius(scene.bounds)
    # above the blocks, looking at the back wall
    start = Camera(eye=[0.278, 0.45, 0.1], target=[0.278, 0.45, 1.0], yfov=40.0, znear=0.01, zfar=10.0)
    walk = InputState(keys={"w"})
    dt = 0.05

    nav = walker(scene, start)
    for _ in range(100):
        nav.update(dt, walk)
    assert hi[2] - radius - nav.speed * dt <= nav.eye[2] <= hi[2] - radius  # stopped at the wall
    nav = walker(scene, start)
    for _ in range(100):
        nav.update(dt, walk, walls=False)
    assert nav.eye[2] > hi[2]  # through it

    nav = walker(scene, start)
    nav.yaw = math.radians(-135.0)  # towards +z and +x
    for _ in range(100):
        nav.update(dt, walk)
    # slid along both walls into the corner, a radius from each
    assert hi[0] - radius - nav.speed * dt <= nav.eye[0] <= hi[0] - radius
    assert hi[2] - radius - nav.speed * dt <= nav.eye[2] <= hi[2] - radius
