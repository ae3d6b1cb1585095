#version 330 core
// Proxy ground plane z = 0: depth (and the stencil "ground" bit) only; never visible in colour.
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);           // overwrites occluder parts below the ground
    o_mask = vec4(0.0, 1.0, 0.0, 0.0);
}
