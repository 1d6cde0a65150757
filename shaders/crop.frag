// glradial crop.frag: distorted perspective crops of an equirectangular panorama, many per draw.
//
// Drawn with crop.vert: one instanced quad per tile of a vertical atlas; the tile's first row
// (v_top) and its parameters arrive as flat varyings:
//   v_r0 = (R00, R01, R02, f), v_r1 = (R10, R11, R12, k1), v_r2 = (R20, R21, R22, k2),
// R = R_pan * R_tilt * R_roll maps camera rays (x right, y down, z forward) to world rays and
// f = 1 / (2 tan(hfov / 2)) is the focal length in lens units (image width = 1).
//
// Geometry of one output pixel (uv in <0;1> over the tile, lens aspect from the frame geometry):
//   p_d = lens_from_uv(uv, u_aspect_hw); p_u = inverse(p_d): exact (bounded Newton, common.glsl),
//   the same exact inverse as the lens's Chebyshev series in r_d^2 when CROP_INVERSE_SERIES is 1
//   (fitted and checked per crop on the CPU: glradial/lens/inverse_series.py), or Drap-Lefevre when
//   CROP_INVERSE_DRAP is 1; camera ray (p_u.x, p_u.y, f); world ray w = R * camera ray;
//   longitude = atan(w.x, w.z) (0 = centre column, + right), latitude = atan(-w.y, |w.xz|) (+ up);
//   panorama texture coordinates u = 0.5 + lon / (2 pi), v = 0.5 - lat / pi (v = 0 is the top row).
// Where the exact inverse has no solution the sample is 0.
//
// Anti-aliasing: the footprint of the output pixel is the change of the world ray across it
// (dFdx/dFdy of the ray, smooth everywhere, so there is no seam at +-180 degrees), turned into
// d(u, v) analytically. CROP_SUPERSAMPLE_X x CROP_SUPERSAMPLE_Y samples on a regular sub-pixel grid,
// placed with that local linear map, each read from the mipmapped panorama with textureGrad at a
// sub-pixel footprint, are averaged: a box (area) filter over the output pixel. The texture repeats
// in u (u may leave [0, 1] near the seam), clamps in v. The validity of the pixel centre decides.

#include "common.glsl"

#ifndef CROP_SUPERSAMPLE_X
#define CROP_SUPERSAMPLE_X 1
#endif
#ifndef CROP_SUPERSAMPLE_Y
#define CROP_SUPERSAMPLE_Y 1
#endif
#ifndef CROP_INVERSE_DRAP
#define CROP_INVERSE_DRAP 0
#endif
#ifndef CROP_INVERSE_SERIES
#define CROP_INVERSE_SERIES 0
#endif

#define CROP_PI 3.14159265358979

uniform sampler2D u_panorama;
uniform ivec2 u_tile_size;    // (w, h) of one output tile in pixels
uniform float u_aspect_hw;    // H / W of the frame geometry the lens refers to (9/16 for 1280x720)
uniform float u_series_scale; // 2 / r_c^2, r_c = corner radius of that frame (lens units)

flat in vec4 v_r0;
flat in vec4 v_r1;
flat in vec4 v_r2;
flat in vec4 v_s0;  // inverse series c0..c3
flat in vec4 v_s1;  // c4..c7
flat in vec4 v_s2;  // c8..c10, tile index
flat in float v_top;

out vec4 frag_color;

// s(x) = sum_i c_i T_i(x) by Clenshaw's recurrence, x = 2 r_d^2 / r_c^2 - 1; r_u = r_d s.
float inverse_series(float x) {
    float b1 = 0.0, b2 = 0.0, b0;
    float x2 = 2.0 * x;
    b0 = v_s2.z + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s2.y + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s2.x + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s1.w + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s1.z + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s1.y + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s1.x + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s0.w + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s0.z + x2 * b1 - b2; b2 = b1; b1 = b0;
    b0 = v_s0.y + x2 * b1 - b2; b2 = b1; b1 = b0;
    return v_s0.x + x * b1 - b2;
}

// World ray through tile position uv; .w = 1 where the inverse exists, 0 where it does not.
vec4 world_ray(vec2 uv) {
    vec2 p_d = lens_from_uv(uv, u_aspect_hw);
    vec2 k = vec2(v_r1.w, v_r2.w);
#if CROP_INVERSE_SERIES
    vec3 c = vec3(p_d * inverse_series(dot(p_d, p_d) * u_series_scale - 1.0), v_r0.w);
    float valid = 1.0;
#elif CROP_INVERSE_DRAP
    vec3 c = vec3(undistort_point_drap(p_d, k), v_r0.w);
    float valid = 1.0;
#else
    vec3 pu = undistort_point_exact(p_d, k);
    vec3 c = vec3(pu.xy, v_r0.w);
    float valid = pu.z;
#endif
    return vec4(dot(v_r0.xyz, c), dot(v_r1.xyz, c), dot(v_r2.xyz, c), valid);
}

void main() {
    vec2 pix = vec2(gl_FragCoord.x - 0.5, gl_FragCoord.y - 0.5 - v_top);
    vec4 w = world_ray((pix + 0.5) / vec2(u_tile_size));
    // Change of the world ray across one output pixel (smooth, no seam), then of (lon, lat).
    vec3 dwx = dFdx(w.xyz);
    vec3 dwy = dFdy(w.xyz);
    float rho2 = max(w.x * w.x + w.z * w.z, 1e-20);
    float rho = sqrt(rho2);
    float n2 = rho2 + w.y * w.y;
    vec2 lonlat = vec2(atan(w.x, w.z), atan(-w.y, rho));
    // d lon = (z dx - x dz) / rho^2; d lat = (-rho dy + y d rho) / |w|^2 with d rho = (x dx + z dz) / rho
    vec2 gx = vec2((w.z * dwx.x - w.x * dwx.z) / rho2, (-rho * dwx.y + w.y * (w.x * dwx.x + w.z * dwx.z) / rho) / n2);
    vec2 gy = vec2((w.z * dwy.x - w.x * dwy.z) / rho2, (-rho * dwy.y + w.y * (w.x * dwy.x + w.z * dwy.z) / rho) / n2);
    vec2 scale = vec2(0.5 / CROP_PI, -1.0 / CROP_PI);
    vec2 tex = vec2(0.5) + lonlat * scale;
    vec2 tx = gx * scale;
    vec2 ty = gy * scale;
#if CROP_SUPERSAMPLE_X == 1 && CROP_SUPERSAMPLE_Y == 1
    vec4 acc = textureGrad(u_panorama, tex, tx, ty);
#else
    // Samples at the centres of an SX x SY grid of sub-pixels, placed with the local linear map
    // (first-order Taylor expansion of the mapping across the pixel), footprint one sub-pixel each.
    const vec2 count = vec2(CROP_SUPERSAMPLE_X, CROP_SUPERSAMPLE_Y);
    vec2 sx = tx / count.x;
    vec2 sy = ty / count.y;
    vec4 acc = vec4(0.0);
    for (int j = 0; j < CROP_SUPERSAMPLE_Y; ++j) {
        for (int i = 0; i < CROP_SUPERSAMPLE_X; ++i) {
            vec2 o = (vec2(i, j) + 0.5) / count - 0.5;
            acc += textureGrad(u_panorama, tex + o.x * tx + o.y * ty, sx, sy);
        }
    }
    acc /= count.x * count.y;
#endif
    frag_color = w.w > 0.5 ? acc : vec4(0.0);
}
