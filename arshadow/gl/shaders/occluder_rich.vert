#version 330 core
// The occluder with a texture and / or sky shading (occluder.vert without them): same gl_Position
// expression as common.vert (see there), plus what shading needs.
invariant gl_Position;
uniform mat4 u_mvp;
in vec4 in_pos;         // world position, w = 1
in vec3 in_normal;      // world normal (crease-angle smoothed)
in vec3 in_albedo;      // linear RGB
in vec2 in_uv;          // base-colour texture coordinates (unbound: 0)
in vec2 in_vis;         // x: sky visibility, y: ground view (arshadow.shading.sky; unbound: 0)
out vec3 v_world;
out vec3 v_normal;
out vec3 v_albedo;
out vec2 v_uv;
out vec2 v_vis;
void main() {
    gl_Position = u_mvp * in_pos;
    v_world = in_pos.xyz;
    v_normal = in_normal;
    v_albedo = in_albedo;
    v_uv = in_uv;
    v_vis = in_vis;
}
