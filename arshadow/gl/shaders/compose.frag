#version 330 core
// GPU-resident compositing (arshadow/gl/gpu_compose.py): the same arithmetic as arshadow/compose/composite.py
// composite() (the sky-occlusion term of _darken_sky included) + arshadow/compose/lens.py LensWarp.warp(),
// per photo pixel of the region drawn, and the camera effects of arshadow/frame/effects.py (the blur of the
// warped layers by arshadow/gl/gpu_effects.py between two stages of this shader, the sensor noise here).
// Rows: every texture here is indexed by the photo's memory row (row 0 = top row of the photo), except the
// renderer's layers, whose texel row 0 is the canvas's BOTTOM row (OpenGL order).
uniform usampler2D u_photo;      // RGB8UI, photo as stored (B, G, R bytes), full photo size
uniform sampler2D u_decode;      // R32F 256 x 1: 8-bit sRGB code -> linear (SRGB_TO_LINEAR)
uniform usampler2D u_encode;     // R8UI 256 x 256: round(x * 65535) -> 8-bit sRGB code (LINEAR_TO_SRGB16)
uniform sampler2D u_color;       // RGBA16F renderer colour (premultiplied linear RGB, coverage)
uniform sampler2D u_mask;        // RG16F renderer mask (blocked weight, ground coverage); RGBA16F: b = sky
uniform sampler2D u_lens;        // RG32F undistortion map (pinhole u, v per photo pixel); only if u_use_lens
uniform bool u_use_lens;
uniform ivec4 u_canvas;          // (u0, v0, w, h) pinhole canvas
uniform ivec4 u_roi;             // (x0, y0, w, h) photo pixels composited (others: the photo unchanged)
uniform bool u_occluder;         // draw the occluder colour over the shadow
uniform bool u_gray;             // grey shadow colour: one multiplier for the three channels
uniform float u_gray_k;          // float32(-opacity * (1 - shadow_color[0]))
uniform vec3 u_dark;             // float32(opacity * (1 - shadow_color)) in B, G, R order
uniform bool u_darken;           // mask present and opacity > 0
uniform vec3 u_gain;             // gain on the occluder's colour in B, G, R order (exposure match)
uniform bool u_sky;              // the mask's b channel holds the sky occlusion (GpuLayers.sky)
uniform vec3 u_sky_wm;           // float32(-opacity * (1 - shadow_color)) in B, G, R order: the mask's weight
uniform vec3 u_sky_ws;           // float32(opacity * (1 - shadow_color) - 1) in B, G, R order: the sky's weight
uniform vec3 u_bleed;            // colour bleeding (SkyShading.bleed) in B, G, R order; 0: a grey object
// the stages: 0 warp + composite; 1 warp only, into the float textures of the blur (the region's texel
// (0, 0) is photo pixel u_origin; zeros outside u_roi); 2 composite the blurred layers (texel = pixel -
// u_blurred_origin)
uniform int u_stage;
uniform ivec2 u_origin;          // photo pixel of the framebuffer's pixel (0, 0)
uniform sampler2D u_bl_color;    // RGBA32F blurred colour + coverage (stage 2)
uniform sampler2D u_bl_mask;     // RGBA32F blurred (mask, sky occlusion, its reflected part) (stage 2)
uniform ivec2 u_blurred_origin;
uniform bool u_noise;            // add the sensor noise where the object covers (frame/effects.add_noise)
uniform sampler2D u_noise_tab;   // RGB32F 256 x 1: noise sigma (8-bit units) per code, B, G, R
uniform uint u_seed;             // the photo's noise seed
layout(location = 0) out vec4 o_rgb;   // RGBA8: (B, G, R, 255) / 255 (read back as GL_RGB -> BGR bytes)
layout(location = 1) out vec4 o_mask;  // R8: round(255 * mask) / 255

vec4 fetch_c(ivec2 p) {   // canvas texel with BORDER_CONSTANT 0
    if (p.x < 0 || p.y < 0 || p.x >= u_canvas.z || p.y >= u_canvas.w) return vec4(0.0);
    return texelFetch(u_color, p, 0);
}
vec3 fetch_m(ivec2 p) {   // (mask clipped to [0, 1] as the readback is, sky occlusion, its reflected part)
    if (p.x < 0 || p.y < 0 || p.x >= u_canvas.z || p.y >= u_canvas.w) return vec3(0.0);
    vec4 t = texelFetch(u_mask, p, 0);
    return vec3(clamp(t.r, 0.0, 1.0), t.b, t.a);
}

// the renderer's layers at photo pixel px: colour + coverage, (mask, sky occlusion, its reflected part)
void warp(ivec2 px, out vec4 c, out vec3 ms) {
    if (u_use_lens) {
        // LensWarp.warp(bottom_up=True): map_x = mx - u0, map_y = (h - 1 + v0) - my (float32), then
        // cv2.convertMaps(CV_16SC2) rounds to 1/32 px and cv2.remap interpolates bilinearly, border 0
        vec2 mp = texelFetch(u_lens, px, 0).rg;
        float mx = mp.x - float(u_canvas.x);
        float my = float(u_canvas.w - 1 + u_canvas.y) - mp.y;
        // cv2 saturates the fixed-point map; far-away (invalid) points give border 0 either way
        mx = clamp(mx, -30000.0, 30000.0);
        my = clamp(my, -30000.0, 30000.0);
        ivec2 q = ivec2(round(vec2(mx, my) * 32.0));
        ivec2 i0 = q >> 5;
        vec2 f = vec2(q & 31) / 32.0;
        float w00 = (1.0 - f.x) * (1.0 - f.y), w10 = f.x * (1.0 - f.y);
        float w01 = (1.0 - f.x) * f.y, w11 = f.x * f.y;
        c = fetch_c(i0) * w00 + fetch_c(i0 + ivec2(1, 0)) * w10 + fetch_c(i0 + ivec2(0, 1)) * w01
            + fetch_c(i0 + ivec2(1, 1)) * w11;
        ms = fetch_m(i0) * w00 + fetch_m(i0 + ivec2(1, 0)) * w10 + fetch_m(i0 + ivec2(0, 1)) * w01
            + fetch_m(i0 + ivec2(1, 1)) * w11;
    } else {
        // no lens: the canvas is the photo's pixel grid; canvas row r (top-down) is texel row h - 1 - r
        ivec2 t = ivec2(px.x - u_canvas.x, u_canvas.w - 1 - (px.y - u_canvas.y));
        c = fetch_c(t);
        ms = fetch_m(t);
    }
}

