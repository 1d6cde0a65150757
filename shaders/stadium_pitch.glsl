// glradial stadium_pitch.glsl: grass (mowing stripes, texture, wear) and the pitch markings.
// Coordinates: metres, pitch centre at the origin, x along the length (goal lines x = +-52.5),
// y across (touchlines y = +-34). jx, jy: change of the ground point per sample step across and
// down the panorama (metres), used to box-filter every pattern by the true pixel footprint.

#define HALF_L 52.5
#define HALF_W 34.0

// Footprint width of a distance function with unit gradient n (metres).
float footprint_along(vec2 n, vec2 jx, vec2 jy) {
    return abs(dot(n, jx)) + abs(dot(n, jy)) + 1e-5;
}

// Coverage of a straight segment a-b of line width w.
float seg_cov(vec2 p, vec2 a, vec2 b, float w, vec2 jx, vec2 jy) {
    vec2 ab = b - a;
    float h = clamp(dot(p - a, ab) / dot(ab, ab), 0.0, 1.0);
    vec2 q = p - (a + h * ab);
    float dist = length(q);
    vec2 n = dist > 1e-6 ? q / dist : vec2(0.0, 1.0);
    // along-segment ends: use the perpendicular gradient for the footprint (ends are short)
    vec2 perp = normalize(vec2(-ab.y, ab.x));
    float fw = footprint_along(h > 0.0 && h < 1.0 ? perp : n, jx, jy);
    return band_coverage(dist, w, fw);
}

// Coverage of a circle (radius r, centre c) line of width w, restricted by the caller.
float ring_cov(vec2 p, vec2 c, float r, float w, vec2 jx, vec2 jy) {
    vec2 q = p - c;
    float l = max(length(q), 1e-5);
    float fw = footprint_along(q / l, jx, jy);
    return band_coverage(l - r, w, fw);
}

// Coverage of a filled disc (radius r): 1-D box filter times the area fraction when sub-pixel.
float spot_cov(vec2 p, vec2 c, float r, vec2 jx, vec2 jy) {
    vec2 q = p - c;
    float l = max(length(q), 1e-5);
    float fw = footprint_along(q / l, jx, jy);
    float fw2 = footprint_along(vec2(-q.y, q.x) / l, jx, jy);
    return band_coverage(l, 2.0 * r, fw) * min(1.0, 2.0 * r / fw2);
}

// Coverage (0..1) of the white markings at ground point g.
float markings(vec2 g, vec2 jx, vec2 jy, float w) {
    // fold into the first quadrant; the footprint only needs absolute values, so flip jx, jy too
    vec2 s = sign(g + 1e-7);
    vec2 p = abs(g);
    jx *= s;
    jy *= s;
    if (p.x > HALF_L + 2.0 || p.y > HALF_W + 2.0) return 0.0;
    float hw = 0.5 * w;
    float c = 0.0;
    c = max(c, seg_cov(p, vec2(0.0, HALF_W - hw), vec2(HALF_L - hw, HALF_W - hw), w, jx, jy));   // touchline
    c = max(c, seg_cov(p, vec2(HALF_L - hw, 0.0), vec2(HALF_L - hw, HALF_W - hw), w, jx, jy));   // goal line
    c = max(c, band_coverage(p.x, w, footprint_along(vec2(1.0, 0.0), jx, jy)) * step(p.y, HALF_W)); // halfway
    if (p.x < 12.0) c = max(c, ring_cov(p, vec2(0.0), 9.15, w, jx, jy));                        // centre circle
    c = max(c, spot_cov(p, vec2(0.0), 0.15, jx, jy));                                             // centre spot
    if (p.x > 30.0) {
        float xa = HALF_L - 16.5 + hw;
        c = max(c, seg_cov(p, vec2(xa, 0.0), vec2(xa, 20.16 + hw), w, jx, jy));                  // penalty area
        c = max(c, seg_cov(p, vec2(xa, 20.16 + hw), vec2(HALF_L, 20.16 + hw), w, jx, jy));
        float xg = HALF_L - 5.5 + hw;
        c = max(c, seg_cov(p, vec2(xg, 0.0), vec2(xg, 9.16 + hw), w, jx, jy));                   // goal area
        c = max(c, seg_cov(p, vec2(xg, 9.16 + hw), vec2(HALF_L, 9.16 + hw), w, jx, jy));
        c = max(c, spot_cov(p, vec2(HALF_L - 11.0, 0.0), 0.11, jx, jy));                          // penalty spot
        if (p.x < xa - hw) c = max(c, ring_cov(p, vec2(HALF_L - 11.0, 0.0), 9.15, w, jx, jy));  // arc
        if (p.x > HALF_L - 2.0 && p.y > HALF_W - 2.0)
            c = max(c, ring_cov(p, vec2(HALF_L, HALF_W), 1.0, w, jx, jy) * step(p.x, HALF_L) * step(p.y, HALF_W)); // corner
    }
    return c;
}

