"""How to bake: :class:`BakePolicy`, its fields' ranges and their validation."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from iat.bake import atlas
from iat.bake.flatten import METHODS, SCALE_MODES
from iat.bake.formats import BYTES_PER_TEXEL
from iat.errors import OptionError

#: largest texture side we accept (GL_MAX_TEXTURE_SIZE of current desktop GPUs and llvmpipe)
GL_MAX_TEXTURE_SIZE = 16384


@dataclass
class BakePolicy:
    """How to bake. Each field: range, typical value, trade-off.

    threshold : int >= 0, typical 2. Patches whose tree depth >= threshold become one
        textured polygon. 0 textures all; higher = fewer, larger-payoff textures and
        more mesh triangles.
    scale : float > 0, typical 1.0. Texture side factor ((n-1) scale + 1 texels).
        < 1 saves texture memory (blur, seams with "naive"); > 1 costs memory, gains nothing
        for bilinear/scan, smooths bicubic.
    method : "bilinear" | "scan" | "bicubic", typical "bilinear". bilinear = report §3.3;
        scan = exact copy of the mesh at texel centres (§5.1); bicubic = smooth C1 fit (§5.2),
        not identical to the mesh but without its subdivision artefacts.
    scale_mode : "clamped" | "naive", typical "clamped". clamped keeps corners/edges exact so
        neighbours agree; naive resizes images (the report's correspondence errors), for comparison.
    budget_mb : float >= 0 or None, typical None. Texture memory budget in MiB (2**20 bytes);
        when set, threshold and scale are chosen by :func:`choose_policy` (0 = all mesh).
    gutter : int >= 0, typical 2. Edge-replicated texels around each tile. Larger = more mip
        levels usable (1 + floor(log2 gutter)) and less bleeding, more atlas waste.
    page_size : int, power of two in [64, 16384], typical 2048. Atlas page side; a tile
        larger than a page is an error. Larger = fewer pages, coarser memory steps.
    pixel_format : "rgba16f" (8 B/texel, exact) | "rgba8" (4 B, sRGB 8-bit of radiance /
        page_scale) | "rgb9e5" (4 B, shared exponent). Typical "rgba16f".
    mipmaps : bool, typical True. Build the mip levels the gutter allows (less aliasing far
        away; costs 25 % more texture memory with gutter 2).
    detail : bool, typical True. Store incoming light on patches with a detail texture so the
        shader combines both in one pass (§3.7); False stores radiance everywhere.
    lod : bool, typical False. Also bake each textured patch's chain of coarser levels from its
        quad-tree (:mod:`iat.bake.lod`, report §6.2.2): the renderer blends two levels per
        fragment by screen-space texel density. Costs the chain (about 1/3 more texels, packed
        in pages of their own); False bakes, renders and reports exactly as before.
    lod_stream : bool, typical False (implies ``lod``). Keep resident on the GPU only the levels
        the current view needs (streaming by distance); ``budget_mb`` then caps what is resident
        instead of choosing the threshold and scale (the bake keeps every level on the host).
    """

    threshold: int = 2
    scale: float = 1.0
    method: str = "bilinear"
    scale_mode: str = "clamped"
    budget_mb: float | None = None
    gutter: int = 2
    page_size: int = 2048
    pixel_format: str = "rgba16f"
    mipmaps: bool = True
    detail: bool = True
    lod: bool = False
    lod_stream: bool = False

    def validate(self) -> BakePolicy:
        """Raise OptionError naming the bad field; returns self."""
        if not isinstance(self.threshold, (int, np.integer)) or self.threshold < 0:
            raise OptionError(f"threshold must be an integer >= 0, got {self.threshold!r}")
        if not (
            isinstance(self.scale, (int, float, np.number)) and np.isfinite(self.scale) and self.scale > 0
        ):
            raise OptionError(f"scale must be a finite number > 0, got {self.scale!r}")
        if self.method not in METHODS:
            raise OptionError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.scale_mode not in SCALE_MODES:
            raise OptionError(f"scale_mode must be one of {', '.join(SCALE_MODES)}, got {self.scale_mode!r}")
        if self.budget_mb is not None and not (np.isfinite(self.budget_mb) and self.budget_mb >= 0):
            raise OptionError(f"budget_mb must be >= 0 or None, got {self.budget_mb!r}")
        if not isinstance(self.gutter, (int, np.integer)) or not 0 <= self.gutter <= 64:
            raise OptionError(f"gutter must be an integer in 0..64, got {self.gutter!r}")
        ps = self.page_size
        if not isinstance(ps, (int, np.integer)) or ps < 64 or ps > GL_MAX_TEXTURE_SIZE or ps & (ps - 1):
            raise OptionError(
                f"page_size must be a power of two in 64..{GL_MAX_TEXTURE_SIZE}, got {self.page_size!r}"
            )
        if self.pixel_format not in BYTES_PER_TEXEL:
            raise OptionError(
                f"pixel_format must be one of {', '.join(BYTES_PER_TEXEL)}, got {self.pixel_format!r}"
            )
        for name in ("lod", "lod_stream"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise OptionError(f"{name} must be True or False, got {getattr(self, name)!r}")
        return self

    @property
    def uses_lod(self) -> bool:
        """Whether the bake makes the level-of-detail chain (``lod`` or ``lod_stream``)."""
        return bool(self.lod or self.lod_stream)

    @property
    def mip_levels(self) -> int:
        return atlas.mip_levels(self.gutter, self.mipmaps)

    def to_dict(self) -> dict:
        """The fields as a dict; ``lod`` and ``lod_stream`` only when set (so a bake without LOD
        writes the same records as before they existed)."""
        d = dataclasses.asdict(self)
        for name in ("lod", "lod_stream"):
            if not d[name]:
                del d[name]
        return d
