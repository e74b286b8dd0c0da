"""The viewer's panels: imgui widgets that read and change :class:`~viewer.state.AppState`.

Panels never call GL and never do long work: they set state fields (tuning
values, the mode, ``request_*`` fields) and the app acts on them next frame.

Windows (docked by the app around the 3D view): **Tuning** (threshold, scale,
method, budget, detail textures, exposure), **View** (mode, divider, cameras,
speed, camera paths), **Stats** (frame rate and frame-time plot, triangles and
draw calls, texture memory against the budget, atlas utilisation, patches,
solve and re-bake times, solve progress with ETA and cancel), **Model** (open,
solve options, export, save), **Lighting** (select, add, delete, move and colour point
and spot lights, emissive strengths, the background re-solve's progress, saving the
lights back to glTF; the day cycle: solve the model's lighting states and blend them
with the time-of-day slider). Plus the menus, the error window and the HUD's lines (what
:mod:`viewer.overlay` draws over the 3D view).
"""

from __future__ import annotations

import functools
import shutil
from pathlib import Path

import numpy as np
from imgui_bundle import ImVec2, ImVec4, hello_imgui, imgui, implot

from iat.bake.flatten import METHODS
from iat.io.load import SUPPORTED_EXTENSIONS
from viewer import false_color
from viewer.bake_worker import snap_scale
from viewer.daylight import model_north, sun_facts, sun_label
from viewer.eta import JobEta
from viewer.lights import ies_controls, new_light_intensity, new_light_position
from viewer.navigation import paths_file
from viewer.state import MODE_LABELS, MODES, AppState

RED = ImVec4(0.85, 0.2, 0.2, 1.0)
GREEN = ImVec4(0.3, 0.75, 0.35, 1.0)
DIM = ImVec4(0.65, 0.65, 0.65, 1.0)
MB = float(1 << 20)
OPEN_ETA, DAY_ETA = JobEta(), JobEta()  # time left while opening a model / solving the day cycle
MODEL_FILTERS = [
    "Models and solutions",
    " ".join(f"*{e}" for e in (*SUPPORTED_EXTENSIONS, ".npz")),
    "All files",
    "*",
]


@functools.lru_cache(maxsize=1)
def has_native_dialogs() -> bool:
    """portable_file_dialogs needs zenity, kdialog, matedialog or qarma on Linux (looked up once: the
    menus ask every frame, and four PATH searches cost 0.7 ms)."""
    import sys

    if sys.platform != "linux":
        return True
    return any(shutil.which(t) for t in ("zenity", "kdialog", "matedialog", "qarma"))


def _help(text: str) -> None:
    imgui.same_line()
    imgui.text_disabled("(?)")
    imgui.set_item_tooltip(text)


def same_line_if_fits(label: str) -> None:
    """Put the next button on this line when it fits in the panel, else on the next (no clipping)."""
    need = imgui.calc_text_size(label).x + 2 * imgui.get_style().frame_padding.x
    imgui.same_line()
    if imgui.get_content_region_avail().x < need:
        imgui.new_line()


def _mb(nbytes: float) -> str:
    return f"{nbytes / MB:.2f} MB"


def _seconds(s: float | None) -> str:
    if s is None:
        return "..."
    return f"{s * 1000:.0f} ms" if s < 1 else f"{s:.1f} s"


