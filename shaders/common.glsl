// glradial common.glsl: coordinate conventions and the radial lens model.
//
// Include this file in every program (glradial.shaderlib expands the include directive); it needs
// nothing injected from Python and compiles as GLSL 3.30 core on its own after a `#version` line.
// Every function below has a NumPy twin of the same name in glradial/lens/lensfuncs.py.
//
// Conventions (docs/DESIGN.md):
//   Pixel (x, y): integer indices are pixel centres, x right, y down; image W x H.
//   Texture coordinates: u = (x + 0.5) / W, v = (y + 0.5) / H; v = 0 is the first row in memory
//     (the top of the image). Rendering keeps that: output row y is gl_FragCoord.y = y + 0.5, and the
//     readback's first row is y = 0, so no flip happens anywhere.
//   Lens coordinates ("apparent distortion at scale", image width = 1):
//     p = (u - 0.5, (v - 0.5) * H / W); principal point at the image centre; aspect_hw = H / W.
//   A lens may also carry a principal point and a pixel aspect (glradial.Lens's cx, cy,
//   pixel_aspect): centre = (cx, cy) is the principal point's offset from the image centre in
//   width units (x right, y down), pixel_aspect = fy / fx (OpenCV's focal lengths); then
//     p = (u - 0.5 - cx, ((v - 0.5) * H / W - cy) / pixel_aspect),
//   so radii stay normalised by the image width along x. centre = (0, 0), pixel_aspect = 1 is the
//   centred model above (the two-argument lens_from_uv / uv_from_lens).
//   A lens is vec2 k = (k1, k2) in lens units.
//   Forward model (undistorted -> distorted): p_d = p_u * (1 + k1 r_u^2 + k2 r_u^4).
//   Correction (undistortion) samples the input at p_d for each output p_u: no inverse needed.
//   Distortion samples the input at p_u = inverse(p_d): Drap-Lefevre (approximate, the paper's)
//   or exact (bounded Newton seeded by Drap-Lefevre).

#ifndef LENS_NEWTON_STEPS
#define LENS_NEWTON_STEPS 8
#endif

// Largest residual |P(r_u) - r_d| (lens units) for which the exact inverse counts as found.
#define LENS_INVERSE_TOLERANCE 1.0e-4

// A radius far beyond any a frame uses: "the lens never folds over".
#define LENS_RADIUS_UNBOUNDED 1.0e6

// Lens point of a texture coordinate for a lens with principal point `centre` (offset from the
// image centre, width units) and pixel aspect fy / fx.
vec2 lens_from_uv(vec2 uv, float aspect_hw, vec2 centre, float pixel_aspect) {
    return vec2(uv.x - 0.5 - centre.x, ((uv.y - 0.5) * aspect_hw - centre.y) / pixel_aspect);
}

vec2 uv_from_lens(vec2 p, float aspect_hw, vec2 centre, float pixel_aspect) {
    return vec2(p.x + centre.x + 0.5, (p.y * pixel_aspect + centre.y) / aspect_hw + 0.5);
}

// The centred model: principal point at the image centre, square pixels.
vec2 lens_from_uv(vec2 uv, float aspect_hw) {
    return lens_from_uv(uv, aspect_hw, vec2(0.0), 1.0);
}

vec2 uv_from_lens(vec2 p, float aspect_hw) {
    return uv_from_lens(p, aspect_hw, vec2(0.0), 1.0);
}

// D = 1 + k1 r^2 + k2 r^4 from the squared undistorted radius.
float radial_factor(float r2, vec2 k) {
    return 1.0 + k.x * r2 + k.y * r2 * r2;
}

// d/dr [r D(r)] = 1 + 3 k1 r^2 + 5 k2 r^4; the lens folds over where this is <= 0.
float radial_slope(float r, vec2 k) {
    float r2 = r * r;
    return 1.0 + 3.0 * k.x * r2 + 5.0 * k.y * r2 * r2;
}

// Smallest radius > 0 where radial_slope is 0, or LENS_RADIUS_UNBOUNDED.
float fold_radius(vec2 k) {
    float a = 5.0 * k.y;
    float b = 3.0 * k.x;
    float s = LENS_RADIUS_UNBOUNDED * LENS_RADIUS_UNBOUNDED;
    if (abs(a) < 1e-15) {
        if (b < 0.0) s = -1.0 / b;
    } else {
        float disc = b * b - 4.0 * a;
        if (disc >= 0.0) {
            float sq = sqrt(disc);
            float s1 = (-b - sq) / (2.0 * a);
            float s2 = (-b + sq) / (2.0 * a);
            if (s1 > 0.0) s = min(s, s1);
            if (s2 > 0.0) s = min(s, s2);
        }
    }
    return sqrt(s);
}

vec2 distort_point(vec2 p_u, vec2 k) {
    return p_u * radial_factor(dot(p_u, p_u), k);
}

// (b1, b2, b3, b4) of the Drap-Lefevre inverse for k3 = k4 = 0.
vec4 drap_coefficients(vec2 k) {
    float k1 = k.x;
    float k2 = k.y;
    return vec4(-k1,
                3.0 * k1 * k1 - k2,
                -12.0 * k1 * k1 * k1 + 8.0 * k1 * k2,
                55.0 * k1 * k1 * k1 * k1 - 55.0 * k1 * k1 * k2 + 5.0 * k2 * k2);
}

// Approximate inverse: p_u = p_d (1 + b1 r^2 + b2 r^4 + b3 r^6 + b4 r^8), r = |p_d|.
vec2 undistort_point_drap(vec2 p_d, vec2 k) {
    vec4 b = drap_coefficients(k);
    float r2 = dot(p_d, p_d);
    return p_d * (1.0 + r2 * (b.x + r2 * (b.y + r2 * (b.z + r2 * b.w))));
}

// Exact inverse of the radial map: r (1 + k1 r^2 + k2 r^4) = r_d, r in [0, fold_radius].
// Returns r_u in .x and 1.0 in .y where a solution exists, 0.0 where r_d is beyond the largest
// distorted radius the lens reaches.
vec2 undistort_radius_exact(float r_d, vec2 k) {
    vec4 b = drap_coefficients(k);
    float r_fold = fold_radius(k);
    float rd2 = r_d * r_d;
    float r = clamp(r_d * (1.0 + rd2 * (b.x + rd2 * (b.y + rd2 * (b.z + rd2 * b.w)))), 0.0, r_fold);
    for (int i = 0; i < LENS_NEWTON_STEPS; ++i) {
        float f = r * radial_factor(r * r, k) - r_d;
        float slope = max(radial_slope(r, k), 1e-6);
        r = clamp(r - f / slope, 0.0, r_fold);
    }
    float residual = abs(r * radial_factor(r * r, k) - r_d);
    return vec2(r, residual <= LENS_INVERSE_TOLERANCE * max(1.0, r_d) ? 1.0 : 0.0);
}

// Exact inverse for a point: xy = p_u, z = 1.0 where valid, 0.0 where no undistorted point maps here.
vec3 undistort_point_exact(vec2 p_d, vec2 k) {
    float r_d = length(p_d);
    vec2 rv = undistort_radius_exact(r_d, k);
    float scale = r_d > 0.0 ? rv.x / r_d : 1.0;
    return vec3(p_d * scale, rv.y);
}
