// Fullscreen pass combining two float images drawn at the viewport's size:
// diff mode shows |a - b| x gain (a = mesh, b = IAT). One triangle covering the
// viewport, no vertex buffer (positions from gl_VertexID).

#if defined VERTEX_SHADER

void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D image_a;  // unit 0, RGBA32F linear radiance
uniform sampler2D image_b;  // unit 1
uniform ivec2 offset;       // viewport origin in the target framebuffer
uniform float gain;         // diff gain
uniform float exposure;
uniform bool tonemap;

out vec4 frag_color;

#include "color.glsl"

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy) - offset;
    vec3 a = texelFetch(image_a, p, 0).rgb;
    vec3 b = texelFetch(image_b, p, 0).rgb;
    vec3 c = abs(a - b) * gain * exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
