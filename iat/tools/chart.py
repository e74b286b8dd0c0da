"""``iat chart``: speed against accuracy over a sweep of bake policies and solver tolerances.

For every model, every solver tolerance and every ``threshold x scale x method``
bake of that solution (plus the plain mesh of each solution), one point:

- error: mean FLIP over a few camera-path frames against the *finest bake*
  (threshold 0, scale 1, method scan, of the tightest-tolerance solution), and
  against a Mitsuba path-traced reference where one is made (the Cornell box by
  default); PSNR against the finest bake and against that solution's mesh;
- GPU memory: texture bytes (the bake's memory report: atlas pages, mip chain and
  waste included) plus vertex and index bytes as the renderer uploads them
  (texture memory alone would put the all-mesh points at zero);
- frame time: the mean over the camera path drawn offscreen, ``ctx.finish()`` after each
  frame (best of two rounds); and triangles drawn.

Every bake here stores radiance in every texel (``detail=False``): detail textures
exist in IAT mode only, and the error measures the illumination.

The Pareto front (points that no other point beats on both error and cost) is
marked, per cost axis. One row of panels per model (error against memory, frame
time and triangles; and against the path-traced reference where there is one); the same data as JSON next
to the PNG. Library: :func:`run_chart`; :func:`main` is the CLI wrapper.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from iat.errors import OptionError
from iat.progress import Progress
from iat.radiosity.cache import cached_solve
from iat.tools.bench import (
    DEFAULT_CACHE,
    FrameTimer,
    bench_solve_options,
    default_models,
    interpolate_path,
    limit_flip_threads,
    machine_info,
    path_poses,
    pick,
    resolve_model,
)
from iat.tools.common import jsonable, memory_report, policy_dict, psnr_from, texture_bytes

log = logging.getLogger(__name__)


#: the default sweep (small enough for all five sample models in a few minutes on 2 cores)
#: thresholds: None means (0, D // 2, D - 1, D) for the solve's max depth D (all textured ... deepest only)
DEFAULT_THRESHOLDS = None
DEFAULT_SCALES = (1.0, 0.5, 0.25)
DEFAULT_METHODS = ("bilinear", "scan", "bicubic")
DEFAULT_TOLERANCES = (0.1, 0.3)  # the tightest is the benchmark's, so its solution is shared
#: methods baked for the looser tolerances (the tightest gets every method)
DEFAULT_TOLERANCE_METHODS = ("scan",)
#: models compared with a Mitsuba path-traced reference as well
REFERENCE_MODELS = ("cornell_box",)
#: bytes per vertex and per triangle as the renderer uploads them (float32 attributes, uint32 indices)
MESH_VERTEX_BYTES = 4 * (3 + 3)  # position, colour
TEX_VERTEX_BYTES = 4 * (3 + 2 + 1 + 2 + 1)  # position, uv, layer, detail uv, detail flag
INDEX_BYTES = 3 * 4

#: error measures and cost axes of the Pareto fronts
ERRORS = ("flip_vs_finest", "flip_vs_reference")
COSTS = ("gpu_mb", "frame_ms", "triangles")


def sweep_tolerances(tolerances, base) -> list[float]:
    """The sweep's solver tolerances, tightest first (``base.tolerance`` alone when none)."""
    return sorted({float(t) for t in tolerances}) or [float(base.tolerance)]


def pareto_mask(cost, error) -> np.ndarray:
    """(n,) bool: True where no other point has ``cost <= and error <=`` with one of them ``<``.

    cost, error : (n,) float; NaN entries are never on the front and dominate nothing.
    """
    c = np.asarray(cost, dtype=np.float64).reshape(-1)
    e = np.asarray(error, dtype=np.float64).reshape(-1)
    ok = np.isfinite(c) & np.isfinite(e)
    cj, ej = c[None, ok], e[None, ok]
    ci, ei = c[:, None], e[:, None]
    dominated = ((cj <= ci) & (ej <= ei) & ((cj < ci) | (ej < ei))).any(axis=1)
    return ok & ~dominated


