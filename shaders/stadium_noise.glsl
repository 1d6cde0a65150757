// glradial stadium_noise.glsl: integer hashes and filtered value noise for the stadium shader.
// Integer hashes make the panorama identical on every run of one driver.

uint hash_u(uint x) {
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

uint hash_u2(ivec2 p, uint salt) {
    return hash_u(uint(p.x) * 0x9e3779b1u ^ hash_u(uint(p.y) + salt * 0x85ebca6bu));
}

// Uniform float in [0, 1) from a cell and a salt.
float hash2(ivec2 p, uint salt) {
    return float(hash_u2(p, salt) >> 8u) * (1.0 / 16777216.0);
}

float hash1(int i, uint salt) {
    return float(hash_u(uint(i) * 0x9e3779b1u + salt * 0x632be5abu) >> 8u) * (1.0 / 16777216.0);
}

// Smooth value noise in [0, 1], one unit = one cell.
float value_noise(vec2 p, uint salt) {
    vec2 c = floor(p);
    vec2 f = p - c;
    vec2 w = f * f * (3.0 - 2.0 * f);
    ivec2 i = ivec2(c);
    float a = hash2(i, salt);
    float b = hash2(i + ivec2(1, 0), salt);
    float cc = hash2(i + ivec2(0, 1), salt);
    float d = hash2(i + ivec2(1, 1), salt);
    return mix(mix(a, b, w.x), mix(cc, d, w.x), w.y);
}

// Value noise at cell size `scale` (metres), faded to its mean 0.5 when the footprint `fp`
// (metres) approaches the cell size: detail finer than a pixel is averaged, never aliased.
float filtered_noise(vec2 p, float scale, float fp, uint salt) {
    float fade = 1.0 - smoothstep(0.3 * scale, 1.2 * scale, fp);
    if (fade <= 0.0) return 0.5;
    return mix(0.5, value_noise(p / scale, salt), fade);
}

// CDF of the unit tent filter (support [-1, 1]).
float tent_cdf(float u) {
    u = clamp(u, -1.0, 1.0);
    return u < 0.0 ? 0.5 * (u + 1.0) * (u + 1.0) : 1.0 - 0.5 * (1.0 - u) * (1.0 - u);
}

// Coverage of the band |s| <= w/2 (s: signed distance from its centre line, metres) seen through a
// pixel of footprint fw (metres), filtered with a tent of half-width fw (a 2-pixel-wide bilinear
// kernel). Unlike a 1-pixel box, the tent keeps the sub-pixel position of lines thinner than a
// pixel: their brightness centroid moves linearly with the line instead of snapping to a row.
float band_coverage(float s, float w, float fw) {
    fw = max(fw, 1e-5);
    return tent_cdf((0.5 * w - s) / fw) - tent_cdf((-0.5 * w - s) / fw);
}

// Box-filtered square wave: +1 on [0, 1/2), -1 on [1/2, 1) (period 1) averaged over width fw.
float tri_integral(float x) {
    // integral of the square wave from 0 to x
    float f = fract(x);
    return f < 0.5 ? f : 1.0 - f;
}
float filtered_square(float x, float fw) {
    fw = max(fw, 1e-5);
    if (fw >= 1.0) return 0.0;
    return (tri_integral(x + 0.5 * fw) - tri_integral(x - 0.5 * fw)) / fw;
}
