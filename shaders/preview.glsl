// Preview mode: the scene before any solve. Every patch unlit:
// colour = emission + ambient x albedo, the albedo taken from the material's
// detail texture when it has one. Only a preview: not a radiance.

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;  // world
in vec3 in_emission;  // emitted radiance of the patch's material
in vec3 in_albedo;    // albedo of the patch's material
in vec2 in_uv;        // detail texture UV

out vec3 v_emission;
out vec3 v_albedo;
out vec2 v_uv;

void main() {
    v_emission = in_emission;
    v_albedo = in_albedo;
    v_uv = in_uv;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D detail;  // unit 1, only read when use_detail
uniform bool use_detail;
uniform float ambient;     // constant standing in for the missing lighting
uniform float exposure;
uniform bool tonemap;

in vec3 v_emission;
in vec3 v_albedo;
in vec2 v_uv;
out vec4 frag_color;

#include "color.glsl"

void main() {
    vec3 albedo = use_detail ? texture(detail, v_uv).rgb : v_albedo;
    vec3 c = (v_emission + ambient * albedo) * exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