# -- Tuning -----------------------------------------------------------------------------------------
def tuning_panel(state: AppState) -> None:
    t = state.tuning
    if not state.model.loaded:
        imgui.text_disabled("nothing open yet")
    auto = t.budget_on
    resolved = state.model.baked.policy if state.model.baked is not None else None

    imgui.begin_disabled(auto or not state.model.loaded)
    top = state.model.deepest + 1
    shown = resolved.threshold if (auto and resolved is not None) else t.threshold
    changed, v = imgui.slider_int("Threshold", int(shown), 0, max(top, 1))
    if changed and not auto:
        t.threshold = int(v)
    _help(
        "Patches whose tree depth is at least the threshold become one textured polygon;\n"
        f"the others stay a mesh. 0 textures every patch, {top} keeps all as mesh."
    )
    shown = resolved.scale if (auto and resolved is not None) else t.scale
    changed, v = imgui.slider_float("Scale", float(shown), 0.125, 2.0, "%.3f", imgui.SliderFlags_.logarithmic)
    if changed and not auto:
        t.scale = snap_scale(v)
    _help(
        "Texture side factor, in quarter-octave steps: below 1 saves memory (blur), above 1 costs\n"
        "memory. At 1, 0.5, 0.25 and 0.125 neighbouring textures meet without seams."
    )
    imgui.end_disabled()

    changed, k = imgui.combo("Method", METHODS.index(t.method) if t.method in METHODS else 0, list(METHODS))
    if changed:
        t.method = METHODS[k]
    _help("bilinear: the report's flattening; scan: scan-converted mesh; bicubic: smooth fit.")
    changed, naive = imgui.checkbox("Naive scaling", t.scale_mode == "naive")
    if changed:
        t.scale_mode = "naive" if naive else "clamped"
    _help("Resize textures as images (the report's correspondence errors) instead of clamped resampling.")

    imgui.separator()
    changed, t.budget_on = imgui.checkbox("Budget", t.budget_on)
    _help("When on, threshold and scale are chosen to fit the texture memory budget.")
    imgui.begin_disabled(not t.budget_on)
    changed, v = imgui.slider_float(
        "Budget (MB)", float(t.budget_mb), 0.0, 256.0, "%.3g MB", imgui.SliderFlags_.logarithmic
    )
    if changed:
        t.budget_mb = max(float(v), 0.0)
    imgui.end_disabled()

    changed, t.detail = imgui.checkbox("Detail textures", t.detail)
    _help("Store incoming light where a material has a detail texture; the shader multiplies both.")
    changed, t.lod = imgui.checkbox("Levels of detail", t.lod)
    _help("Also bake each texture's coarser quad-tree levels; far surfaces blend two of them per pixel.")
    imgui.begin_disabled(not t.lod)
    imgui.same_line()
    changed, t.lod_stream = imgui.checkbox("Stream", t.lod_stream)
    _help("Keep on the GPU only the levels the view needs (the budget, when on, caps them).")
    imgui.end_disabled()
    lo, hi = min(0.05, float(t.exposure)), max(20.0, float(t.exposure))  # an auto exposure may be outside
    changed, v = imgui.slider_float(
        "Exposure", float(t.exposure), lo, hi, "%.3g", imgui.SliderFlags_.logarithmic
    )
    if changed:
        t.exposure = float(v)
    _help(
        "Multiplier on radiance before the tone map; set from the view when a model opens\n"
        "(View: Auto exposure, key X)."
    )
    changed, state.view.tonemap = imgui.checkbox("sRGB tone map", state.view.tonemap)

    imgui.separator()
    if state.jobs.rebaking:
        imgui.text_colored(DIM, "re-baking... (showing the previous bake)")
    elif resolved is not None:
        imgui.text_colored(DIM, f"on screen: {state.model.policy_summary()}")


