"""Image and seam metrics: PSNR, FLIP, relative error, lit-pixel masks, edge mismatch.

Images are ``(h, w, 3)`` float arrays of linear RGB radiance (the renderer's
float read-back, :func:`iat.measure.reference.render_reference`), unless said otherwise.
Every function is vectorised numpy and returns plain Python floats.
"""

from __future__ import annotations

import numpy as np

from iat.color import LUMINANCE_WEIGHTS, srgb_encode

__all__ = [
    "luminance",
    "psnr",
    "srgb_tonemap",
    "flip",
    "relative_error",
    "lit_mask",
    "edge_mismatch",
]


def _image(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{name}: expected an (h, w, 3) image, got shape {a.shape}")
    return a


def _same_shape(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")


def luminance(img) -> np.ndarray:
    """Rec. 709 luminance of linear RGB.

    img : (..., 3) float linear RGB. Returns (...) float64.
    """
    a = np.asarray(img, dtype=np.float64)
    if a.shape[-1] != 3:
        raise ValueError(f"luminance: last axis must be RGB (3), got shape {a.shape}")
    return a @ LUMINANCE_WEIGHTS


def psnr(a, b, peak: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB, ``10 log10(peak**2 / MSE)``.

    a, b : (h, w, 3) float linear radiance (``b`` is the reference).
    peak : the signal peak; default the maximum of ``b``.
    MSE is the mean over all pixels and channels. Returns ``inf`` for identical
    images, ``-inf`` when the peak is 0 and the images differ.
    """
    a, b = _image(a, "a"), _image(b, "b")
    _same_shape(a, b)
    mse = float(np.mean((a - b) ** 2))
    if mse == 0.0:
        return float("inf")
    p = float(np.max(b)) if peak is None else float(peak)
    if p <= 0.0:
        return float("-inf")
    return float(10.0 * np.log10(p * p / mse))


def srgb_tonemap(img, exposure: float = 1.0) -> np.ndarray:
    """Tone map for display and LDR metrics: ``clamp(exposure * x, 0, 1)``, then sRGB encode.

    img : (..., 3) float linear radiance. Returns (...) float32 in [0, 1] (sRGB-encoded).
    """
    x = np.clip(np.asarray(img, dtype=np.float64) * float(exposure), 0.0, 1.0)
    return srgb_encode(x).astype(np.float32)


def flip(test, reference, exposure: float = 1.0, return_map: bool = False):
    """Mean LDR-FLIP error (NVIDIA ꟻLIP, package ``flip_evaluator``) of ``test`` against ``reference``.

    test, reference : (h, w, 3) float linear radiance. Both are tone-mapped with
    :func:`srgb_tonemap` (``clamp(exposure * x)`` then sRGB) and compared as LDR
    sRGB images at FLIP's default 67 pixels per degree.
    Returns the mean error, a float in [0, 1] (0 for identical images); with
    ``return_map=True`` returns ``(mean, (h, w) float32 error map)``.
    Raises ImportError when ``flip_evaluator`` is not installed.
    """
    try:
        import flip_evaluator
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "iat.measure.metrics.flip needs the 'flip-evaluator' package (NVIDIA FLIP): "
            f"pip install flip-evaluator ({e})"
        ) from e
    t, r = _image(test, "test"), _image(reference, "reference")
    _same_shape(t, r)
    t_ldr = np.ascontiguousarray(srgb_tonemap(t, exposure))
    r_ldr = np.ascontiguousarray(srgb_tonemap(r, exposure))
    err_map, mean, _params = flip_evaluator.evaluate(
        r_ldr, t_ldr, "LDR", inputsRGB=True, applyMagma=False, computeMeanError=True
    )
    mean = float(mean)
    if return_map:
        return mean, np.asarray(err_map, dtype=np.float32).reshape(t.shape[:2])
    return mean


def relative_error(test, reference, mask=None, floor: float = 1e-3, return_map: bool = False):
    """Mean relative luminance error ``|Lt - Lr| / max(Lr, floor)``.

    test, reference : (h, w, 3) float linear radiance; L is Rec. 709 luminance.
    mask : (h, w) bool pixels to average over (e.g. :func:`lit_mask`); None: all.
    floor : lower bound of the denominator (radiance units), so black reference
    pixels do not blow up the ratio.
    Returns the mean (float; NaN when the mask selects no pixel); with
    ``return_map=True`` returns ``(mean, (h, w) float64 per-pixel map)`` (the
    map covers every pixel, masked or not).
    """
    t, r = _image(test, "test"), _image(reference, "reference")
    _same_shape(t, r)
    lr = luminance(r)
    emap = np.abs(luminance(t) - lr) / np.maximum(lr, float(floor))
    if mask is None:
        sel = emap
    else:
        m = np.asarray(mask, dtype=bool)
        if m.shape != emap.shape:
            raise ValueError(f"mask shape {m.shape} does not match image shape {emap.shape}")
        sel = emap[m]
    mean = float(sel.mean()) if sel.size else float("nan")
    if return_map:
        return mean, emap
    return mean


def lit_mask(reference, rel: float = 0.02) -> np.ndarray:
    """The "lit diffuse surfaces" of an image: luminance above ``rel`` x its 99th percentile.

    reference : (h, w, 3) float linear radiance. Returns (h, w) bool.
    The 99th percentile (not the maximum) keeps a few very bright emitter pixels
    from setting the scale; an all-black image gives an all-False mask.
    """
    lum = luminance(_image(reference, "reference"))
    if lum.size == 0:
        return np.zeros(lum.shape, dtype=bool)
    return lum > float(rel) * float(np.percentile(lum, 99.0))


def smooth_lit_mask(reference) -> np.ndarray:
    """(h, w) bool: lit pixels (mean above 0.05) away from edges: the 3 x 3 neighbourhood varies by
    less than 15 % of its mean plus four times the image's mean local spread, which absorbs a path
    tracer's noise. The pixels a mesh-against-reference error is judged on (edges are the mesh's
    resolution, not its light).

    reference : (h, w, 3) float linear radiance."""
    y = _image(reference, "reference").mean(axis=2)
    pad = np.pad(y, 1, mode="edge")
    win = np.stack([pad[i : i + y.shape[0], j : j + y.shape[1]] for i in range(3) for j in range(3)])
    return (y > 0.05) & (
        win.max(axis=0) - win.min(axis=0) < 0.15 * win.mean(axis=0) + 4 * win.std(axis=0).mean()
    )


def reference_errors(test, reference, mask=None) -> dict:
    """A render against a path-traced reference, in linear radiance: ``rel_smooth`` (mean absolute
    error over the mean on :func:`smooth_lit_mask` pixels), ``rel_blocks`` (the same on 8 x 8 pixel
    block means above 0.05: robust to edges, sensitive to any bias) and ``bias`` (mean over the
    smooth pixels / the reference's, minus 1).

    test, reference : (h, w, 3) float, h and w multiples of 8; mask : (h, w) bool (default
    :func:`smooth_lit_mask` of ``reference``)."""
    img, ref = _image(test, "test").astype(np.float64), _image(reference, "reference").astype(np.float64)
    _same_shape(img, ref)
    mask = smooth_lit_mask(ref) if mask is None else mask
    err = np.abs(img - ref).mean(axis=2)
    h, w = ref.shape[:2]
    blocks = (h // 8, 8, w // 8, 8)
    a = ref.mean(axis=2).reshape(blocks).mean(axis=(1, 3))
    b = img.mean(axis=2).reshape(blocks).mean(axis=(1, 3))
    bl = a > 0.05
    return {
        "rel_smooth": float(err[mask].sum() / ref.mean(axis=2)[mask].sum()),
        "rel_blocks": float(np.abs(a - b)[bl].sum() / a[bl].sum()),
        "bias": float(img[mask].mean() / ref[mask].mean() - 1.0),
    }


def edge_mismatch(values_a, values_b) -> tuple[float, float]:
    """Seam error: how much two sides of shared edges disagree.

    values_a, values_b : (n, 3) float radiance sampled at the same n points of
    shared edges, from each side (e.g. the texels of two neighbouring patches).
    Returns ``(max, mean)`` of the absolute difference over all points and
    channels; ``(0.0, 0.0)`` when n is 0.
    """
    a = np.asarray(values_a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(values_b, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"edge_mismatch: shapes differ: {a.shape} vs {b.shape}")
    if a.size == 0:
        return 0.0, 0.0
    d = np.abs(a - b)
    return float(d.max()), float(d.mean())
