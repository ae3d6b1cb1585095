#version 330 core
// The triangle's index + 1 (0 = none) into an R32I target.
layout(location = 0) out int o_id;
void main() {
    o_id = gl_PrimitiveID + 1;
}
