// An image (the false-colour legend, already display-encoded) drawn over the view: a quad that
// fills the viewport it is drawn into, no buffers (gl_VertexID), the image's row 0 at the bottom.

#if defined VERTEX_SHADER

out vec2 v_uv;

void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    v_uv = p;
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D image;

in vec2 v_uv;
out vec4 frag_color;

void main() {
    frag_color = vec4(texture(image, v_uv).rgb, 1.0);
}

#endif
