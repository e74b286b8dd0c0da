"""``iat bench``: the report's Figure 3 (mesh against IAT), and more.

For each model: triangles, frame rate over the model's camera path and texture
memory, the columns of the report's Figure 3; and beyond it draw calls, the
IAT-against-mesh image error (PSNR and FLIP over path frames), the seam error,
solve, bake, re-bake and load times.

Frame rate: the path's poses are interpolated to a fixed number of frames, each
drawn offscreen with :meth:`iat.render.renderer.Renderer.draw` (tone-mapped into an RGBA8
framebuffer, as a window would be) and finished with ``ctx.finish()``; the rate
is ``frames / wall time``, best of ``repeats`` rounds, mesh and IAT rounds
interleaved so that background load hits both alike. It is measured at the
requested size and at a tiny size (:data:`TINY_SIZE`): Mesa's llvmpipe is a
software rasteriser, fill-bound at 640x480, so the tiny size shows the
triangle-bound case that the report's Onyx was in.

The solve uses the solver's defaults (:data:`BENCH_SOLVE` holds no overrides;
26 k-41 k elements on the samples, minutes on 2 cores), the bake the default
:class:`~iat.bake.policy.BakePolicy`.
Solutions are cached (:func:`iat.radiosity.cache.cached_solve`, content-keyed) and solved
again when the model file is newer or the options differ.

Library: :func:`run_bench` returns a JSON-able dict, :func:`format_table` turns
it into Markdown; :func:`main` is the CLI wrapper.
"""

from __future__ import annotations

import logging
import math
import os
import platform
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from iat.camera import Camera
from iat.color import LUMINANCE_WEIGHTS
from iat.errors import LoadError
from iat.progress import Progress
from iat.radiosity.cache import cached_solve
from iat.tools.common import jsonable, memory_report, policy_dict, psnr_from, texture_bytes

log = logging.getLogger(__name__)


#: the sample models, in the order of the table
DEFAULT_MODELS = ("cornell_box", "house", "cave", "lavapit", "pool")
#: where the sample models live
SAMPLE_DIR = Path(__file__).resolve().parents[2] / "sample_models"
#: default solution cache
DEFAULT_CACHE = Path("out") / "bench"
#: the triangle-bound case: few pixels, so per-vertex work dominates the frame
TINY_SIZE = (64, 48)
#: bump when the JSON layout changes
SCHEMA_VERSION = 1
#: the benchmark's solve: overrides of the solver's defaults, none now that the defaults are fast
#: (depth 6, tolerance 0.1, 5 % unshot + ambient: 2 s for the Cornell box, 30-75 s for the other
#: samples on 2 shared cores; this was depth 4 without indirect refinement while the defaults
#: took hours on the house)
BENCH_SOLVE: dict = {}


def bench_solve_options(**overrides):
    """:class:`~iat.radiosity.SolveOptions` of :data:`BENCH_SOLVE` (fields the solver lacks are dropped)."""
    from dataclasses import fields

    from iat.radiosity import SolveOptions

    known = {f.name for f in fields(SolveOptions)}
    return SolveOptions(**{k: v for k, v in {**BENCH_SOLVE, **overrides}.items() if k in known})


#: the report's Figure 3 (Silicon Graphics Onyx Reality Engine 2, 16 MB texture memory, Performer):
#: name -> (our model, triangles polygon, fps polygon, triangles IAT, fps IAT, texture MB IAT)
REPORT_FIGURE3 = {
    "maus": ("house", 95536, 7.5, 39820, 15.0, 1.26),
    "cave": ("cave", 43960, 20.0, 19492, 30.0, 0.77),
    "lavapit": ("lavapit", 55158, 8.6, 7183, 30.0, 1.48),
    "pool": ("pool", 84384, 8.6, 39865, 15.0, 2.76),
}
_REPORT_BY_MODEL = {v[0]: k for k, v in REPORT_FIGURE3.items()}
_REPORT_FIELDS = ("model", "triangles_mesh", "fps_mesh", "triangles_iat", "fps_iat", "texture_mb")


