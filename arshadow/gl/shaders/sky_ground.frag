#version 330 core
// Sky occlusion of the visible ground (the contact shadow): 1 - the map's sky visibility, into the mask
// target's b channel, and the object's reflected light part of it into a (colour bleeding; additive
// blending; the stencil limits it to ground the occluder does not cover). With u_falloff (a measured
// point light, Shading.ratio_falloff) both times (1 + q0) / (g + q0): the sky's share of this ground
// point's light over the share the composite applies, g = (d0 / d)^3 the lamp's irradiance here relative
// to where that share holds.
uniform sampler2D u_vis;     // RG32F (sky visibility, its reflected-light part), texel row 0 = the map's first row (y0)
uniform bool u_falloff;
uniform vec3 u_lamp;         // the point light, local frame
uniform vec4 u_ref;          // xyz: where the ratio holds (local frame, on the ground); w: q0, sky / lamp there
in vec2 v_st;
in vec3 v_pos;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);
    vec2 v = texture(u_vis, v_st).rg;
    float k = 1.0;
    if (u_falloff) {
        float g = pow(distance(u_lamp, u_ref.xyz) / max(distance(u_lamp, v_pos), 1e-9), 3.0);
        k = (1.0 + u_ref.w) / (g + u_ref.w);
    }
    o_mask = k * vec4(0.0, 0.0, 1.0 - v.r, v.g);
}