# -- View -------------------------------------------------------------------------------------------
def view_panel(state: AppState) -> None:
    for i, m in enumerate(MODES):
        if i:
            imgui.same_line()
        if imgui.radio_button(MODE_LABELS[m], state.view.mode == m):
            state.view.mode = m
    if state.view.mode == "false":
        false_color.settings_panel(state)
    if state.view.mode == "split":
        changed, v = imgui.slider_float("Divider", float(state.view.split), 0.0, 1.0, "%.2f")
        if changed:
            state.view.split = float(v)
        imgui.text_colored(DIM, "mesh left, IAT right; drag the line in the view")
    if state.view.mode == "diff":
        changed, v = imgui.slider_float(
            "Diff gain", float(state.view.diff_gain), 1.0, 256.0, "x%.0f", imgui.SliderFlags_.logarithmic
        )
        if changed:
            state.view.diff_gain = float(v)
        imgui.text_colored(DIM, "|mesh - IAT| x gain")

    imgui.separator()
    cams = state.model.cameras
    names = [c.name or f"camera {k}" for k, c in enumerate(cams)] or ["(none)"]
    changed, k = imgui.combo("Camera", min(state.view.camera_index, len(names) - 1), names)
    if changed and cams:
        state.view.camera_index = k
        if state.view.nav is not None:
            state.view.nav.reset(cams[k])
    if imgui.button("Reset view") and state.view.nav is not None:
        state.view.nav.reset()
    imgui.same_line()
    changed, state.view.walls = imgui.checkbox("Walls", state.view.walls)
    _help("Walls stop you (you slide along them); off, you walk through them.")
    imgui.same_line()
    if imgui.button("Auto exposure"):
        state.requests.auto_exposure = True
    _help("Exposure from the view on screen, as 'iat render' picks it: its 99th percentile at 0.8 (key X).")
    nav = state.view.nav
    if nav is not None:
        imgui.same_line()
        imgui.text(f"speed {nav.speed * nav.effective_gear:.3g}/s")
        _help(
            "WASD / arrows walk and turn, Q/E fall and rise, Shift x4, drag to look, wheel changes speed.\n"
            "Gamepad: left stick walks and turns, right stick looks, triggers rise and fall,\n"
            "A changes speed gear, B or Start resets."
        )

    imgui.separator()
    imgui.text("Camera paths")
    names = list(state.paths.named)
    if names:
        cur = names.index(state.paths.selected) if state.paths.selected in names else 0
        changed, k = imgui.combo("Path", cur, names)
        state.paths.selected = names[k]
    else:
        imgui.text_disabled("no paths yet: record one")
    rec = state.paths.recorder  # read once: Stop recording clears it in this frame
    if rec is None:
        if imgui.button("Record"):
            state.start_recording()
    else:
        if imgui.button("Stop recording"):
            state.stop_recording()
        imgui.same_line()
        imgui.text_colored(RED, f"REC {len(rec.cameras)}")
    imgui.same_line()
    p = state.paths.player  # read once: Stop clears it in this frame
    if p is None:
        imgui.begin_disabled(not names)
        if imgui.button("Play"):
            state.start_playback(state.paths.selected or names[0])
        imgui.end_disabled()
    else:
        if imgui.button("Stop"):
            state.stop_playback()
        imgui.same_line()
        imgui.text(f"{p.index}/{p.frames}" if state.paths.playback_frames else f"{p.index} frames")
    changed, v = imgui.input_int("Frames", int(state.paths.playback_frames))
    if changed:
        state.paths.playback_frames = max(int(v), 0)
    _help("0 plays the path in real time; N plays exactly N frames (benchmark).")
    imgui.begin_disabled(not state.model.path or not state.paths.named)
    if imgui.button("Save paths"):
        state.requests.save_paths = True
    imgui.end_disabled()
    if state.model.path:
        imgui.same_line()
        imgui.text_colored(DIM, paths_file(state.model.path).name)
    imgui.text_colored(DIM, "F12: screenshot")


# -- Stats ------------------------------------------------------------------------------------------
def _bar(fraction: float, text: str, color: ImVec4 | None = None) -> None:
    if color is not None:
        imgui.push_style_color(imgui.Col_.plot_histogram, color)
    imgui.progress_bar(float(min(max(fraction, 0.0), 1.0)), ImVec2(-1, 0), text)
    if color is not None:
        imgui.pop_style_color()


