#version 330 core
// Base pass of the occluder: ambient term ([Kolivand-Stencil]: I_a K_a) and coverage. With sky shading
// (u_use_vis): the sky term times the vertex's sky visibility plus the light bounced from the ground
// times its ground view (arshadow.shading.sky); with a texture: the albedo times the base-colour texture.
uniform float u_ambient;
uniform vec3 u_ambient_tint;  // linear RGB tint of the ambient (sky) term (1: grey)
uniform bool u_use_vis;
uniform vec3 u_bounce;       // ground albedo x open-ground irradiance (linear RGB)
uniform bool u_textured;
uniform vec3 u_albedo_gain;   // linear gain on the mesh's own colours (measured exposure)
uniform sampler2D u_tex;     // linear RGB base colour, row 0 = the image's bottom (GL order)
uniform bool u_seen;          // the ground's light weighted by the irradiance of the ground seen
uniform sampler2D u_seen_map; // the ground's irradiance / the open ground's (GroundOcclusion.irradiance)
uniform vec4 u_seen_rect;     // its x0, y0, width, height (metres, the vertices' frame); 1 outside
uniform float u_seen_z;       // the ground's height in the vertices' frame
in vec3 v_world;
in vec3 v_normal;
in vec3 v_albedo;
in vec2 v_uv;
in vec2 v_vis;
layout(location = 0) out vec4 o_color;   // rgb: linear colour (premultiplied after MSAA resolve), a: coverage
layout(location = 1) out vec4 o_mask;    // r: blocked light weight, g: ground coverage, b: sky occlusion
// The mean irradiance (a share of the open ground's) of the ground that p sees round its normal n:
// SEEN_DIRS cosine-weighted directions (a Fibonacci spiral in the projected disc, as
// arshadow.shading.sky.cosine_directions), each reaching the ground read on the map; 1 on open ground.
// The object is not counted as a blocker (its ground view, v_vis.y, has that). Per fragment: the ground
// under a face changes within a centimetre of its foot, faster than its vertices can carry.
const int SEEN_DIRS = 64;
float ground_seen(vec3 p, vec3 n) {
    vec3 a = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 tx = normalize(cross(a, n));
    vec3 ty = cross(n, tx);
    float h = max(p.z - u_seen_z, 0.0);
    float s = 0.0;
    float c = 0.0;
    for (int i = 0; i < SEEN_DIRS; ++i) {
        float r = sqrt((float(i) + 0.5) / float(SEEN_DIRS));
        float phi = float(i) * 2.399963229728653;
        vec3 d = tx * (r * cos(phi)) + ty * (r * sin(phi)) + n * sqrt(max(0.0, 1.0 - r * r));
        if (d.z < -1e-6) {
            vec2 st = (p.xy + (h / -d.z) * d.xy - u_seen_rect.xy) / u_seen_rect.zw;
            bool on = all(greaterThanEqual(st, vec2(0.0))) && all(lessThanEqual(st, vec2(1.0)));
            s += on ? texture(u_seen_map, st).r : 1.0;
            c += 1.0;
        }
    }
    return c > 0.0 ? s / c : 1.0;
}

void main() {
    vec3 alb = u_albedo_gain * (u_textured ? v_albedo * texture(u_tex, v_uv).rgb : v_albedo);
    vec3 sky = u_ambient * u_ambient_tint;
    float g = u_seen ? v_vis.y * ground_seen(v_world, normalize(v_normal)) : v_vis.y;
    vec3 e = u_use_vis ? sky * v_vis.x + u_bounce * g : sky;
    o_color = vec4(e * alb, 1.0);
    o_mask = vec4(0.0);
}
