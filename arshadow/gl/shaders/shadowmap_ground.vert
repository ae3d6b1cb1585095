#version 330 core
// Shadow-map baseline: the ground plane z = 0 (homogeneous vertices, w = 0 at infinity) seen by the
// camera, with its position in the light's clip space for the shadow-map lookup. The same program and
// inputs draw the base pass and every light pass, so the depths are identical (GL_LEQUAL passes).
invariant gl_Position;
uniform mat4 u_mvp;        // clip_from_world of the camera
uniform mat4 u_light_vp;   // light clip_from_world (the shadow map's projection)
in vec4 in_pos;
out vec4 v_light;
out vec3 v_world;
out vec3 v_normal;
out vec3 v_albedo;
void main() {
    gl_Position = u_mvp * in_pos;
    v_light = u_light_vp * in_pos;
    v_world = in_pos.xyz;   // unused for the ground
    v_normal = vec3(0.0, 0.0, 1.0);
    v_albedo = vec3(0.0);
}