# -- models and solutions ----------------------------------------------------------------------
def resolve_model(name: str | Path) -> Path:
    """A model file from a path or a sample model's name (``house`` -> ``sample_models/house.glb``)."""
    p = Path(name)
    if p.is_file():
        return p
    for cand in (SAMPLE_DIR / f"{p.name}.glb", SAMPLE_DIR / p.name):
        if p.suffix == "" and cand.is_file():
            return cand
    raise LoadError("no such model file (nor a sample model of that name)", p)


def default_models() -> tuple[list[Path], list[str]]:
    """The sample models that exist, and the names of those that do not (yet)."""
    found, missing = [], []
    for name in DEFAULT_MODELS:
        f = SAMPLE_DIR / f"{name}.glb"
        (found if f.is_file() else missing).append(f if f.is_file() else name)
    return found, missing


# -- camera paths ------------------------------------------------------------------------------
def path_poses(scene) -> list[Camera]:
    """The model's walkthrough: ``camera_paths["default"]`` (or the first path), else its cameras."""
    paths = getattr(scene, "camera_paths", {}) or {}
    poses = paths.get("default") or (next(iter(paths.values())) if paths else None)
    if poses:
        return list(poses)
    return list(scene.cameras) or [scene.default_camera()]


def interpolate_path(poses: list[Camera], frames: int) -> list[Camera]:
    """``frames`` cameras evenly along the open polyline of ``poses`` (eye, target, up, fov linear).

    The first frame is the first pose, the last frame the last pose; a single pose repeats.
    """
    frames = int(frames)
    if frames < 1:
        raise ValueError("frames must be >= 1")
    k = len(poses)
    if k == 0:
        raise ValueError("a camera path needs at least one pose")
    eye = np.array([p.eye for p in poses])
    tgt = np.array([p.target for p in poses])
    up = np.array([p.up for p in poses])
    fov = np.array([p.yfov for p in poses], dtype=np.float64)
    t = np.linspace(0.0, k - 1.0, frames) if frames > 1 else np.zeros(1)
    i0 = np.minimum(np.floor(t).astype(int), k - 1)
    i1 = np.minimum(i0 + 1, k - 1)
    w = (t - i0)[:, None]
    out = []
    for f in range(frames):
        a, b, s = i0[f], i1[f], float(w[f, 0])
        u = (1 - s) * up[a] + s * up[b]
        if np.linalg.norm(u) < 1e-9:
            u = up[a]
        out.append(
            Camera(
                eye=(1 - s) * eye[a] + s * eye[b],
                target=(1 - s) * tgt[a] + s * tgt[b],
                up=u,
                yfov=float((1 - s) * fov[a] + s * fov[b]),
                znear=min(poses[a].znear, poses[b].znear),
                zfar=max(poses[a].zfar, poses[b].zfar),
                name=f"frame {f}",
            )
        )
    return out


def pick(items: list, n: int) -> list:
    """``n`` items evenly spread over ``items`` (all when there are fewer)."""
    if n >= len(items):
        return list(items)
    idx = np.unique(np.round(np.linspace(0, len(items) - 1, max(n, 1))).astype(int))
    return [items[i] for i in idx]


# -- measurements ------------------------------------------------------------------------------
class FrameTimer:
    """Times whole frames of a :class:`~iat.render.renderer.Renderer` into its own offscreen RGBA8 target."""

    def __init__(self, renderer, size: tuple[int, int]):
        self.r = renderer
        self.size = (int(size[0]), int(size[1]))
        ctx = renderer.ctx
        self._prev = ctx.fbo
        self._color = ctx.renderbuffer(self.size, 4)
        self._depth = ctx.depth_renderbuffer(self.size)
        self.fbo = ctx.framebuffer(color_attachments=[self._color], depth_attachment=self._depth)

    def run(self, cameras: list[Camera], mode: str) -> float:
        """Draw every camera once in ``mode``, ``ctx.finish()`` after each; returns wall seconds."""
        ctx = self.r.ctx
        w, h = self.size
        t0 = time.perf_counter()
        for cam in cameras:
            self.r.draw(cam, mode, viewport=(0, 0, w, h), target=self.fbo, tonemap=True)
            ctx.finish()
        return time.perf_counter() - t0

    def release(self) -> None:
        if self._prev is not None:
            try:
                self._prev.use()
            except Exception:  # pragma: no cover - a released default framebuffer
                pass
        for o in (self.fbo, self._color, self._depth):
            o.release()


