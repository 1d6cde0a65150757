// glradial sampling.glsl: reads the source image at a texture coordinate, with a constant fill
// outside the image's area.
//
// Border rule: a position outside the input's area (uv outside [0, 1], i.e. pixel coordinates
// outside [-0.5, W - 0.5] x [-0.5, H - 0.5], or NaN) gets u_fill exactly; a position inside it is
// interpolated, and taps beyond the edge repeat the edge pixel (OpenCV's BORDER_REPLICATE), so the
// fill never bleeds into valid pixels and the result ends with a hard edge.
//
// Inject SAMPLING_INTERPOLATION (glradial.shaderlib defines) as one of the names below; linear is
// the default. Every tap is a texelFetch, so the caller's sampler state (filter, wrap, mipmaps)
// never matters and the result is the same on every driver.
//   Pixel coordinates: xy = uv * size - 0.5, pixel centres at integers (docs/DESIGN.md).
//   nearest: the tap at round(xy) (halves round up).
//   linear:  bilinear over the 2x2 taps around xy.
//   cubic:   Keys cubic convolution, a = -0.75, over the 4x4 taps (OpenCV's INTER_CUBIC kernel).
// Uniforms: u_source (sampler2D, unit chosen by the caller), u_fill (vec4, texture units: value/255
// for 8-bit normalized textures, value/65535 for 16-bit, raw for float textures).

#define SAMPLING_NEAREST 0
#define SAMPLING_LINEAR 1
#define SAMPLING_CUBIC 2

#ifndef SAMPLING_INTERPOLATION
#define SAMPLING_INTERPOLATION SAMPLING_LINEAR
#endif

// Keys' cubic convolution parameter (OpenCV uses the same value for INTER_CUBIC).
#define SAMPLING_CUBIC_A -0.75

uniform sampler2D u_source;
uniform vec4 u_fill;

vec4 fetch_clamped(ivec2 texel, ivec2 size) {
    return texelFetch(u_source, clamp(texel, ivec2(0), size - 1), 0);
}

// Weights of the taps at offsets -1, 0, 1, 2 for a fractional position t in [0, 1).
vec4 cubic_weights(float t) {
    float a = SAMPLING_CUBIC_A;
    float w0 = ((a * (t + 1.0) - 5.0 * a) * (t + 1.0) + 8.0 * a) * (t + 1.0) - 4.0 * a;
    float w1 = ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0;
    float w2 = ((a + 2.0) * (1.0 - t) - (a + 3.0)) * (1.0 - t) * (1.0 - t) + 1.0;
    return vec4(w0, w1, w2, 1.0 - w0 - w1 - w2);
}

vec4 sample_source(vec2 uv) {
    // Written so that NaN (every comparison false) also takes the fill.
    if (!(all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0))))) {
        return u_fill;
    }
    ivec2 size = textureSize(u_source, 0);
    vec2 xy = uv * vec2(size) - 0.5;
#if SAMPLING_INTERPOLATION == SAMPLING_NEAREST
    return fetch_clamped(ivec2(floor(xy + 0.5)), size);
#else
    vec2 base = floor(xy);
    vec2 t = xy - base;
    ivec2 i = ivec2(base);
#if SAMPLING_INTERPOLATION == SAMPLING_LINEAR
    vec4 top = mix(fetch_clamped(i, size), fetch_clamped(i + ivec2(1, 0), size), t.x);
    vec4 bottom = mix(fetch_clamped(i + ivec2(0, 1), size), fetch_clamped(i + ivec2(1, 1), size), t.x);
    return mix(top, bottom, t.y);
#else
    vec4 wx = cubic_weights(t.x);
    vec4 wy = cubic_weights(t.y);
    vec4 result = vec4(0.0);
    for (int row = 0; row < 4; ++row) {
        ivec2 r = i + ivec2(-1, row - 1);
        vec4 line = wx.x * fetch_clamped(r, size) + wx.y * fetch_clamped(r + ivec2(1, 0), size)
                  + wx.z * fetch_clamped(r + ivec2(2, 0), size) + wx.w * fetch_clamped(r + ivec2(3, 0), size);
        result += wy[row] * line;
    }
    return result;
#endif
#endif
}
