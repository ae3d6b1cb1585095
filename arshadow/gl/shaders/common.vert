#version 330 core
// Position-only vertex shader shared by the ground, the shadow volumes and the planar shadow.
// The expression for gl_Position is identical (and invariant) in every program that writes depth which a
// later pass compares with GL_EQUAL or against coincident geometry (the z-fail light cap = the
// occluder's own light-facing faces): same source, same float32 inputs -> bit-identical depth.
invariant gl_Position;
uniform mat4 u_mvp;     // clip_from_world (projection @ gl_from_world [@ planar shadow matrix])
in vec4 in_pos;         // homogeneous world position (w = 0: a point at infinity)
void main() {
    gl_Position = u_mvp * in_pos;
}
