#version 330 core
// Proxy ground plane z = 0: depth (and the stencil "ground" bit); never visible in colour. Colour 1: the
// ground coverage (g) and, with sky occlusion (u_sky), the ground occlusion map read at the fragment's
// ground point (arshadow.gl.sky.GroundSkyMap): 1 - its sky visibility into b, the object's reflected-light
// part into a (colour bleeding); 0 off the map. With u_falloff (a measured point light,
// Shading.ratio_falloff) both times (1 + q0) / (g + q0): the sky's share of this ground point's light over
// the share the composite applies, g = (d0 / d)^3 the lamp's irradiance here relative to where that share
// holds (arshadow/gl/falloff.py).
uniform bool u_sky;
uniform sampler2D u_vis;     // RG32F (sky visibility, its reflected-light part), texel row 0 = the map's first row (y0)
uniform vec4 u_vis_rect;     // the map's x0, y0, width, height (metres, the local frame)
uniform bool u_falloff;
uniform vec3 u_lamp;         // the point light, local frame
uniform vec4 u_ref;          // xyz: where the ratio holds (local frame, on the ground); w: q0, sky / lamp there
in vec4 v_pos;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    o_color = vec4(0.0);           // overwrites occluder parts below the ground
    vec4 m = vec4(0.0, 1.0, 0.0, 0.0);
    if (u_sky) {
        vec3 p = v_pos.xyz / v_pos.w;
        vec2 st = (p.xy - u_vis_rect.xy) / u_vis_rect.zw;
        if (all(greaterThanEqual(st, vec2(0.0))) && all(lessThanEqual(st, vec2(1.0)))) {
            vec2 v = texture(u_vis, st).rg;
            float k = 1.0;
            if (u_falloff) {
                float g = pow(distance(u_lamp, u_ref.xyz) / max(distance(u_lamp, p), 1e-9), 3.0);
                k = (1.0 + u_ref.w) / (g + u_ref.w);
            }
            m.b = k * (1.0 - v.r);
            m.a = k * v.g;
        }
    }
    o_mask = m;
}
