// Mesh mode: vertex-coloured triangles (Gouraud shading). Each vertex carries its
// outgoing radiance (linear RGB); the rasteriser interpolates it, no lighting here.
// Used for the solution's leaf mesh and for the mesh part of a Baked.
// Solution sets (lighting states, e.g. times of day) carry two colours per vertex,
// the neighbouring states' radiance, mixed by the uniform `blend` (0: in_color exactly).
// Detail textures, as iat.glsl: a vertex with in_detail = 1 (a patch whose material has a
// detail texture, iat.render.mesh_detail) carries its incoming light (radiance / albedo),
// multiplied here by the repeated detail (albedo) texture at in_detail_uv.

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;  // world
in vec3 in_color;     // linear radiance (state a), incoming light on detail vertices
in vec3 in_color_b;   // the same of state b (= in_color for a single solution)
in vec2 in_detail_uv; // detail texture UV (repeats)
in float in_detail;   // 1: in_color is incoming light x detail texture; 0: radiance

uniform float blend;  // 0: state a, 1: state b (linear radiance mixed per vertex)

out vec3 v_color;
out vec2 v_detail_uv;
flat out float v_detail;

void main() {
    v_color = blend > 0.0 ? mix(in_color, in_color_b, blend) : in_color;
    v_detail_uv = in_detail_uv;
    v_detail = in_detail;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform float exposure;     // multiplier on radiance
uniform bool tonemap;       // true: clamp + sRGB encode (window); false: linear radiance (float FBO)
uniform sampler2D detail;   // unit 1, only read when use_detail
uniform bool use_detail;    // this draw call's material has a detail texture

in vec3 v_color;
in vec2 v_detail_uv;
flat in float v_detail;
out vec4 frag_color;

#include "color.glsl"

void main() {
    vec3 c = v_color;
    if (use_detail) {
        c *= mix(vec3(1.0), texture(detail, v_detail_uv).rgb, v_detail);
    }
    c *= exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