def stats_panel(state: AppState) -> None:
    st = state.stats
    h = st.frame_history()
    if st.idling:
        imgui.text(f"idling: {st.idle_fps:4.1f} fps while nothing changes")
        _help(
            "Nothing moves, so the window redraws a few times a second (Menu View: FPS idling).\n"
            "A frame's own work now allows the rate below; moving the camera ends idling."
        )
        imgui.text_colored(
            DIM, f"a frame's work {1000.0 / max(st.work_fps, 1e-9):5.1f} ms ({st.work_fps:.0f} fps)"
        )
    else:
        recent = h[-60:]
        mean = 1000.0 / st.fps if st.fps > 0 else 0.0
        worst = float(recent.max()) if recent.size else 0.0
        imgui.text(f"{st.fps:5.1f} fps   {mean:5.1f} ms/frame   max {worst:5.1f} ms")
    if h.size and implot.begin_plot(
        "##frametimes",
        ImVec2(-1, hello_imgui.em_size(7.0)),
        implot.Flags_.no_legend | implot.Flags_.no_mouse_text,
    ):
        implot.setup_axes("", "ms", implot.AxisFlags_.no_tick_labels, 0)
        top = max(50.0, float(h.max()) * 1.1)
        implot.setup_axes_limits(0, max(len(h) - 1, 1), 0, top, implot.Cond_.always)
        xs = np.arange(len(h), dtype=np.float32)
        implot.plot_line("frame ms", xs, h.astype(np.float32))
        limit = implot.Spec(line_color=RED, flags=int(implot.InfLinesFlags_.horizontal))
        implot.plot_inf_lines("50 ms", np.array([50.0], np.float32), limit)
        implot.end_plot()

    mem = state.model.memory
    if imgui.begin_table(
        "counts", 3, imgui.TableFlags_.borders_inner_h | imgui.TableFlags_.sizing_stretch_prop
    ):
        imgui.table_setup_column("")
        imgui.table_setup_column("triangles")
        imgui.table_setup_column("draw calls")
        imgui.table_headers_row()
        rows = [("Mesh", state.model.mesh_triangles, state.model.mesh_draw_calls)]
        if mem:
            rows.append(("IAT", state.model.iat_triangles, mem.get("draw_calls", 0)))
            rows.append(
                ("  mesh part", mem.get("triangles_mesh_part", 0), int(mem.get("triangles_mesh_part", 0) > 0))
            )
            rows.append(
                (
                    "  textured",
                    mem.get("triangles_textured_part", 0),
                    mem.get("draw_calls", 0) - int(mem.get("triangles_mesh_part", 0) > 0),
                )
            )
        for name, tris, calls in rows:
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text(name)
            imgui.table_next_column()
            imgui.text(f"{tris:,}")
            imgui.table_next_column()
            imgui.text(f"{calls}")
        imgui.end_table()
    if state.model.mesh_triangles and mem:
        fewer = state.model.mesh_triangles / max(state.model.iat_triangles, 1)
        imgui.text_wrapped(f"IAT draws {fewer:,.0f}x fewer triangles than the mesh")
    rs = state.stats.render
    if st.view_redraws or st.view_copies:
        imgui.text_colored(DIM, f"3D view drawn {st.view_redraws:,} times, copied {st.view_copies:,}")
        _help(
            "The 3D view is drawn only when camera, mode, exposure, bake or blend change;\n"
            "else its last image is copied."
        )
    if st.panel_skips:
        imgui.text_colored(DIM, f"panels drawn {st.panel_draws:,} times, kept {st.panel_skips:,}")
        _help(
            "A panel is drawn when it changed (at once while you use it, else at most five times\n"
            "a second); else the window keeps its last pixels."
        )
    if rs:
        imgui.push_style_color(imgui.Col_.text, DIM)
        imgui.text_wrapped(
            f"last frame drew {rs.get('triangles', 0):,} triangles in {rs.get('draw_calls', 0)} calls"
        )
        imgui.pop_style_color()

    imgui.separator()
    used = float(mem.get("texture_bytes", 0)) if mem else 0.0
    budget = float(state.tuning.budget_mb) * MB
    over = state.tuning.budget_on and used > budget
    if state.tuning.budget_on:
        frac = used / budget if budget > 0 else (1.0 if used > 0 else 0.0)
        label = f"{_mb(used)} / {_mb(budget)}"
    else:  # nothing to compare with: the bar is full, the text says so
        frac, label = (1.0 if used > 0 else 0.0), f"{_mb(used)} (budget off)"
    n_states = int(mem.get("solutions", 1)) if mem else 1
    layers = f"  ({n_states} lighting states: {n_states} layers per page)" if n_states > 1 else ""
    imgui.text("Texture memory" + layers)
    lod = state.stats.lod
    if lod:
        resident = sorted(lod.get("resident_levels", {}).items(), reverse=True)
        levels = ", ".join(f"{k}: {n}" for k, n in resident)
        imgui.text_wrapped(
            f"LOD resident {_mb(lod.get('resident_bytes', 0))} / {_mb(lod.get('total_bytes', 0))}"
            f"{' (streaming)' if lod.get('streaming') else ''}; tree levels (tiles) {levels}"
        )
    _bar(frac, label, RED if (over or (budget <= 0 and used > 0 and state.tuning.budget_on)) else None)
    if mem:
        pages = f"{mem.get('pages', 0)} page(s) {mem.get('page_width', 0)}x{mem.get('page_height', 0)}"
        imgui.text(f"Atlas utilisation   {pages}")
        _bar(float(mem.get("utilisation", 0.0)), f"{100 * float(mem.get('utilisation', 0.0)):.0f} %")
        pt, pm = int(mem.get("patches_textured", 0)), int(mem.get("patches_meshed", 0))
        imgui.text(f"Patches textured {pt:,}   meshed {pm:,}")
        _bar(pt / max(pt + pm, 1), f"{pt} / {pt + pm}", GREEN)
        imgui.text_colored(
            DIM, f"vertex + index bytes {_mb(mem.get('vertex_bytes', 0) + mem.get('index_bytes', 0))}"
        )

    if state.lighting.relighting:
        imgui.text_colored(RED, "stale: the lights changed, re-solving (Lighting panel)")
    imgui.separator()
    solve = _seconds(state.model.solve_seconds) if state.model.loaded else "-"
    if state.model.from_cache:
        solve += " (cached)"
    imgui.text(f"Solve {solve}")
    jobs = state.jobs
    imgui.text(f"Re-bake {_seconds(jobs.bake_seconds) if jobs.rebakes else '-'}   ({jobs.rebakes} bakes)")
    if state.jobs.rebaking:
        imgui.same_line()
        imgui.text_colored(DIM, "baking...")

    job = state.jobs.open_job
    if job is not None and not job.done:
        imgui.separator()
        eta = OPEN_ETA.update(job, job.fraction)
        imgui.text(f"Opening {Path(job.path).name}: {job.message}")
        _bar(job.fraction, f"{100 * job.fraction:.0f} %  ETA {_seconds(eta) if eta is not None else '...'}")
        if imgui.button("Cancel"):
            job.cancel()
    if state.messages.status:
        imgui.separator()
        imgui.text_wrapped(state.messages.status)


