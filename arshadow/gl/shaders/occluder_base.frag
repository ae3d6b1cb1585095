#version 330 core
// Base pass of the occluder: ambient term ([Kolivand-Stencil]: I_a K_a) and coverage.
uniform float u_ambient;
uniform vec3 u_ambient_tint;  // linear RGB tint of the ambient (sky) term (1: grey)
in vec3 v_world;
in vec3 v_normal;
in vec3 v_albedo;
layout(location = 0) out vec4 o_color;   // rgb: linear colour (premultiplied after MSAA resolve), a: coverage
layout(location = 1) out vec4 o_mask;    // r: blocked light weight, g: ground coverage
void main() {
    o_color = vec4(u_ambient * u_ambient_tint * v_albedo, 1.0);
    o_mask = vec4(0.0);
}