uint hash(uint x) {   // a 32-bit integer mix (lowbias32): uniform, decorrelated bits
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}
// a standard normal per photo pixel, channel and seed (Box-Muller of two hashed uniforms in (0, 1])
float gauss(ivec2 px, uint ch) {
    uint h = hash(u_seed ^ hash(uint(px.x) ^ hash(uint(px.y) ^ hash(ch))));
    float u1 = float((h >> 8) + 1u) / 16777216.0;
    float u2 = float(hash(h) >> 8) / 16777216.0;
    return sqrt(-2.0 * log(u1)) * cos(6.28318530718 * u2);
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy) + u_origin;   // photo pixel (x, memory row y)
    bool inside = px.x >= u_roi.x && px.y >= u_roi.y && px.x < u_roi.x + u_roi.z && px.y < u_roi.y + u_roi.w;
    vec4 c;
    vec3 ms;   // (mask, sky occlusion, its reflected part), warped (and blurred in stage 2)
    if (u_stage == 1) {
        c = vec4(0.0);
        ms = vec3(0.0);
        if (inside) warp(px, c, ms);
        o_rgb = c;
        o_mask = vec4(ms, 0.0);
        return;
    }
    uvec3 bgr = texelFetch(u_photo, px, 0).rgb;
    if (!inside) {
        o_rgb = vec4(vec3(bgr) / 255.0, 1.0);
        o_mask = vec4(0.0);
        return;
    }
    if (u_stage == 2) {
        c = texelFetch(u_bl_color, px - u_blurred_origin, 0);
        ms = texelFetch(u_bl_mask, px - u_blurred_origin, 0).rgb;
    } else {
        warp(px, c, ms);
    }
    float m = ms.x;
    // composite(): linear light, B, G, R order as the numpy path
    vec3 lin = vec3(texelFetch(u_decode, ivec2(int(bgr.r), 0), 0).r,
                    texelFetch(u_decode, ivec2(int(bgr.g), 0), 0).r,
                    texelFetch(u_decode, ivec2(int(bgr.b), 0), 0).r);
    // (1 - alpha) - opacity * mask * (1 - tint), clamped at 0: the mask is coverage-weighted like the
    // colour, so it is subtracted from the uncovered share (composite.py: no seam along the contact)
    float keep = u_occluder ? 1.0 - c.a : 1.0;
    float g = keep;
    if (u_sky) {
        // _darken_sky: keep - opacity * mask * (1 - tint) - sky * (1 - opacity * (1 - tint)), clipped at 0,
        // the warped sky clipped to [-1, 1] first (numpy_compose.py), whatever the opacity
        // (per colour channel with a coloured object's reflected light: composite.sky_planes)
        vec3 s = clamp(vec3(ms.y) - vec3(ms.z) * u_bleed, -1.0, 1.0);
        lin *= max(vec3(keep) + vec3(m) * u_sky_wm + s * u_sky_ws, vec3(0.0));
        g = 1.0;
    } else if (u_darken) {
        if (u_gray) {
            g = max(m * u_gray_k + keep, 0.0);
        } else {
            lin *= max((vec3(m) * -u_dark) + keep, vec3(0.0));
            g = 1.0;
        }
    }
    lin *= g;
    if (u_occluder) {
        lin += c.bgr * u_gain;   // premultiplied colour, RGB -> BGR
    }
    vec3 idx = clamp(lin * 65535.0 + 0.5, 0.0, 65535.0);
    uvec3 k = uvec3(idx);   // truncation, as numpy's unsafe cast to uint16
    uvec3 o = uvec3(texelFetch(u_encode, ivec2(int(k.r & 255u), int(k.r >> 8)), 0).r,
                    texelFetch(u_encode, ivec2(int(k.g & 255u), int(k.g >> 8)), 0).r,
                    texelFetch(u_encode, ivec2(int(k.b & 255u), int(k.b >> 8)), 0).r);
    if (u_noise && u_occluder && c.a != 0.0) {
        // add_noise(): sigma looked up per channel at the composited code, times the coverage, rounded
        // half to even (np.round) and clipped
        vec3 sig = vec3(texelFetch(u_noise_tab, ivec2(int(o.r), 0), 0).r,
                        texelFetch(u_noise_tab, ivec2(int(o.g), 0), 0).g,
                        texelFetch(u_noise_tab, ivec2(int(o.b), 0), 0).b);
        vec3 z = vec3(gauss(px, 0u), gauss(px, 1u), gauss(px, 2u));
        o = uvec3(clamp(roundEven(z * sig * c.a + vec3(o)), 0.0, 255.0));
    }
    o_rgb = vec4(vec3(o) / 255.0, 1.0);
    float mm = clamp(m * 255.0 + 0.5, 0.0, 255.0);
    o_mask = vec4(floor(mm) / 255.0, 0.0, 0.0, 0.0);
}
