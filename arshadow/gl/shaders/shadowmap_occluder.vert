#version 330 core
// Shadow-map baseline: the occluder seen by the camera, with its position in the light's clip space.
invariant gl_Position;
uniform mat4 u_mvp;
uniform mat4 u_light_vp;
in vec4 in_pos;         // world position, w = 1
in vec3 in_normal;      // world normal (crease-angle smoothed)
in vec3 in_albedo;      // linear RGB
out vec4 v_light;
out vec3 v_world;
out vec3 v_normal;
out vec3 v_albedo;
void main() {
    gl_Position = u_mvp * in_pos;
    v_light = u_light_vp * in_pos;
    v_world = in_pos.xyz;
    v_normal = in_normal;
    v_albedo = in_albedo;
}
