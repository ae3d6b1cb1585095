#version 330 core
// Accumulates one light's weight where the stencil test passed (ground bit set, volume count != 0).
uniform float u_weight;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);
    o_mask = vec4(u_weight, 0.0, 0.0, 0.0);
}
