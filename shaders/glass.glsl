// Glass (thin transmissive patches): drawn after the opaque surfaces with blending
// (ZERO, SRC_COLOR), so what lies behind is seen times the glass's transmittance. Glass
// itself stores no light (the solver passes it through), so nothing is added.
// Into a tone-mapped (sRGB-encoded) target the factor is T^(1/2.2), the encoded image of a
// radiance multiplied by T (exact for a pure power law, close for the sRGB curve).

#if defined VERTEX_SHADER

uniform mat4 clip_from_world;

in vec3 in_position;      // world
in vec3 in_transmission;  // linear RGB transmittance

out vec3 v_transmission;

void main() {
    v_transmission = in_transmission;
    gl_Position = clip_from_world * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform bool tonemap;

in vec3 v_transmission;
out vec4 frag_color;

void main() {
    frag_color = vec4(tonemap ? pow(v_transmission, vec3(1.0 / 2.2)) : v_transmission, 1.0);
}

#endif
