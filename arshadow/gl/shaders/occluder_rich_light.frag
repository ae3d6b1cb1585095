#version 330 core
// One light's direct Phong term ([Kolivand-Stencil]: K_d I_l (N.L) + I_l K_s (N.H)^n), added where the stencil
// says the surface is outside this light's shadow volume.
uniform vec4 u_light;        // homogeneous world position (w = 0: direction towards the light)
uniform vec3 u_light_color;  // linear colour x weight
uniform vec3 u_direct_tint;  // linear RGB tint of every light's direct term (1: grey)
uniform float u_light_d2;    // a point light's squared distance to the world origin (the marker's paper)
uniform float u_point_falloff;  // 1: a point light's term times u_light_d2 / d^2 (Shading.point_falloff)
uniform vec3 u_eye;          // camera centre, world
uniform float u_kd;
uniform float u_ks;
uniform float u_shininess;
uniform bool u_textured;
uniform vec3 u_albedo_gain;   // linear gain on the mesh's own colours (measured exposure)
uniform sampler2D u_tex;     // linear RGB base colour (see occluder_base.frag)
in vec2 v_uv;
in vec3 v_world;
in vec3 v_normal;
in vec3 v_albedo;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;
void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;             // open meshes seen from behind
    vec3 to_light = u_light.xyz - v_world * u_light.w;
    vec3 l = normalize(to_light);
    // irradiance ~ cos / d^2, normalised at the world origin (where the exposure is matched)
    float falloff = (u_point_falloff > 0.5 && u_light.w != 0.0) ? u_light_d2 / max(dot(to_light, to_light), 1e-12) : 1.0;
    vec3 v = normalize(u_eye - v_world);
    float ndl = dot(n, l);
    vec3 c = vec3(0.0);
    if (ndl > 0.0) {
        vec3 h = normalize(l + v);
        float spec = pow(max(dot(n, h), 0.0), u_shininess);
        vec3 alb = u_albedo_gain * (u_textured ? v_albedo * texture(u_tex, v_uv).rgb : v_albedo);
        c = falloff * u_direct_tint * u_light_color * (u_kd * alb * ndl + u_ks * spec);
    }
    o_color = vec4(c, 0.0);
    o_mask = vec4(0.0);
}
