#version 330 core
// Sky occlusion of the visible ground (the contact shadow): 1 - the map's sky visibility, into the mask
// target's b channel (additive blending; the stencil limits it to ground the occluder does not cover).
uniform sampler2D u_vis;     // R32F sky visibility, texel row 0 = the map's first row (y0)
in vec2 v_st;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);
    o_mask = vec4(0.0, 0.0, 1.0 - texture(u_vis, v_st).r, 0.0);
}