def frame_rates(
    renderer,
    cameras: list[Camera],
    size: tuple[int, int],
    modes=("mesh", "iat"),
    repeats: int = 2,
    warmup: int = 2,
) -> dict:
    """Frames per second per mode: ``len(cameras) / best round time``, rounds interleaved across modes.

    Returns ``{mode: {"fps", "frame_ms", "rounds_s": [...]}}``.
    """
    timer = FrameTimer(renderer, size)
    try:
        for m in modes:  # first frames pay for shader variants and texture residency
            timer.run(cameras[: max(1, warmup)], m)
        rounds: dict[str, list[float]] = {m: [] for m in modes}
        for _ in range(max(1, int(repeats))):
            for m in modes:
                rounds[m].append(timer.run(cameras, m))
    finally:
        timer.release()
    out = {}
    for m in modes:
        best = min(rounds[m])
        out[m] = {
            "fps": len(cameras) / best if best > 0 else float("inf"),
            "frame_ms": 1000.0 * best / len(cameras),
            "rounds_s": rounds[m],
        }
    return out


_FLIP_LIMITED = False


def limit_flip_threads(n: int = 1) -> bool:
    """Run FLIP (``flip_evaluator``, OpenMP) on ``n`` threads; returns whether that was possible.

    On a small machine shared with llvmpipe's rasteriser threads and other work, OpenMP's
    spinning barriers made a 64x48 FLIP ten times slower than one thread; the benchmark's
    FLIPs are small, so one thread is the robust choice. Best effort: a no-op when the
    package or its bundled libgomp is not found.
    """
    global _FLIP_LIMITED
    if _FLIP_LIMITED:
        return True
    try:
        import ctypes
        import glob

        import flip_evaluator

        base = Path(flip_evaluator.__file__).resolve().parent
        libs = glob.glob(str(base.parent / "flip_evaluator.libs" / "libgomp*.so*")) + glob.glob(
            str(base / "libgomp*.so*")
        )
        if not libs:
            return False
        ctypes.CDLL(libs[0]).omp_set_num_threads(int(n))
    except (ImportError, OSError, AttributeError):
        return False
    _FLIP_LIMITED = True
    return True


def image_errors(renderer, cameras: list[Camera], size: tuple[int, int], with_flip: bool = True) -> dict:
    """IAT against mesh, same solution, over ``cameras``: PSNR, FLIP and relative error.

    Both are rendered as float32 linear radiance. PSNR's peak is the frame's
    display white: the radiance that the automatic exposure of the mesh frame
    (:func:`iat.color.auto_exposure`) maps to 1, so a bright emitter in view
    does not inflate it. FLIP compares the two tone-mapped with that exposure.
    The relative error is over the lit pixels of the mesh frame.
    Returns ``{"frames", "psnr_db" (over all frames' pixels), "psnr_db_min" (worst frame),
    "flip_mean", "flip_max", "rel_error_lit"}``.
    """
    from iat.color import auto_exposure
    from iat.measure.metrics import flip, lit_mask, relative_error

    if with_flip:
        limit_flip_threads()
    sq, n, psnrs, flips, rels = 0.0, 0, [], [], []
    for cam in cameras:
        ref = renderer.render(cam, size=size, mode="mesh")
        img = renderer.render(cam, size=size, mode="iat")
        e = auto_exposure(ref)
        peak = 1.0 / e
        mse = float(np.mean((img.astype(np.float64) - ref) ** 2))
        sq += mse / (peak * peak)
        n += 1
        psnrs.append(psnr_from(mse / (peak * peak)))
        if with_flip:
            flips.append(flip(img, ref, exposure=e))
        m = lit_mask(ref)
        if m.any():
            rels.append(relative_error(img, ref, mask=m))
    return {
        "frames": n,
        "psnr_db": psnr_from(sq / max(n, 1)),
        "psnr_db_min": min(psnrs) if psnrs else None,
        "flip_mean": float(np.mean(flips)) if flips else None,
        "flip_max": float(np.max(flips)) if flips else None,
        "rel_error_lit": float(np.mean(rels)) if rels else None,
    }


