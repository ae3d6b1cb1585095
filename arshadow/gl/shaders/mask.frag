#version 330 core
// Accumulates one light's weight where the stencil test passed (ground bit set, volume count != 0).
// With u_falloff (a measured point light, Shading.ratio_falloff): the blocked share of the fragment's own
// ground light is the weight times a = g (1 + q0) / (g + q0), g = (d0 / d)^3 the lamp's irradiance there
// relative to the point where the composite's shadow ratio r0 = q0 / (1 + q0) holds. The mask (r) keeps the
// weight (the shadow mask's contract, CONVENTIONS.md); the difference rides on the sky channel (b), which
// the composite weighs by r0 where the mask is weighed by 1 - r0: weight (a - 1) / q0.
uniform float u_weight;
uniform bool u_falloff;
uniform mat4 u_inv_mvp;   // local_from_clip of the canvas
uniform vec2 u_viewport;  // the canvas in pixels
uniform vec3 u_lamp;      // the point light, local frame
uniform vec4 u_ref;       // xyz: where the ratio holds (local frame, on the ground); w: q0, sky / lamp there
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_mask;

// the ground point (z = u_ref.z) under the pixel: the camera ray through it, from two depths
vec3 ground_point() {
    vec2 ndc = 2.0 * gl_FragCoord.xy / u_viewport - 1.0;
    vec4 a = u_inv_mvp * vec4(ndc, -1.0, 1.0);
    vec4 b = u_inv_mvp * vec4(ndc, 0.0, 1.0);
    vec3 pa = a.xyz / a.w;
    vec3 pb = b.xyz / b.w;
    float t = (u_ref.z - pa.z) / (pb.z - pa.z);
    return pa + t * (pb - pa);
}

void main() {
    float extra = 0.0;
    if (u_falloff) {
        float g = pow(distance(u_lamp, u_ref.xyz) / max(distance(u_lamp, ground_point()), 1e-9), 3.0);
        extra = u_weight * (g * (1.0 + u_ref.w) / (g + u_ref.w) - 1.0) / u_ref.w;
    }
    o_color = vec4(0.0);
    o_mask = vec4(u_weight, 0.0, extra, 0.0);
}
