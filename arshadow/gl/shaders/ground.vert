#version 330 core
// The proxy ground plane: the same gl_Position expression as common.vert (invariant: bit-identical depth
// with the shadow volumes and the planar shadow, which use that one), and its homogeneous local position
// (points at infinity have w = 0) for the sky channel.
invariant gl_Position;
uniform mat4 u_mvp;
in vec4 in_pos;         // homogeneous local position on z = 0
out vec4 v_pos;
void main() {
    gl_Position = u_mvp * in_pos;
    v_pos = in_pos;
}