# -- Lighting ---------------------------------------------------------------------------------------
def _light_label(k: int, lt) -> str:
    return f"{lt.name or f'light {k}'} ({lt.kind})##light{k}"


def lighting_panel(state: AppState) -> None:
    ed = state.lighting.editor
    if ed is None:
        imgui.text_disabled("an exported bake: lit by its textures" if state.model.path else "nothing open")
        return
    _, state.lighting.show_lights = imgui.checkbox("Show lights", state.lighting.show_lights)
    _help("Light markers in the view: click one to select it, drag it to move it at its height.")

    day = state.lighting.day_cycle
    imgui.begin_disabled(day)
    lights = ed.lights
    if state.lighting.selected_light >= len(lights):
        state.lighting.selected_light = len(lights) - 1
    rows = max(min(len(lights), 6), 2)  # every light shown up to 6, then the list scrolls
    tall = rows * imgui.get_text_line_height_with_spacing() + 2 * imgui.get_style().frame_padding.y
    if imgui.begin_list_box("##lights", ImVec2(-1, tall)):
        for k, lt in enumerate(lights):
            clicked, _ = imgui.selectable(_light_label(k, lt), k == state.lighting.selected_light)
            if clicked:
                state.lighting.selected_light = k
        if not lights:
            imgui.text_disabled("no point or spot lights")
        imgui.end_list_box()
    for kind in ("point", "spot"):  # where the camera looks, as bright as the scene's lamps
        if kind == "spot":
            same_line_if_fits(f"Add {kind} light")
        if imgui.button(f"Add {kind} light"):
            pos, power = new_light_position(ed.scene, state.view.camera), new_light_intensity(ed.scene)
            state.lighting.selected_light = ed.add(kind, pos, intensity=power)
    same_line_if_fits("Delete light")
    imgui.begin_disabled(state.lighting.selected_light < 0)
    if imgui.button("Delete light") and state.lighting.selected_light >= 0:
        ed.delete(state.lighting.selected_light)
        state.lighting.selected_light = min(state.lighting.selected_light, len(ed.lights) - 1)
    imgui.end_disabled()

    k = state.lighting.selected_light
    if 0 <= k < len(ed.lights) and ed.lights[k].kind == "directional":  # the sun: a direction, no place
        imgui.text_wrapped(f"sun: {sun_facts(ed.lights[k], model_north(state))}")  # from true north
        _help("A direction, not a lamp: set its place, date and time in the Sun & sky panel (or --sun).")
    elif 0 <= k < len(ed.lights):
        lt = ed.lights[k]
        lo, hi = ed.scene.bounds
        step = float(np.linalg.norm(hi - lo)) * 0.002
        changed, v = imgui.drag_float3("Position", [float(x) for x in lt.position], step)
        if changed:
            ed.move(k, np.clip(np.asarray(v, dtype=np.float64), lo, hi))
        if lt.kind == "spot":
            changed, v = imgui.drag_float3("Direction", [float(x) for x in lt.direction], 0.01)
            if changed and np.linalg.norm(v) > 1e-6:
                ed.edit(k, direction=v)
            changed, outer = imgui.slider_angle("Outer cone", float(lt.outer_cone), 1.0, 90.0)
            if changed and outer > lt.inner_cone:
                ed.edit(k, outer_cone=float(outer))
            changed, inner = imgui.slider_angle("Inner cone", float(lt.inner_cone), 0.0, 89.0)
            if changed and inner < lt.outer_cone:
                ed.edit(k, inner_cone=float(inner))
        changed, col = imgui.color_edit3("Colour", [float(x) for x in lt.color])
        if changed:
            ed.edit(k, color=np.clip(col, 0.0, None))
        top = max(float(lt.intensity) * 4.0, float(np.linalg.norm(hi - lo)) ** 2, 1e-3)
        changed, v = imgui.slider_float(
            "Intensity", float(lt.intensity), 0.0, top, "%.3g W/sr", imgui.SliderFlags_.logarithmic
        )
        if changed:
            ed.edit(k, intensity=max(float(v), 0.0))
        ies_controls(state, ed, k)

    em = ed.emissive()
    if em:
        imgui.separator()
        imgui.text("Emission strength")
        for m in em:
            changed, v = imgui.slider_float(
                f"{ed.base.materials[m].name}##emission{m}", ed.strength(m), 0.0, 4.0, "x%.2f"
            )
            if changed:
                ed.set_strength(m, max(float(v), 0.0))
    imgui.end_disabled()
    if day:
        imgui.text_colored(DIM, "turn the day cycle off to edit the lights")

    imgui.separator()
    rl = state.lighting.relighter
    if state.lighting.relighting:
        relight_progress(rl)
    elif rl is not None and getattr(rl, "cancelled", False):
        imgui.text_colored(RED, "re-solve cancelled: the view keeps the last lighting solved")
    elif state.lighting.relights:
        step, steps = state.lighting.relight_step
        imgui.text_colored(
            DIM, f"solved in {_seconds(state.lighting.relight_seconds)} (step {step}/{steps}, resolve)"
        )
    imgui.begin_disabled(day)
    if imgui.button("Refine mesh"):
        state.requests.remesh = True
    imgui.end_disabled()
    _help(
        "Moving lights keeps the mesh (the solve continues from the last solution, fast);\n"
        "this solves afresh so the mesh follows the new shadows."
    )

    if not state.requests.file_fields["lights"] and state.model.path:
        p = Path(ed.base.path or state.model.path)
        state.requests.file_fields["lights"] = str(p.with_name(p.stem + "-lit" + (p.suffix or ".glb")))
    _path_input(state, "glTF file##lights", "lights")
    imgui.begin_disabled(not ed.base.path)
    if imgui.button("Save lights") and state.requests.file_fields["lights"].strip():
        state.requests.save_lights = state.requests.file_fields["lights"].strip()
    imgui.end_disabled()
    _help(
        "Writes a copy of the model with these lights (KHR_lights_punctual) and emission;\n"
        "the geometry is unchanged."
    )

    day_cycle_panel(state)


