// GLB view (iat.render.glb_view): an exported glTF drawn unlit, as a viewer does with
// KHR_materials_unlit: baseColorFactor x baseColorTexture x COLOR_0 (x the layered export's
// illumination texture) x radiance_scale. Textures are sRGB (decoded by the GPU); the output is
// exposure x linear radiance, sRGB-encoded when tonemap is set (the viewer's window).

#if defined VERTEX_SHADER
uniform mat4 clip_from_world;
in vec3 in_position;
in vec4 in_color;
in vec2 in_uv0;
in vec2 in_uv1;
out vec4 v_color;
out vec2 v_uv0;
out vec2 v_uv1;
void main() {
    v_color = in_color;
    v_uv0 = in_uv0;
    v_uv1 = in_uv1;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
uniform sampler2D base_tex;   // unit 0
uniform sampler2D ill_tex;    // unit 1
uniform bool use_base;
uniform bool use_ill;
uniform int base_set;         // TEXCOORD_<n> of the base colour texture (0 or 1)
uniform int ill_set;
uniform float ill_rgbm;       // > 0: the illumination texture is RGBM, rgb x alpha x this (--hdr)
uniform bvec2 base_mirror;    // MIRRORED_REPEAT on s / t (the texture itself repeats)
uniform bvec2 ill_mirror;
uniform vec4 factor;          // baseColorFactor
uniform float radiance_scale;
uniform float exposure;
uniform bool tonemap;
in vec4 v_color;
in vec2 v_uv0;
in vec2 v_uv1;
out vec4 frag_color;
#include "color.glsl"
vec2 fold(vec2 uv, bvec2 m) {
    vec2 f = 1.0 - abs(mod(uv, 2.0) - 1.0);
    return vec2(m.x ? f.x : uv.x, m.y ? f.y : uv.y);
}
void main() {
    vec4 c = factor * v_color;
    if (use_base) {
        c *= texture(base_tex, fold(base_set == 1 ? v_uv1 : v_uv0, base_mirror));
    }
    if (use_ill) {
        vec4 t = texture(ill_tex, fold(ill_set == 1 ? v_uv1 : v_uv0, ill_mirror));
        c.rgb *= ill_rgbm > 0.0 ? t.rgb * t.a * ill_rgbm : t.rgb;
    }
    vec3 r = c.rgb * radiance_scale * exposure;
    frag_color = vec4(tonemap ? srgb_encode(r) : r, 1.0);
}
#endif