def seam_errors(baked, solution) -> dict:
    """Seam error (:func:`iat.measure.seams.seam_error`, absolute radiance along shared coplanar edges)
    of the IAT textures and of the solution's own mesh, for scale: ``{"iat": {...}, "mesh": {...}}``."""
    from iat.measure.seams import seam_error

    return jsonable({"iat": seam_error(baked, solution=solution), "mesh": seam_error(solution)})


def _rebake_policy(policy):
    """A policy one slider step away (threshold + 1), to time a re-bake."""
    return replace(policy, threshold=int(policy.threshold) + 1)


@dataclass(frozen=True)
class BenchSettings:
    """What :func:`run_bench` measures and how (its keyword arguments).

    frames : frames drawn per round over the camera path (interpolated to that many poses)
    size, tiny_size : (w, h) of the fill-bound and of the triangle-bound measurement (tiny_size None:
    none); solve_options : :class:`iat.radiosity.SolveOptions` (None: :func:`bench_solve_options`);
    policy : BakePolicy (None: the default policy); cache_dir : the solution cache;
    error_frames : path frames compared mesh vs IAT, at ``error_size`` (None: ``size``; at a tiny
    size the mip-mapped IAT image is filtered where the mesh aliases, so the comparison says little
    there); repeats : timed rounds of the frames (the best counts); with_flip : the FLIP error too.
    """

    frames: int = 60
    size: tuple[int, int] = (640, 480)
    tiny_size: tuple[int, int] | None = TINY_SIZE
    solve_options: object = None
    policy: object = None
    cache_dir: str | Path = DEFAULT_CACHE
    error_frames: int = 8
    repeats: int = 2
    with_flip: bool = True
    error_size: tuple[int, int] | None = None

    def resolved(self) -> BenchSettings:
        """These settings with the default solve options and policy where they are None."""
        from iat.bake.policy import BakePolicy

        solve_options = bench_solve_options() if self.solve_options is None else self.solve_options
        return replace(
            self, solve_options=solve_options, policy=BakePolicy() if self.policy is None else self.policy
        )