def relight_progress(rl) -> None:
    """The re-solve under way: a bar with the step and the time left, and Cancel."""
    f = float(getattr(rl, "fraction", 0.0))
    eta = getattr(rl, "eta", None)
    step = int(getattr(rl, "step", 0))
    left = f"{_seconds(eta)} left" if eta is not None else "measuring..."
    _bar(f, f"re-solving: step {max(step, 1)}  {100 * f:.0f} %  {left}")
    if hasattr(rl, "cancel"):
        if imgui.button("Cancel##relight"):
            rl.cancel()
        _help(
            "Stop the re-solve; the view keeps the last lighting solved\n"
            "(a coarse step, or from before the edit)."
        )


def day_cycle_panel(state: AppState) -> None:
    imgui.separator()
    imgui.text("Day cycle")
    states = state.lighting.states
    sset = state.lighting.solution_set
    if not states and sset is None:
        imgui.text_disabled("the model has no lighting states (extras iat_lighting_states)")
        return
    names = list(sset.names) if sset is not None else list(states)
    imgui.text_colored(DIM, ", ".join(names))
    job = state.lighting.set_job
    if job is not None and not job.done:
        eta = DAY_ETA.update(job, job.fraction)
        left = f"{_seconds(eta)} left" if eta is not None else "measuring..."
        _bar(job.fraction, f"{100 * job.fraction:.0f} %  {left}  {job.message[:40]}")
        if imgui.button("Cancel##day"):
            job.cancel()
        return
    if sset is None:
        if imgui.button("Solve day cycle"):
            state.requests.day_cycle = True
        _help(
            "Solves every lighting state on one mesh (the union of their own adaptive meshes),\n"
            "then bakes them into texture layers that share one atlas layout."
        )
        return
    changed, on = imgui.checkbox("Day cycle on", state.lighting.day_cycle)
    if changed:
        state.lighting.day_cycle = bool(on)
    imgui.begin_disabled(not state.lighting.day_cycle)
    changed, v = imgui.slider_float("Time of day", float(state.lighting.day_time), 0.0, 1.0, "%.3f")
    if changed:
        state.lighting.day_time = float(min(max(v, 0.0), 1.0))
    imgui.text(state.lighting.day_label() or " ")
    sun = sun_label(state)
    if sun:
        imgui.text(sun)
        _help("Where the sun stands at this time (the compass in the view's corner points to it).")
    keys = "  ".join(f"{n} {t:.2f}" for n, t in zip(sset.names, sset.times, strict=True))
    imgui.text_colored(DIM, "keys: " + keys)
    mem = state.model.memory
    if mem and int(mem.get("solutions", 1)) > 1:
        n = int(mem["solutions"])
        per = float(mem.get("texture_bytes", 0)) / n
        imgui.text(f"{n} states x {_mb(per)} = {_mb(float(mem.get('texture_bytes', 0)))} of texture")
    imgui.end_disabled()


