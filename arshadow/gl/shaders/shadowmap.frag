#version 330 core
// Shadow-map baseline (the technique of three.js, model-viewer, pyrender), one fragment shader for the
// ground and the occluder:
//   u_pass 0 (base):  occluder -> ambient colour + coverage; ground -> ground coverage;
//   u_pass 1 (light): occluder -> this light's Phong term x visibility; ground -> weight x (1 - visibility)
//                     (added with blending ONE, ONE).
// Visibility = percentage-closer filtering: the mean of u_pcf x u_pcf depth comparisons (each one the
// hardware's 2x2 bilinear comparison of a sampler2DShadow) around the fragment's shadow-map position.
// Depth bias: slope-scaled through glPolygonOffset in the depth pass, plus u_bias here (NDC depth units).
uniform int u_pass;
uniform int u_is_ground;
uniform sampler2DShadow u_map;
uniform int u_pcf;           // kernel side (1, 3, 5, ...)
uniform float u_texel;       // 1 / map size
uniform float u_bias;
uniform float u_weight;
uniform float u_ambient;
uniform vec3 u_ambient_tint;  // linear RGB tint of the ambient (sky) term (1: grey)
uniform vec4 u_light;        // homogeneous world position (w = 0: direction towards the light)
uniform vec3 u_light_color;  // linear colour x weight
uniform vec3 u_direct_tint;  // linear RGB tint of every light's direct term (1: grey)
uniform vec3 u_eye;
uniform float u_kd;
uniform float u_ks;
uniform float u_shininess;
in vec4 v_light;
in vec3 v_world;
in vec3 v_normal;
in vec3 v_albedo;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;

float visibility() {
    if (v_light.w <= 0.0) return 1.0;               // behind the light: not in the map
    vec3 p = v_light.xyz / v_light.w * 0.5 + 0.5;
    // receivers beyond the far plane (which encloses the caster) compare as the far plane: shadowed
    // wherever the map holds any caster depth, lit where it is empty (cleared to 1)
    float z = min(p.z, 1.0) - u_bias;
    int h = u_pcf / 2;
    float s = 0.0;
    for (int j = -h; j <= h; ++j)
        for (int i = -h; i <= h; ++i) {
            vec2 q = p.xy + vec2(float(i), float(j)) * u_texel;
            // outside the map: no caster there -> lit
            s += (any(lessThan(q, vec2(0.0))) || any(greaterThan(q, vec2(1.0)))) ? 1.0
                 : texture(u_map, vec3(q, z));
        }
    return s / float(u_pcf * u_pcf);
}

void main() {
    if (u_pass == 0) {
        if (u_is_ground == 1) {
            o_color = vec4(0.0);                      // overwrites occluder parts below the ground
            o_mask = vec4(0.0, 1.0, 0.0, 0.0);
        } else {
            o_color = vec4(u_ambient * u_ambient_tint * v_albedo, 1.0);
            o_mask = vec4(0.0);
        }
        return;
    }
    float vis = visibility();
    if (u_is_ground == 1) {
        o_color = vec4(0.0);
        o_mask = vec4(u_weight * (1.0 - vis), 0.0, 0.0, 0.0);
        return;
    }
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    vec3 l = normalize(u_light.xyz - v_world * u_light.w);
    vec3 v = normalize(u_eye - v_world);
    float ndl = dot(n, l);
    vec3 c = vec3(0.0);
    if (ndl > 0.0) {
        vec3 hv = normalize(l + v);
        float spec = pow(max(dot(n, hv), 0.0), u_shininess);
        c = vis * u_direct_tint * u_light_color * (u_kd * v_albedo * ndl + u_ks * spec);
    }
    o_color = vec4(c, 0.0);
    o_mask = vec4(0.0);
}
