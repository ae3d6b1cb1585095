#version 330 core
// A batch of sky directions' scratch tiles (covered, face value), side by side in u_scratch, added into the
// ground map's sums with their weights (additive blending): sum of (w * (1 - covered), w * value).
#define TILES 16
uniform sampler2D u_scratch;
uniform int u_res;
uniform float u_weight[TILES];  // 0 for the tiles a short last batch leaves unused
layout(location = 0) out vec2 o_sum;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec2 s = vec2(0.0);
    for (int k = 0; k < TILES; ++k) {
        vec2 c = texelFetch(u_scratch, ivec2(p.x + k * u_res, p.y), 0).rg;
        s += u_weight[k] * vec2(1.0 - c.r, c.g);
    }
    o_sum = s;
}