def bench_model(
    model: str | Path, settings: BenchSettings | None = None, progress: Progress | None = None
) -> dict:
    """One model's row of the benchmark (see :func:`run_bench` for the fields)."""
    from iat.bake.baker import Baker
    from iat.render.renderer import Renderer

    def step(frac: float, msg: str) -> None:
        if progress is not None:
            progress(frac, msg)

    model = resolve_model(model)
    cfg = (settings or BenchSettings()).resolved()
    policy, size, tiny_size = cfg.policy, cfg.size, cfg.tiny_size

    def solve_progress(f, m):
        if progress is not None:
            return progress(0.3 * f, f"solve: {m}")
        return True

    step(0.0, "load + solve")
    scene, sol, sinfo = cached_solve(model, cfg.solve_options, cfg.cache_dir, progress=solve_progress)
    step(0.3, "bake")
    baker = Baker(sol, scene)
    t0 = time.perf_counter()
    baked = baker.bake(policy)
    bake_s = time.perf_counter() - t0
    # a slider step: the threshold one up (pages re-blitted from cached tiles), and back (cached pages)
    other = _rebake_policy(policy)
    t0 = time.perf_counter()
    baker.bake(other)
    rebake_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    baked = baker.bake(policy)
    rebake_cached_s = time.perf_counter() - t0
    mem = memory_report(baked)
    seam = seam_errors(baked, sol)
    # IAT against mesh compares illumination: detail textures (report §3.7) exist in IAT mode only,
    # so the image error is measured on the same bake with radiance in every texel
    n_detail = len(getattr(baked, "detail_textures", {}) or {})
    err_baked = baker.bake(replace(policy, detail=False)) if n_detail else baked

    step(0.4, "upload")
    poses = path_poses(scene)
    cams = interpolate_path(poses, cfg.frames)
    r = Renderer()
    try:
        gl_renderer = str(r.ctx.info.get("GL_RENDERER", ""))
        r.ctx.finish()
        t0 = time.perf_counter()
        r.set_solution(sol)
        r.ctx.finish()
        up_mesh = time.perf_counter() - t0
        t0 = time.perf_counter()
        r.set_baked(baked)
        r.ctx.finish()
        up_iat = time.perf_counter() - t0

        counts = {}
        for m in ("mesh", "iat"):
            r.render(cams[0], size=(8, 6), mode=m)
            st = r.stats()
            counts[m] = (int(st["triangles"]), int(st["draw_calls"]))

        step(0.45, f"frames {size[0]}x{size[1]}")
        rates = {_size_key(size): frame_rates(r, cams, size, repeats=cfg.repeats)}
        if tiny_size is not None and tuple(tiny_size) != tuple(size):
            step(0.65, f"frames {tiny_size[0]}x{tiny_size[1]}")
            rates[_size_key(tiny_size)] = frame_rates(r, cams, tiny_size, repeats=cfg.repeats)
        step(0.75, "image error")
        esize = tuple(size) if cfg.error_size is None else tuple(cfg.error_size)
        if err_baked is not baked:
            r.set_baked(err_baked)
        err = image_errors(r, pick(cams, cfg.error_frames), esize, with_flip=cfg.with_flip)
        err["detail_textures_off"] = err_baked is not baked
    finally:
        r.release()
    step(1.0, "done")

    tri_mesh = int(len(sol.drawn_mesh().triangles))
    tri_iat = int(len(baked.mesh_indices) + len(baked.tex_indices))
    textured = np.asarray(baked.patch_textured, dtype=bool)
    row = {
        "model": model.stem,
        "file": str(model),
        "patches": int(scene.n_patches),
        "path_poses": len(poses),
        "triangles_mesh": tri_mesh,
        "triangles_iat": tri_iat,
        "triangles_drawn_mesh": counts["mesh"][0],
        "triangles_drawn_iat": counts["iat"][0],
        "textured_patches": int(textured.sum()),
        "draw_calls_mesh": counts["mesh"][1],
        "draw_calls_iat": counts["iat"][1],
        "texture_mb": texture_bytes(mem) / 2**20,
        "memory": mem,
        "frame_rate": {
            k: {m: v[m]["fps"] for m in v} | {f"{m}_frame_ms": v[m]["frame_ms"] for m in v}
            for k, v in rates.items()
        },
        "error": err,
        "psnr_db": err["psnr_db"],
        "flip": err["flip_mean"],
        "seam_error": seam["iat"],
        "seam_error_mesh": seam["mesh"],
        "radiance_p99": float(np.percentile(sol.vert_radiance.astype(np.float64) @ LUMINANCE_WEIGHTS, 99))
        if len(sol.vert_radiance)
        else 0.0,
        "detail_textures": n_detail,
        "solve_s": sinfo["solve_s"],
        "solve_cached": sinfo["cached"],
        "solve_stats": {k: v for k, v in sol.stats.items() if k != "options"},
        "bake_s": bake_s,
        "rebake_s": rebake_s,
        "rebake_cached_s": rebake_cached_s,
        "load_s": {"scene": sinfo["load_s"], "upload_mesh": up_mesh, "upload_iat": up_iat},
        "policy": policy_dict(baked.policy if getattr(baked, "policy", None) is not None else policy),
        "bake_timings": dict(getattr(baked, "timings", {}) or {}),
        "gl_renderer": gl_renderer,
        "report": _report_row(model.stem),
    }
    return jsonable(row)


def _size_key(size) -> str:
    return f"{int(size[0])}x{int(size[1])}"


def _report_row(stem: str) -> dict | None:
    name = _REPORT_BY_MODEL.get(stem)
    if name is None:
        return None
    _, tm, fm, ti, fi, mb = REPORT_FIGURE3[name]
    return {
        "name": name,
        "triangles_mesh": tm,
        "fps_mesh": fm,
        "triangles_iat": ti,
        "fps_iat": fi,
        "texture_mb": mb,
    }


def _preload_loader() -> None:
    """Import the model loader's lazily imported libraries, so the first model's load time is its own."""
    try:
        import PIL.Image  # noqa: F401
        import pygltflib  # noqa: F401
        import trimesh  # noqa: F401
    except ImportError:  # pragma: no cover - the loader reports what is missing
        pass


