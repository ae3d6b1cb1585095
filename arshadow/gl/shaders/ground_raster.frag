#version 330 core
// Covered (1) and the nearest face's value (u_values, one texel per face: gl_PrimitiveID) into an RG32F
// scratch target.
uniform sampler2D u_values;
layout(location = 0) out vec2 o_cover;
void main() {
    int w = textureSize(u_values, 0).x;
    o_cover = vec2(1.0, texelFetch(u_values, ivec2(gl_PrimitiveID % w, gl_PrimitiveID / w), 0).r);
}
