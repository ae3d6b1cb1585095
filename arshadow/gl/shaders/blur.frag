#version 330 core
// One pass of the separable Gaussian of the camera effects (arshadow/gl/gpu_effects.py): the warped layers
// (colour + coverage, mask + sky occlusion; RGBA32F textures of the region) convolved along u_dir with the
// kernel cv2.GaussianBlur applies to float32 layers, zero beyond the region (BORDER_CONSTANT).
uniform sampler2D u_src0;        // RGBA32F premultiplied colour, coverage
uniform sampler2D u_src1;        // RGBA32F (mask, sky occlusion, its reflected part, 0)
uniform sampler2D u_kernel;      // R32F (2 r + 1) x 1: cv2.getGaussianKernel(2 r + 1, sigma, CV_32F)
uniform int u_radius;            // r
uniform ivec2 u_dir;             // (1, 0): along rows (cv2's row filter, first); (0, 1): along columns
uniform ivec2 u_size;            // the region's size: texels outside it are 0
layout(location = 0) out vec4 o0;
layout(location = 1) out vec4 o1;

bool within(ivec2 p) {
    return p.x >= 0 && p.y >= 0 && p.x < u_size.x && p.y < u_size.y;
}

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float w = texelFetch(u_kernel, ivec2(u_radius, 0), 0).r;
    vec4 a = texelFetch(u_src0, p, 0) * w;
    vec4 b = texelFetch(u_src1, p, 0) * w;
    // the symmetric kernel's pairs, nearest first (as cv2's symmetric column filter sums them)
    for (int k = 1; k <= u_radius; k++) {
        w = texelFetch(u_kernel, ivec2(u_radius + k, 0), 0).r;
        ivec2 d = u_dir * k;
        vec4 a0 = within(p + d) ? texelFetch(u_src0, p + d, 0) : vec4(0.0);
        vec4 a1 = within(p - d) ? texelFetch(u_src0, p - d, 0) : vec4(0.0);
        vec4 b0 = within(p + d) ? texelFetch(u_src1, p + d, 0) : vec4(0.0);
        vec4 b1 = within(p - d) ? texelFetch(u_src1, p - d, 0) : vec4(0.0);
        a += (a0 + a1) * w;
        b += (b0 + b1) * w;
    }
    o0 = a;
    o1 = b;
}