// Signed stripe field in [-1, 1] (filtered) and the horizontal mowing direction of this band.
vec3 stripes(vec2 g, vec2 jx, vec2 jy) {
    float w = u_stripe_width;
    if (u_stripe_pattern == 0) {        // bands across the pitch, varying along x
        float f = footprint_along(vec2(1.0, 0.0), jx, jy) / (2.0 * w);
        float s = filtered_square(g.x / (2.0 * w), f);
        return vec3(s, 0.0, 1.0);
    } else if (u_stripe_pattern == 1) { // bands along the pitch, varying along y
        float f = footprint_along(vec2(0.0, 1.0), jx, jy) / (2.0 * w);
        float s = filtered_square(g.y / (2.0 * w), f);
        return vec3(s, 1.0, 0.0);
    } else if (u_stripe_pattern == 2) { // checkerboard
        float fx = footprint_along(vec2(1.0, 0.0), jx, jy) / (2.0 * w);
        float fy = footprint_along(vec2(0.0, 1.0), jx, jy) / (2.0 * w);
        float s = filtered_square(g.x / (2.0 * w), fx) * filtered_square(g.y / (2.0 * w), fy);
        return vec3(s, 0.7071, 0.7071);
    } else if (u_stripe_pattern == 3) { // diagonal
        vec2 n = vec2(cos(u_stripe_angle), sin(u_stripe_angle));
        float f = footprint_along(n, jx, jy) / (2.0 * w);
        float s = filtered_square(dot(g, n) / (2.0 * w), f);
        return vec3(s, -n.y, n.x);
    }
    return vec3(0.0, 1.0, 0.0);
}

// Grass albedo (linear RGB) at ground point g seen along horizontal view direction v.
vec3 grass_albedo(vec2 g, vec2 jx, vec2 jy, vec2 v, float fp) {
    vec3 st = stripes(g, jx, jy);
    // mown grass looks lighter when seen along the direction the blades were laid
    float view = dot(v, st.yz);
    float shade = 1.0 + st.x * (u_stripe_contrast * view + u_stripe_offset);
    float n = 0.45 * (filtered_noise(g, 0.35, fp, 1u) - 0.5)
            + 0.35 * (filtered_noise(g, 1.7, fp, 2u) - 0.5)
            + 0.5 * (filtered_noise(g, 9.0, fp, 3u) - 0.5);
    float patch = filtered_noise(g, 28.0, fp, 4u);
    vec3 col = mix(u_grass, u_grass2, smoothstep(0.3, 0.8, patch) * 0.8);
    col *= shade * (1.0 + u_grass_noise * 0.35 * n);
    // wear: goal mouths, penalty spots, centre circle, linesmen's strips
    vec2 p = abs(g);
    if (u_wear <= 0.0 || (p.x < HALF_L - 20.0 && length(p) > 16.0 && abs(p.y - HALF_W - 1.5) > 3.0)) return col;
    float wear = exp(-dot(p - vec2(HALF_L - 3.0, 0.0), p - vec2(HALF_L - 3.0, 0.0)) / 18.0)
               + 0.6 * exp(-dot(p - vec2(HALF_L - 11.0, 0.0), p - vec2(HALF_L - 11.0, 0.0)) / 8.0)
               + 0.4 * exp(-dot(p, p) / 40.0)
               + 0.35 * exp(-pow((p.y - (HALF_W + 1.5)) / 0.8, 2.0)) * step(p.x, HALF_L * 0.95);
    wear *= u_wear * (0.5 + filtered_noise(g, 0.8, fp, 5u)) * smoothstep(0.2, 0.6, filtered_noise(g, 3.0, fp, 6u) + 0.2);
    col = mix(col, vec3(0.22, 0.16, 0.08) * (0.8 + 0.4 * n), clamp(wear, 0.0, 0.85));
    return col;
}

#define TRACK_HALF_STRAIGHT 42.195
#define TRACK_RADIUS 36.5
#define TRACK_LANE 1.22
#define TRACK_LANES 8.0

// Ground albedo: grass, or an athletics track (tartan with lane lines) around it, or the surface
// behind the boards. g ground point, jx jy footprint, v horizontal view direction, fp footprint.
vec3 ground_albedo(vec2 g, vec2 jx, vec2 jy, vec2 v, float fp) {
    if (u_track != 0) {
        vec2 q = vec2(max(abs(g.x) - TRACK_HALF_STRAIGHT, 0.0), g.y);
        float rr = length(q);
        float lane = rr - TRACK_RADIUS;
        if (lane >= 0.0) {
            vec3 col = u_surround * (0.9 + 0.2 * filtered_noise(g, 1.3, fp, 7u));
            if (lane < TRACK_LANES * TRACK_LANE + 0.1) {
                vec2 n = vec2(q.x * sign(g.x), q.y) / max(rr, 1e-4);  // gradient of rr
                float fw = footprint_along(n, jx, jy);
                float k = clamp(floor(lane / TRACK_LANE + 0.5), 0.0, TRACK_LANES);
                col = mix(col, vec3(0.8), band_coverage(lane - k * TRACK_LANE, 0.05, fw));
            } else {
                col *= 0.8;
            }
            return col;
        }
    } else if (abs(g.x) > u_side_d[0].z + 0.3 || abs(g.y) > u_side_d[2].z + 0.3) {
        return u_surround * (0.9 + 0.2 * filtered_noise(g, 1.3, fp, 7u));
    }
    vec3 col = grass_albedo(g, jx, jy, v, fp);
    return mix(col, vec3(u_line_brightness), markings(g, jx, jy, u_line_width));
}
