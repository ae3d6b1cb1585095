#version 330 core
// Sky occlusion of the visible ground (the contact shadow): 1 - the map's sky visibility, into the mask
// target's b channel, and the object's reflected light part of it into a (colour bleeding; additive
// blending; the stencil limits it to ground the occluder does not cover).
uniform sampler2D u_vis;     // RG32F (sky visibility, its reflected-light part), texel row 0 = the map's first row (y0)
in vec2 v_st;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);
    vec2 v = texture(u_vis, v_st).rg;
    o_mask = vec4(0.0, 0.0, 1.0 - v.r, v.g);
}