def machine_info(gl_renderer: str = "") -> dict:
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count()
    return {
        "cpu_cores": cores,
        "cpu": platform.processor() or platform.machine(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "gl_renderer": gl_renderer,
        "lp_num_threads": os.environ.get("LP_NUM_THREADS"),
        "load_average": _loadavg(),
    }


def _loadavg():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):  # pragma: no cover - not Unix
        return None


def run_bench(models=(), progress: Progress | None = None, **settings) -> dict:
    """The benchmark of ``models`` (names or paths; empty: every sample model that exists).

    settings : the fields of :class:`BenchSettings`.
    progress : ``progress(fraction, message)`` over the whole run.

    Returns ``{"schema", "settings", "machine", "models": [row, ...], "skipped", "report_figure3"}``;
    a row holds ``model, file, patches, triangles_mesh, triangles_iat, draw_calls_mesh,
    draw_calls_iat, texture_mb, memory, frame_rate: {"WxH": {mesh, iat, mesh_frame_ms,
    iat_frame_ms}}, psnr_db, flip, error: {...}, seam_error, solve_s, solve_cached, bake_s,
    rebake_s, load_s: {scene, upload_mesh, upload_iat}, policy, report`` (the report's
    Figure 3 numbers for the matching model, or None).
    """
    cfg = BenchSettings(**settings).resolved()
    skipped: list[str] = []
    if models:
        paths = [resolve_model(m) for m in models]
    else:
        paths, skipped = default_models()
    _preload_loader()
    rows = []
    n = max(len(paths), 1)
    load_start = _loadavg()
    for k, p in enumerate(paths):

        def sub(f, m, k=k, p=p):
            if progress is not None:
                return progress((k + f) / n, f"{Path(p).stem}: {m}")
            return True

        rows.append(bench_model(p, cfg, progress=sub))
    gl = rows[0]["gl_renderer"] if rows else ""
    return jsonable(
        {
            "schema": SCHEMA_VERSION,
            "settings": {
                "frames": int(cfg.frames),
                "size": [int(cfg.size[0]), int(cfg.size[1])],
                "tiny_size": None
                if cfg.tiny_size is None
                else [int(cfg.tiny_size[0]), int(cfg.tiny_size[1])],
                "error_frames": int(cfg.error_frames),
                "error_size": list(cfg.size if cfg.error_size is None else cfg.error_size),
                "repeats": int(cfg.repeats),
                "solve_options": asdict(cfg.solve_options),
                "policy": policy_dict(cfg.policy),
                "cache_dir": str(cfg.cache_dir),
            },
            "machine": {**machine_info(gl), "load_average_start": load_start},
            "models": rows,
            "skipped": skipped,
            "report_figure3": {
                k: dict(zip(_REPORT_FIELDS, v, strict=True)) for k, v in REPORT_FIGURE3.items()
            },
        }
    )


# -- output ------------------------------------------------------------------------------------
def _f(v, fmt: str = ".1f", none: str = "–") -> str:
    if v is None:
        return none
    if isinstance(v, float) and not math.isfinite(v):
        return none
    return format(v, fmt)