# -- File -------------------------------------------------------------------------------------------
def _path_input(state: AppState, label: str, key: str) -> None:
    imgui.set_next_item_width(-hello_imgui.em_size(6.0))
    _, state.requests.file_fields[key] = imgui.input_text(label, state.requests.file_fields[key])


def file_panel(state: AppState) -> None:
    imgui.text_wrapped(f"Open: {state.model.path or '(nothing)'}")
    if not state.requests.file_fields["open"]:
        state.requests.file_fields["open"] = state.model.path
    _path_input(state, "File to open", "open")
    imgui.begin_disabled(state.jobs.opening)
    if imgui.button("Open") and state.requests.file_fields["open"].strip():
        state.requests.open = state.requests.file_fields["open"].strip()
    imgui.end_disabled()
    if has_native_dialogs():
        imgui.same_line()
        if imgui.button("Browse..."):
            open_dialog(state)
    o = state.model.solve_options
    changed, v = imgui.slider_int("Solve depth", int(o.max_depth), 1, 10)
    if changed:
        o.max_depth = int(v)
    _help("max_depth of the radiosity solve for models opened from now on")
    changed, v = imgui.slider_float(
        "Tolerance", float(o.tolerance), 0.005, 0.5, "%.3f", imgui.SliderFlags_.logarithmic
    )
    if changed:
        o.tolerance = float(v)
    changed, v = imgui.slider_int(
        "Ambient rays", int(o.ambient_rays), 16, 1024, flags=imgui.SliderFlags_.logarithmic
    )
    if changed:
        o.ambient_rays = int(v)
    _help("rays a vertex of the ambient term (the light still unshot): more is smoother indoors")
    changed, v = imgui.slider_int(
        "Sky rays", int(o.sky_samples), 64, 4096, flags=imgui.SliderFlags_.logarithmic
    )
    if changed:
        o.sky_samples = int(v)
    _help("directions a vertex towards the sky (noisy ones get 4 x more): more is smoother by daylight")
    changed, state.model.use_cache = imgui.checkbox("Use solution cache", state.model.use_cache)
    _help("Solved models are kept (by file content and options) so they reopen at once.")

    imgui.separator()
    if not state.requests.file_fields["export"] and state.model.path:
        state.requests.file_fields["export"] = str(
            Path(state.model.path).with_name(Path(state.model.path).stem + "-iat.glb")
        )
    _path_input(state, "GLB file", "export")
    imgui.begin_disabled(state.model.baked is None)
    if imgui.button("Export GLB") and state.requests.file_fields["export"].strip():
        state.requests.export = state.requests.file_fields["export"].strip()
    imgui.end_disabled()
    if not state.requests.file_fields["solution"] and state.model.path:
        state.requests.file_fields["solution"] = str(Path(state.model.path).with_suffix(".npz"))
    _path_input(state, "Solution file", "solution")
    imgui.begin_disabled(state.model.solution is None)
    if imgui.button("Save solution") and state.requests.file_fields["solution"].strip():
        state.requests.save_solution = state.requests.file_fields["solution"].strip()
    imgui.end_disabled()


def open_dialog(state: AppState) -> None:
    from imgui_bundle import portable_file_dialogs as pfd

    start = str(Path(state.model.path).parent) if state.model.path else str(Path.cwd())
    state.requests.dialogs["open"] = pfd.open_file("Open a model or solution", start, MODEL_FILTERS)


def export_dialog(state: AppState) -> None:
    from imgui_bundle import portable_file_dialogs as pfd

    default = Path(state.model.path).stem + "-iat.glb" if state.model.path else "iat.glb"
    state.requests.dialogs["export"] = pfd.save_file(
        "Export the bake as GLB", default, ["glTF binary", "*.glb"]
    )


