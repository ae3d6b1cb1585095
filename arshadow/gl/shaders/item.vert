#version 330 core
// Item buffer of the object's self-occlusion (arshadow.gl.sky.GLItemBuffer): positions already in NDC.
in vec3 in_pos;
void main() {
    gl_Position = vec4(in_pos, 1.0);
}