def format_table(result: dict) -> str:
    """Markdown: Figure 3 (ours beside the report's), then the columns beyond it."""
    st = result["settings"]
    big = f"{st['size'][0]}x{st['size'][1]}"
    tiny = f"{st['tiny_size'][0]}x{st['tiny_size'][1]}" if st.get("tiny_size") else None
    lines = [
        f"Figure 3, ours: {st['frames']} frames over each model's camera path; "
        f"{result['machine']['gl_renderer'] or 'OpenGL'}, {result['machine']['cpu_cores']} cores. "
        f"Policy: {_policy_brief(st['policy'])}.",
        "",
    ]
    head = ["name", "triangles", f"fps {big}"] + ([f"fps {tiny}"] if tiny else [])
    head += ["texture MB", "draw calls", "report: name", "triangles", "fps", "texture MB"]
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    for row in result["models"]:
        rep = row.get("report")
        for kind in ("mesh", "iat"):
            label = "polygon" if kind == "mesh" else "IAT"
            cells = [
                f"{row['model']} ({label})",
                f"{row[f'triangles_{kind}']:,}",
                _f(row["frame_rate"][big][kind]),
            ]
            if tiny:
                cells.append(_f(row["frame_rate"].get(tiny, {}).get(kind)))
            cells += [
                "-" if kind == "mesh" else _f(row["texture_mb"], ".2f"),
                str(row[f"draw_calls_{kind}"]),
            ]
            if rep:
                cells += [
                    f"{rep['name']} ({label})",
                    f"{rep[f'triangles_{kind}']:,}",
                    _f(rep[f"fps_{kind}"]),
                    "-" if kind == "mesh" else _f(rep["texture_mb"], ".2f"),
                ]
            else:
                cells += ["", "", "", ""]
            lines.append("| " + " | ".join(cells) + " |")
    shown = {row["report"]["name"] for row in result["models"] if row.get("report")}
    rest = [k for k in REPORT_FIGURE3 if k not in shown]
    if rest:
        lines += [
            "",
            "The report's Figure 3 (SGI Onyx Reality Engine 2, Performer), models not run here:",
            "",
        ]
        lines += ["| name | triangles | fps | texture MB |", "|---|---|---|---|"]
        for k in rest:
            _, tm, fm, ti, fi, mb = REPORT_FIGURE3[k]
            lines.append(f"| {k} (polygon) | {tm:,} | {fm:.1f} | - |")
            lines.append(f"| {k} (IAT) | {ti:,} | {fi:.1f} | {mb:.2f} |")
    lines += [
        "",
        "Beyond Figure 3 (IAT against the mesh of the same solution; times in seconds):",
        "",
    ]
    head2 = [
        "model",
        "IAT/mesh triangles",
        f"speed-up {big}",
    ]
    head2 += [f"speed-up {tiny}"] if tiny else []
    head2 += [
        "PSNR dB (worst)",
        "FLIP (max)",
        "seam max IAT (mesh)",
        "radiance p99",
        "solve",
        "bake",
        "re-bake",
        "load scene",
        "upload mesh",
        "upload IAT",
    ]
    lines += ["| " + " | ".join(head2) + " |", "|" + "|".join(["---"] * len(head2)) + "|"]
    for row in result["models"]:
        fr = row["frame_rate"]
        e = row["error"]
        seam = row.get("seam_error") or {}
        cells = [
            row["model"],
            _f(row["triangles_iat"] / max(row["triangles_mesh"], 1), ".3f"),
            _f(_ratio(fr[big]["iat"], fr[big]["mesh"]), ".2f") + "x",
        ]
        if tiny:
            cells.append(_f(_ratio(fr.get(tiny, {}).get("iat"), fr.get(tiny, {}).get("mesh")), ".2f") + "x")
        cells += [
            f"{_f(e['psnr_db'])} ({_f(e['psnr_db_min'])})",
            f"{_f(e['flip_mean'], '.4f')} ({_f(e['flip_max'], '.4f')})",
            f"{_f(_seam_value(seam), '.3g')} ({_f(_seam_value(row.get('seam_error_mesh') or {}), '.3g')})",
            _f(row.get("radiance_p99"), ".3g"),
            _f(row["solve_s"], ".2f") + (" (cached)" if row["solve_cached"] else ""),
            _f(row["bake_s"], ".3f"),
            _f(row["rebake_s"], ".3f"),
            _f(row["load_s"]["scene"], ".3f"),
            _f(row["load_s"]["upload_mesh"], ".3f"),
            _f(row["load_s"]["upload_iat"], ".3f"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    if result.get("skipped"):
        lines += ["", f"Not benchmarked (no model file yet): {', '.join(result['skipped'])}."]
    return "\n".join(lines) + "\n"


def _ratio(a, b):
    if a is None or b is None or not b:
        return None
    return a / b


def _seam_value(seam: dict):
    for k in ("max", "max_abs", "seam_max", "value", "mean"):
        if k in seam and isinstance(seam[k], int | float):
            return seam[k]
    return None


def _policy_brief(p: dict) -> str:
    keys = ("threshold", "scale", "method", "budget_mb", "pixel_format", "mipmaps")
    return ", ".join(f"{k}={p[k]}" for k in keys if k in p)
