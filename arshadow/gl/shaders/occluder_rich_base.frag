#version 330 core
// Base pass of the occluder: ambient term ([Kolivand-Stencil]: I_a K_a) and coverage. With sky shading
// (u_use_vis): the sky term times the vertex's sky visibility plus the light bounced from the ground
// times its ground view (arshadow.shading.sky); with a texture: the albedo times the base-colour texture.
uniform float u_ambient;
uniform vec3 u_ambient_tint;  // linear RGB tint of the ambient (sky) term (1: grey)
uniform bool u_use_vis;
uniform vec3 u_bounce;       // ground albedo x open-ground irradiance (linear RGB)
uniform vec3 u_self;         // the object's light on itself per unit of the share it sees (arshadow.shading.interreflect)
uniform bool u_textured;
uniform vec3 u_albedo_gain;   // linear gain on the mesh's own colours (measured exposure)
uniform sampler2D u_tex;     // linear RGB base colour, row 0 = the image's bottom (GL order)
in vec3 v_world;
in vec3 v_normal;
in vec3 v_albedo;
in vec2 v_uv;
in vec2 v_vis;
layout(location = 0) out vec4 o_color;   // rgb: linear colour (premultiplied after MSAA resolve), a: coverage
layout(location = 1) out vec4 o_mask;    // r: blocked light weight, g: ground coverage, b: sky occlusion
void main() {
    vec3 alb = u_albedo_gain * (u_textured ? v_albedo * texture(u_tex, v_uv).rgb : v_albedo);
    vec3 sky = u_ambient * u_ambient_tint;
    // the rest of the hemisphere (1 - sky visibility - ground view) sees the object itself
    vec3 e = u_use_vis ? sky * v_vis.x + u_bounce * v_vis.y + u_self * max(1.0 - v_vis.x - v_vis.y, 0.0) : sky;
    o_color = vec4(e * alb, 1.0);
    o_mask = vec4(0.0);
}