def poll_dialogs(state: AppState) -> None:
    """Pick up the answers of native file dialogs (they run in their own process)."""
    for kind in list(state.requests.dialogs):
        d = state.requests.dialogs[kind]
        if not d.ready(0):
            continue
        del state.requests.dialogs[kind]
        res = d.result()
        if kind == "open" and res:
            state.requests.open = res[0]
            state.requests.file_fields["open"] = res[0]
        elif kind == "export" and res:
            state.requests.export = res if res.lower().endswith(".glb") else res + ".glb"


# -- menus, errors, the HUD's lines ------------------------------------------------------------------------
def menus(state: AppState) -> None:
    native = has_native_dialogs()
    if imgui.begin_menu("File"):
        if imgui.menu_item_simple("Open...", "Ctrl+O"):
            if native:
                open_dialog(state)
            else:
                _focus("Model")
                state.messages.set_status(
                    "no native file dialog here (install zenity): type the path in the Model panel"
                )
        if imgui.menu_item_simple("Open the Cornell box"):
            from viewer.state import default_model

            state.requests.open = str(default_model())
        if imgui.menu_item_simple("Export GLB...", enabled=state.model.baked is not None):
            if native:
                export_dialog(state)
            else:
                _focus("Model")
        if imgui.menu_item_simple("Save camera paths", enabled=bool(state.model.path and state.paths.named)):
            state.requests.save_paths = True
        if imgui.menu_item_simple("Screenshot", "F12"):
            state.requests.screenshot = ""
        imgui.separator()
        if imgui.menu_item_simple("Quit"):
            state.requests.quit = True
        imgui.end_menu()
    if imgui.begin_menu("Mode"):
        for m in MODES:
            if imgui.menu_item_simple(MODE_LABELS[m], None, state.view.mode == m):
                state.view.mode = m
        imgui.separator()
        if imgui.menu_item_simple("Reset view", "R") and state.view.nav is not None:
            state.view.nav.reset()
        for k, c in enumerate(state.model.cameras):
            if (
                imgui.menu_item_simple(f"Camera: {c.name or k}", None, k == state.view.camera_index)
                and state.view.nav
            ):
                state.view.camera_index = k
                state.view.nav.reset(c)
        imgui.end_menu()


def _focus(window: str) -> None:
    try:
        hello_imgui.get_runner_params().docking_params.focus_dockable_window(window)
    except Exception:  # outside a hello_imgui run (tests)
        pass


def error_window(state: AppState) -> None:
    """The last error, in a small window over the view, until dismissed."""
    if not state.messages.error:
        return
    vp = imgui.get_main_viewport()
    imgui.set_next_window_pos(
        ImVec2(vp.work_pos.x + vp.work_size.x * 0.5, vp.work_pos.y + 40), imgui.Cond_.always, ImVec2(0.5, 0.0)
    )
    imgui.set_next_window_size_constraints(ImVec2(300, 0), ImVec2(vp.work_size.x * 0.8, 400))
    flags = (
        imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_docking
    )
    opened, keep = imgui.begin("Error", True, flags)
    if opened:
        imgui.push_style_color(imgui.Col_.text, ImVec4(1.0, 0.45, 0.4, 1.0))
        imgui.text_wrapped(state.messages.error)
        imgui.pop_style_color()
        imgui.text_colored(DIM, "the viewer keeps showing the last good model")
        if imgui.button("Dismiss"):
            keep = False
    imgui.end()
    if not keep:
        state.messages.clear_error()


def hud_lines(state: AppState) -> list[str]:
    """Text drawn at the bottom of the view: the day-cycle moment and its texture memory against
    the budget (N states cost N texture layers), the re-solve in progress."""
    lines = []
    if state.lighting.day_cycle and state.lighting.solution_set is not None:
        lines.append(f"day {state.lighting.day_time:.2f}: {state.lighting.day_label()}")
        if sun_label(state):
            lines.append(sun_label(state))
        mem = state.model.memory
        if mem:
            n = int(mem.get("solutions", 1))
            used = float(mem.get("texture_bytes", 0))
            on = state.tuning.budget_on
            budget = f"{_mb(float(state.tuning.budget_mb) * MB)} budget" if on else "no budget"
            lines.append(f"texture {n} x {_mb(used / max(n, 1))} = {_mb(used)} / {budget}")
    if state.lighting.relighting:
        lines.append("re-solving the lighting...")
    return lines
