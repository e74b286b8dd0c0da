// Mesh mode: vertex-coloured triangles (Gouraud shading). Each vertex carries its
// outgoing radiance (linear RGB); the rasteriser interpolates it, no lighting here.
// Used for the solution's leaf mesh and for the mesh part of a Baked.
// Solution sets (lighting states, e.g. times of day) carry two colours per vertex,
// the neighbouring states' radiance, mixed by the uniform `blend` (0: in_color exactly).

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;  // world
in vec3 in_color;     // linear radiance (state a)
in vec3 in_color_b;   // linear radiance of state b (= in_color for a single solution)

uniform float blend;  // 0: state a, 1: state b (linear radiance mixed per vertex)

out vec3 v_color;

void main() {
    v_color = blend > 0.0 ? mix(in_color, in_color_b, blend) : in_color;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform float exposure;  // multiplier on radiance
uniform bool tonemap;    // true: clamp + sRGB encode (window); false: linear radiance (float FBO)

in vec3 v_color;
out vec4 frag_color;

#include "color.glsl"

void main() {
    vec3 c = v_color * exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
