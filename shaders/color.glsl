// Colour helpers shared by the shaders: iat.render.gl.shader_source splices this file in where a
// shader includes it (GLSL 330 has no include directive). The same curve as iat.color.

// Linear radiance -> display values: clamp to [0, 1], then the sRGB OETF.
vec3 srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}