def default_thresholds(max_depth: int) -> tuple[int, ...]:
    """``(0, D // 2, D - 1, D)`` without repeats: every patch textured ... only the deepest."""
    d = int(max_depth)
    return tuple(sorted({0, d // 2, max(d - 1, 0), d}))


def _geometry_bytes_baked(baked) -> int:
    return int(
        len(baked.mesh_positions) * MESH_VERTEX_BYTES
        + len(baked.mesh_indices) * INDEX_BYTES
        + len(baked.tex_positions) * TEX_VERTEX_BYTES
        + len(baked.tex_indices) * INDEX_BYTES
    )


def _geometry_bytes_mesh(sol) -> int:
    drawn = sol.drawn_mesh()
    return int(len(drawn.position) * MESH_VERTEX_BYTES + len(drawn.triangles) * INDEX_BYTES)


def _mean_flip(images, refs, exposures) -> float:
    from iat.measure.metrics import flip

    return float(np.mean([flip(a, b, exposure=e) for a, b, e in zip(images, refs, exposures, strict=True)]))


def _psnr(images, refs, exposures) -> float:
    """PSNR over all frames, peak = each frame's display white (1 / exposure); capped at 200 dB."""
    v = [
        float(np.mean((a.astype(np.float64) - b) ** 2)) * e * e
        for a, b, e in zip(images, refs, exposures, strict=True)
    ]
    return psnr_from(float(np.mean(v)))


@dataclass(frozen=True)
class ChartSettings:
    """What :func:`run_chart` sweeps and measures (its keyword arguments).

    size, frames : (w, h) and frames of the camera path timed; thresholds, scales, methods : the bake
    policies (thresholds None: :func:`default_thresholds` of the solve's depth); tolerances : the
    solves (:func:`sweep_tolerances`); tolerance_methods : the methods baked for all but the
    tightest; solve_options : :class:`iat.radiosity.SolveOptions` (None:
    :func:`~iat.tools.bench.bench_solve_options`); cache_dir : the solution cache (references in its
    ``refs``); error_frames : path frames of the image errors; reference_spp : samples per pixel
    of the Mitsuba reference (None: no reference) of the ``reference_models``.
    """

    size: tuple[int, int] = (160, 120)
    frames: int = 10
    thresholds: tuple | None = DEFAULT_THRESHOLDS
    scales: tuple = DEFAULT_SCALES
    methods: tuple = DEFAULT_METHODS
    tolerances: tuple = DEFAULT_TOLERANCES
    solve_options: object = None
    cache_dir: str | Path = DEFAULT_CACHE
    error_frames: int = 3
    reference_spp: int | None = 64
    reference_models: tuple = REFERENCE_MODELS
    tolerance_methods: tuple = DEFAULT_TOLERANCE_METHODS

    def resolved(self) -> ChartSettings:
        """These settings with the default solve options and thresholds where they are None."""
        base = bench_solve_options() if self.solve_options is None else self.solve_options
        thresholds = default_thresholds(base.max_depth) if self.thresholds is None else self.thresholds
        return replace(self, solve_options=base, thresholds=thresholds)


def chart_model(
    model: str | Path, settings: ChartSettings | None = None, progress: Progress | None = None
) -> dict:
    """One model's sweep: ``{"model", "file", "points": [...], "finest", "reference", "pareto"}``.

    The tightest tolerance gets ``thresholds x scales x methods``, the others
    ``thresholds x scales x tolerance_methods``; every solution also gives a mesh point. A reference
    is rendered at ``settings.reference_spp`` (None: none) whatever the ``reference_models``.
    """
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.color import auto_exposure
    from iat.render.renderer import Renderer

    def step(f, m):
        if progress is not None:
            progress(min(max(f, 0.0), 1.0), m)

    model = resolve_model(model)
    limit_flip_threads()
    cfg = (settings or ChartSettings()).resolved()
    base, thresholds, scales, cache_dir = cfg.solve_options, cfg.thresholds, cfg.scales, cfg.cache_dir
    tols = sweep_tolerances(cfg.tolerances, base)
    full = [(int(t), float(s), str(m)) for t in thresholds for s in scales for m in cfg.methods]
    lean = [(int(t), float(s), str(m)) for t in thresholds for s in scales for m in cfg.tolerance_methods]
    n_steps = len(full) + (len(tols) - 1) * len(lean) + len(tols) + 2
    done = 0

    # solutions (cached), tightest tolerance first: its finest bake is the common reference
    sols = []
    for tol in tols:
        step(done / n_steps, f"solve tolerance {tol:g}")
        scene, sol, info = cached_solve(model, replace(base, tolerance=tol), cache_dir)
        sols.append((tol, scene, sol, info))
        done += 1
    scene = sols[0][1]
    cams = interpolate_path(path_poses(scene), cfg.frames)
    ecams = pick(cams, cfg.error_frames)
    w, h = int(cfg.size[0]), int(cfg.size[1])

    points: list[dict] = []
    r = Renderer()
    try:
        gl_renderer = str(r.ctx.info.get("GL_RENDERER", ""))
        timer = FrameTimer(r, (w, h))

        def frame_ms(mode: str) -> float:
            timer.run(cams[:1], mode)  # warm-up
            return 1000.0 * min(timer.run(cams, mode) for _ in range(2)) / len(cams)

        try:
            # the finest bake of the tightest solution, its mesh, and the path-traced reference
            tol0, _, sol0, _ = sols[0]
            finest_policy = BakePolicy(threshold=0, scale=1.0, method="scan", detail=False)
            finest = Baker(sol0, scene).bake(finest_policy)
            r.set_solution(sol0)
            r.set_baked(finest)
            finest_imgs = [r.render(c, size=(w, h), mode="iat") for c in ecams]
            mesh0_imgs = [r.render(c, size=(w, h), mode="mesh") for c in ecams]
            exps = [auto_exposure(im) for im in finest_imgs]
            mexps = [auto_exposure(im) for im in mesh0_imgs]
            ref_imgs, ref_info = None, None
            if cfg.reference_spp:
                step(done / n_steps, "path-traced reference")
                ref_imgs, ref_info = _references(scene, ecams, (w, h), int(cfg.reference_spp), cache_dir)
            rexps = [auto_exposure(im) for im in ref_imgs] if ref_imgs is not None else None
            done += 1

            def measure(imgs) -> dict:
                d = {
                    "flip_vs_finest": _mean_flip(imgs, finest_imgs, exps),
                    "psnr_vs_finest": _psnr(imgs, finest_imgs, exps),
                    "psnr_vs_mesh": _psnr(imgs, mesh0_imgs, mexps),
                    "flip_vs_reference": None,
                }
                if ref_imgs is not None:
                    d["flip_vs_reference"] = _mean_flip(imgs, ref_imgs, rexps)
                return d

            for k, (tol, _, sol, info) in enumerate(sols):
                policies = full if k == 0 else lean
                baker = Baker(sol, scene)
                r.set_solution(sol)
                step(done / n_steps, f"tol {tol:g}: mesh")
                imgs = [r.render(c, size=(w, h), mode="mesh") for c in ecams]
                st = r.stats()
                points.append(
                    {
                        "kind": "mesh",
                        "tolerance": tol,
                        "threshold": None,
                        "scale": None,
                        "method": None,
                        "texture_mb": 0.0,
                        "gpu_mb": _geometry_bytes_mesh(sol) / 2**20,
                        "triangles": int(len(sol.drawn_mesh().triangles)),
                        "draw_calls": int(st["draw_calls"]),
                        "frame_ms": frame_ms("mesh"),
                        "bake_s": None,
                        "solve_s": info["solve_s"],
                        **measure(imgs),
                    }
                )
                done += 1
                for t, s, m in policies:
                    step(done / n_steps, f"tol {tol:g}: t={t} s={s:g} {m}")
                    pol = BakePolicy(threshold=t, scale=s, method=m, detail=False)
                    t0 = time.perf_counter()
                    baked = baker.bake(pol)
                    bake_s = time.perf_counter() - t0
                    r.set_baked(baked)
                    imgs = [r.render(c, size=(w, h), mode="iat") for c in ecams]
                    st = r.stats()
                    mem = memory_report(baked)
                    tex = texture_bytes(mem)
                    points.append(
                        {
                            "kind": "iat",
                            "tolerance": tol,
                            "threshold": t,
                            "scale": s,
                            "method": m,
                            "texture_mb": tex / 2**20,
                            "gpu_mb": int(mem.get("total_bytes", tex + _geometry_bytes_baked(baked))) / 2**20,
                            "triangles": int(len(baked.mesh_indices) + len(baked.tex_indices)),
                            "draw_calls": int(st["draw_calls"]),
                            "frame_ms": frame_ms("iat"),
                            "bake_s": bake_s,
                            "solve_s": info["solve_s"],
                            **measure(imgs),
                        }
                    )
                    done += 1
        finally:
            timer.release()
    finally:
        r.release()

    pareto = {}
    for err in ERRORS:
        e = np.array([np.nan if p[err] is None else p[err] for p in points], dtype=np.float64)
        for cost in COSTS:
            c = np.array([p[cost] for p in points], dtype=np.float64)
            mask = pareto_mask(c, e)
            pareto[f"{err}/{cost}"] = [int(i) for i in np.flatnonzero(mask)]
    step(1.0, "done")
    return jsonable(
        {
            "model": model.stem,
            "file": str(model),
            "patches": int(scene.n_patches),
            "finest": {"tolerance": tols[0], "policy": policy_dict(finest_policy)},
            "reference": ref_info,
            "gl_renderer": gl_renderer,
            "points": points,
            "pareto": pareto,
        }
    )


def _references(scene, cams, size, spp: int, cache_dir) -> tuple[list | None, dict | None]:
    """Mitsuba references of ``cams`` (cached in ``cache_dir/refs``), or (None, None) without mitsuba."""
    try:
        from iat.measure.reference import mitsuba_variant, render_reference_cached
    except ImportError:
        return None, None
    try:
        t0 = time.perf_counter()
        imgs = [render_reference_cached(scene, c, size, spp, Path(cache_dir) / "refs") for c in cams]
        return imgs, {
            "renderer": "mitsuba3",
            "variant": mitsuba_variant(),
            "spp": spp,
            "frames": len(cams),
            "time_s": time.perf_counter() - t0,
        }
    except ImportError as e:
        log.warning("no path-traced reference: %s", e)
        return None, None


def run_chart(
    models=(),
    out: str | Path = "chart.png",
    progress: Progress | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    **settings,
) -> dict:
    """Sweep every model, write ``out`` (PNG, one row of panels per model) and ``out`` with ``.json``.

    workers, scheduler : solve the sweep's solutions first as parallel Dask tasks
      (:func:`iat.tools.batch.presolve`) on that many local workers or on that cluster; the
      measuring (frame times above all) stays in this process, one model after another.

    models : names or paths (empty: the sample models that exist); settings : the fields of
    :class:`ChartSettings`. Returns the JSON dict:
    ``{"settings", "machine", "models": [{"model", "points": [{kind, tolerance, threshold,
    scale, method, texture_mb, gpu_mb, triangles, draw_calls, frame_ms, bake_s, solve_s,
    flip_vs_finest, psnr_vs_finest, psnr_vs_mesh, flip_vs_reference}], "pareto":
    {"<error>/<cost>": [point indices]}, ...}], "png", "json"}``.
    """
    cfg = ChartSettings(**settings).resolved()
    base, cache_dir = cfg.solve_options, cfg.cache_dir
    skipped: list[str] = []
    if models:
        paths = [resolve_model(m) for m in models]
    else:
        paths, skipped = default_models()
    out = Path(out)
    if workers is not None or scheduler:
        from iat.tools.batch import presolve, print_errors

        pairs = [
            (p, replace(base, tolerance=t)) for p in paths for t in sweep_tolerances(cfg.tolerances, base)
        ]
        report = presolve(pairs, cache_dir, workers=workers, scheduler=scheduler, progress=progress)
        if report is not None and report.failed:
            print_errors(report, prog="iat chart")
            raise OptionError(f"{len(report.failed)} of the sweep's solves failed (see above)")
    rows = []
    n = max(len(paths), 1)
    for k, p in enumerate(paths):

        def sub(f, m, k=k, p=p):
            if progress is not None:
                return progress((k + f) / n, f"{Path(p).stem}: {m}")
            return True

        spp = cfg.reference_spp if Path(p).stem in set(cfg.reference_models or ()) else None
        rows.append(chart_model(p, replace(cfg, reference_spp=spp), progress=sub))
    result = jsonable(
        {
            "settings": {
                "size": [int(cfg.size[0]), int(cfg.size[1])],
                "frames": int(cfg.frames),
                "error_frames": int(cfg.error_frames),
                "thresholds": list(cfg.thresholds),
                "scales": list(cfg.scales),
                "methods": list(cfg.methods),
                "tolerances": list(cfg.tolerances),
                "tolerance_methods": list(cfg.tolerance_methods),
                "solve_options": asdict(base),
                "reference_spp": cfg.reference_spp,
                "reference_models": list(cfg.reference_models or ()),
            },
            "machine": machine_info(rows[0]["gl_renderer"] if rows else ""),
            "models": rows,
            "skipped": skipped,
            "png": str(out),
            "json": str(out.with_suffix(".json")),
        }
    )
    plot(result, out)
    _write_json(out.with_suffix(".json"), result)
    return result


def _write_json(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)


_GPU_LABEL = "GPU memory, MB (textures + geometry)"
_METHOD_COLOURS = {"bilinear": "tab:blue", "scan": "tab:orange", "bicubic": "tab:green"}
_TOL_MARKERS = ["o", "s", "^", "D", "v", "P"]


def plot(result: dict, out: str | Path) -> Path:
    """Draw the chart of a :func:`run_chart` result: per model a row of three panels (Agg)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    rows = result["models"]
    n = max(len(rows), 1)
    row_h, head_h = 3.4, 0.75  # inches
    fig, axes = plt.subplots(n, 4, figsize=(20, row_h * n + head_h), squeeze=False)
    tols = sorted({p["tolerance"] for row in rows for p in row["points"]})
    marker = {t: _TOL_MARKERS[i % len(_TOL_MARKERS)] for i, t in enumerate(tols)}
    panels = [
        ("gpu_mb", "flip_vs_finest", _GPU_LABEL, "FLIP vs finest bake"),
        ("frame_ms", "flip_vs_finest", "frame time, ms", "FLIP vs finest bake"),
        ("triangles", "flip_vs_finest", "triangles drawn", "FLIP vs finest bake"),
        ("gpu_mb", "flip_vs_reference", _GPU_LABEL, "FLIP vs path-traced reference"),
    ]
    size = result["settings"]["size"]
    for r, row in enumerate(rows):
        pts = row["points"]
        for c, (xk, yk, xl, yl) in enumerate(panels):
            ax = axes[r][c]
            have = [p for p in pts if p.get(yk) is not None]
            if not have:  # no path-traced reference for this model: leave the cell empty
                ax.set_axis_off()
                continue
            for p in have:
                if p["kind"] == "mesh":
                    ax.scatter(
                        p[xk],
                        p[yk],
                        marker=marker[p["tolerance"]],
                        facecolor="none",
                        edgecolor="black",
                        s=60,
                        linewidths=1.4,
                        zorder=3,
                    )
                else:
                    ax.scatter(
                        p[xk],
                        p[yk],
                        marker=marker[p["tolerance"]],
                        color=_METHOD_COLOURS.get(p["method"], "0.5"),
                        s=14 + 26 * p["scale"],
                        alpha=0.75,
                        linewidths=0,
                        zorder=2,
                    )
            front = sorted((pts[i] for i in row["pareto"].get(f"{yk}/{xk}", [])), key=lambda p: p[xk])
            if front:
                ax.step(
                    [p[xk] for p in front],
                    [p[yk] for p in front],
                    where="post",
                    color="crimson",
                    lw=1.2,
                    zorder=4,
                )
                ax.scatter(
                    [p[xk] for p in front],
                    [p[yk] for p in front],
                    s=70,
                    facecolor="none",
                    edgecolor="crimson",
                    lw=1.2,
                    zorder=5,
                )
            xs = [p[xk] for p in have]
            if min(xs) > 0 and max(xs) / min(xs) > 20:
                ax.set_xscale("log")
                ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel(xl, fontsize=8)
            ax.set_ylabel(yl, fontsize=8)
            ax.set_title(f"{row['model']}: {yl} against {xl.split(',')[0]}", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(True, which="both", alpha=0.25)
    handles = [Line2D([], [], marker="o", ls="", color=col, label=m) for m, col in _METHOD_COLOURS.items()]
    handles += [Line2D([], [], marker=marker[t], ls="", color="0.3", label=f"tolerance {t:g}") for t in tols]
    handles += [
        Line2D(
            [],
            [],
            marker="o",
            ls="",
            markerfacecolor="none",
            markeredgecolor="black",
            label="mesh (no texture)",
        ),
        Line2D([], [], color="crimson", marker="o", markerfacecolor="none", label="Pareto front"),
    ]
    top = 1.0 - head_h / (row_h * n + head_h)
    fig.suptitle(
        f"IAT speed against accuracy: {size[0]}x{size[1]}, {result['machine'].get('gl_renderer', '')}; "
        "colour = method, marker = solver tolerance, marker size = texture scale",
        fontsize=10,
        y=1.0 - 0.15 / (row_h * n + head_h),
    )
    fig.legend(
        handles=handles,
        loc="upper center",
        ncol=len(handles),
        fontsize=8,
        frameon=False,
        bbox_to_anchor=(0.5, 1.0 - 0.4 / (row_h * n + head_h)),
    )
    fig.tight_layout(rect=(0, 0, 1, top))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
