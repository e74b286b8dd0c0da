// IAT mode: one textured polygon per patch. The illumination texture (an atlas
// page, one layer of a texture array) holds linear radiance, or on patches with a
// detail texture the incoming light, which is multiplied here by the repeated
// detail (albedo) texture (report section 3.7).
// Solution sets: the pages of every lighting state sit in the same texture array,
// state k's page p at layer k * n_pages + p (one shared atlas layout); one pass
// samples the two neighbouring states' layers and mixes them by `blend` (linear
// radiance per texel; blend 0 reads state a alone, exactly).

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;   // world
in vec2 in_uv;         // atlas UV in [0, 1] of the page
in float in_layer;     // atlas page (layer of the texture array)
in vec2 in_detail_uv;  // detail texture UV (repeats)
in float in_detail;    // 1: texel is incoming light x detail texture; 0: texel is radiance

out vec2 v_uv;
flat out float v_layer;
out vec2 v_detail_uv;
flat out float v_detail;

void main() {
    v_uv = in_uv;
    v_layer = in_layer;
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

in vec2 v_uv;
flat in float v_layer;
in vec2 v_detail_uv;
flat in float v_detail;
out vec4 frag_color;

#include "color.glsl"

vec3 page(float layer) {
    return texture(pages, vec3(v_uv, v_layer + layer)).rgb;
}

void main() {
    vec3 c = page(layer_a);
    if (blend > 0.0) {
        c = mix(c, page(layer_b), blend);
    }
    c *= page_scale;
    if (use_detail) {
        c *= mix(vec3(1.0), texture(detail, v_detail_uv).rgb, v_detail);
    }
    c *= exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
