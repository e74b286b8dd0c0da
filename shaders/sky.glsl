// The sky behind everything (Renderer.set_sky): one triangle covering the viewport, each pixel
// the radiance of its view direction looked up in the sky's equirectangular image
// (iat.radiosity.sky.sky_equirect: row j at zenith angle pi j / (h - 1), column i at azimuth
// 2 pi (i + 0.5) / w, d = (sin phi sin theta, cos theta, -cos phi sin theta)).

#if defined VERTEX_SHADER

out vec2 v_ndc;

void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    v_ndc = p;
    gl_Position = vec4(p, 1.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform mat4 world_from_clip;  // inverse of the camera's clip_from_world
uniform sampler2D sky;         // unit 0, (h, w) RGB32F linear radiance, row 0 the zenith
uniform float exposure;
uniform bool tonemap;

in vec2 v_ndc;
out vec4 frag_color;

#include "color.glsl"

const float PI = 3.14159265358979;

void main() {
    vec4 a = world_from_clip * vec4(v_ndc, -1.0, 1.0);
    vec4 b = world_from_clip * vec4(v_ndc, 1.0, 1.0);
    vec3 d = normalize(b.xyz / b.w - a.xyz / a.w);
    vec2 size = vec2(textureSize(sky, 0));
    float u = atan(d.x, -d.z) / (2.0 * PI);
    float theta = acos(clamp(d.y, -1.0, 1.0));
    float v = (theta / PI * (size.y - 1.0) + 0.5) / size.y;
    vec3 c = texture(sky, vec2(u, v)).rgb * exposure;
    frag_color = vec4(tonemap ? srgb_encode(c) : c, 1.0);
}

#endif
