#version 330 core
// The ground occlusion map's square on z = 0 (arshadow.gl.sky): same gl_Position expression as
// common.vert; passes the map coordinates and the local position on.
invariant gl_Position;
uniform mat4 u_mvp;
in vec4 in_pos;         // local position on z = 0, w = 1
in vec2 in_st;          // map coordinates 0..1 across the square
out vec2 v_st;
out vec3 v_pos;
void main() {
    gl_Position = u_mvp * in_pos;
    v_st = in_st;
    v_pos = in_pos.xyz;
}
