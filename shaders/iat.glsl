// IAT mode: one textured polygon per patch. The illumination texture (an atlas
// page, one layer of a texture array) holds linear radiance, or on patches with a
// detail texture the incoming light, which is multiplied here by the repeated
// detail (albedo) texture (report section 3.7).
// Solution sets: the pages of every lighting state sit in the same texture array,
// state k's page p at layer k * n_pages + p (one shared atlas layout); one pass
// samples the two neighbouring states' layers and mixes them by `blend` (linear
// radiance per texel; blend 0 reads state a alone, exactly).
// LOD (compiled with `#define LOD`, iat.render.lod): each patch's levels (its quad-tree cut at
// coarser levels, iat.bake.lod) sit anywhere in the pages; a table texture holds, per tile, a
// header (n_levels, finest resident level, finest texels - 1) and per level (x, y, page, side - 1).
// The fragment picks lambda = log2(finest texels per pixel) + lod_bias from the derivatives of
// the tile's texel coordinates, clamped to the resident levels, and mixes levels floor(lambda)
// and floor(lambda) + 1 by fract(lambda): one pass, continuous as the camera moves.

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;   // world
#if defined LOD
in vec2 in_st;         // the patch's lattice coordinates in [0, 1]
in float in_tile;      // row of the LOD table
out vec2 v_st;
flat out float v_tile;
#else
in vec2 in_uv;         // atlas UV in [0, 1] of the page
in float in_layer;     // atlas page (layer of the texture array)
out vec2 v_uv;
flat out float v_layer;
#endif
in vec2 in_detail_uv;  // detail texture UV (repeats)
in float in_detail;    // 1: texel is incoming light x detail texture; 0: texel is radiance

out vec2 v_detail_uv;
flat out float v_detail;

void main() {
#if defined LOD
    v_st = in_st;
    v_tile = in_tile;
#else
    v_uv = in_uv;
    v_layer = in_layer;
#endif
    v_detail_uv = in_detail_uv;
    v_detail = in_detail;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2DArray pages;  // unit 0
uniform sampler2D detail;      // unit 1, only read when use_detail
uniform bool use_detail;       // this draw call's material has a detail texture
uniform float page_scale;      // rgba8 pages store radiance / page_scale; 1 for float pages
uniform float layer_a;         // layer offset of state a (k * n_pages)
uniform float layer_b;         // layer offset of state b
uniform float blend;           // 0: state a, 1: state b
uniform float exposure;
uniform bool tonemap;

#if defined LOD
uniform sampler2D lod_table;   // unit 2: RGBA32F, (columns, rows) = ((L + 1) x blocks, rows)
uniform int lod_rows;          // table rows per column block (tiles wrap into blocks of columns)
uniform int lod_columns;       // L + 1
uniform vec2 atlas_size;       // texels of the page texture (W, H)
uniform float lod_bias;        // added to lambda (negative: finer levels)
uniform bool lod_show;         // output (lambda, level, weight) instead of radiance
uniform bool lod_snap;         // the nearest level alone, no blend (pops; for comparison)
in vec2 v_st;
flat in float v_tile;
#else
in vec2 v_uv;
flat in float v_layer;
#endif
in vec2 v_detail_uv;
flat in float v_detail;
out vec4 frag_color;

#include "color.glsl"

#if defined LOD
vec4 lod_entry(int column) {
    int t = int(v_tile + 0.5);
    return texelFetch(lod_table, ivec2(column + lod_columns * (t / lod_rows), t % lod_rows), 0);
}

vec3 lod_level(float j, float layer) {
    vec4 e = lod_entry(1 + int(j));
    vec2 uv = (e.xy + v_st * e.w + 0.5) / atlas_size;
    return textureLod(pages, vec3(uv, e.z + layer), 0.0).rgb;
}
#else
vec3 page(float layer) {
    return texture(pages, vec3(v_uv, v_layer + layer)).rgb;
}
#endif

void main() {
#if defined LOD
    vec4 head = lod_entry(0);
    vec2 tc = v_st * head.z;
    float rho = max(length(dFdx(tc)), length(dFdy(tc)));
    float lambda = log2(max(rho, 1e-20)) + lod_bias;
    float lam = clamp(lod_snap ? floor(lambda + 0.5) : lambda, head.y, head.x - 1.0);
    float j0 = floor(lam);
    float f = lam - j0;
    vec3 c = lod_level(j0, layer_a);
    if (f > 0.0) {
        c = mix(c, lod_level(j0 + 1.0, layer_a), f);
    }
    if (lod_show) {
        frag_color = vec4(lambda, j0, f, 1.0);
        return;
    }
#else
    vec3 c = page(layer_a);
    if (blend > 0.0) {
        c = mix(c, page(layer_b), blend);
    }
#endif
    c *= page_scale;
    if (use_detail) {
        c *= mix(vec3(1.0), texture(detail, v_detail_uv).rgb, v_detail);
    }
    c *= exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
