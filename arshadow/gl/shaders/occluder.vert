#version 330 core
// The occluder: same gl_Position expression as common.vert (see there), plus what Phong shading needs.
invariant gl_Position;
uniform mat4 u_mvp;
in vec4 in_pos;         // world position, w = 1
in vec3 in_normal;      // world normal (crease-angle smoothed)
in vec3 in_albedo;      // linear RGB
out vec3 v_world;
out vec3 v_normal;
out vec3 v_albedo;
void main() {
    gl_Position = u_mvp * in_pos;
    v_world = in_pos.xyz;
    v_normal = in_normal;
    v_albedo = in_albedo;
}
