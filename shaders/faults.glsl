// Model faults (iat.render.fault_tint): the triangles of the patches that carry a fault the loader
// found, drawn over what the mode drew (depth test <=, pulled towards the camera by a polygon
// offset) with blending (SRC_ALPHA, ONE_MINUS_SRC_ALPHA): the pixel becomes
// (1 - alpha) x what was drawn + alpha x the kind's colour. A patch carrying several kinds shows the
// first that ``shown`` lets through (bit k: kind k of iat.geometry.faults.FAULTS).

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;  // world
in float in_bits;     // the patch's fault bits

flat out int v_bits;

void main() {
    v_bits = int(in_bits + 0.5);
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform int shown;       // the kinds tinted (bits)
uniform vec3 colors[4];  // linear RGB of each kind
uniform float alpha;
uniform bool tonemap;

flat in int v_bits;
out vec4 frag_color;

#include "color.glsl"

void main() {
    int b = v_bits & shown;
    if (b == 0) {
        discard;
    }
    int k = 0;
    while (k < 3 && ((b >> k) & 1) == 0) {
        k++;
    }
    vec3 c = colors[k];
    frag_color = vec4(tonemap ? srgb_encode(c) : c, alpha);
}

#endif
