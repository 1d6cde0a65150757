// glradial stadium_stands.glsl: ray casting of the stands (per-side 2-D profiles), boards, masts,
// and their surface textures. Side i has outward normal side_normal(i), its profile coordinates are
// d = dot(p.xy, n) - u_side_a[i].x (metres beyond the stand front) and z.

#define NSEG 10
#define MAT_SKY -1
#define MAT_GROUND 0
#define MAT_FRONT 1
#define MAT_SEAT1 2
#define MAT_BACK 3
#define MAT_SOFFIT 4
#define MAT_BALCONY 5
#define MAT_SEAT2 6
#define MAT_ROOF_UNDER 7
#define MAT_FASCIA 8
#define MAT_ROOF_TOP 9
#define MAT_BOARD 10
#define MAT_MAST 11
#define MAT_LAMP 12
#define MAT_OUTSIDE 13

vec2 side_normal(int i) {
    return i == 0 ? vec2(1.0, 0.0) : i == 1 ? vec2(-1.0, 0.0) : i == 2 ? vec2(0.0, 1.0) : vec2(0.0, -1.0);
}

float side_d(int i, vec2 p) {
    return dot(p, side_normal(i)) - u_side_a[i].x;
}

// Height of the seating surface of side i at profile distance d (0 outside the stand).
float side_surface(int i, float d) {
    vec4 a = u_side_a[i];
    vec4 b = u_side_b[i];
    vec4 c = u_side_c[i];
    if (d < 0.0 || d > c.y) return 0.0;
    if (b.x > 0.5 && d >= b.y) return b.z + b.w + c.x * (d - b.y);
    return a.y + a.z * d;
}

// The side whose wedge (mitered corners) holds p: the largest d.
int owner_side(vec2 p, out float dmax) {
    int best = 0;
    dmax = side_d(0, p);
    for (int i = 1; i < 4; ++i) {
        float d = side_d(i, p);
        if (d > dmax) { dmax = d; best = i; }
    }
    return best;
}

// Corner index of a point in a corner quadrant (beyond two stand fronts), or -1.
// Corner c joins x-side (c & 1) and y-side 2 + (c >> 1).
int corner_of(vec2 p) {
    int ix = p.x < 0.0 ? 1 : 0;
    int iy = p.y < 0.0 ? 3 : 2;
    if (side_d(ix, p) > 0.0 && side_d(iy, p) > 0.0) return ix + 2 * (iy - 2);
    return -1;
}

bool corner_open(vec2 p) {
    int c = corner_of(p);
    return c >= 0 && u_open_corner[c] != 0;
}

float cross2(vec2 a, vec2 b) { return a.x * b.y - a.y * b.x; }

struct Hit {
    float t;
    int mat;
    int side;
    vec3 n;   // surface normal (world)
};

// Intersect the ray with side i's profile segments; keeps the nearest hit owned by side i.
void hit_side(int i, vec3 ro, vec3 rd, inout Hit h) {
    vec2 n = side_normal(i);
    vec2 o = vec2(dot(ro.xy, n) - u_side_a[i].x, ro.z);
    vec2 r = vec2(dot(rd.xy, n), rd.z);
    for (int k = 0; k < u_nseg[i]; ++k) {
        vec4 s = u_seg[i * NSEG + k];
        vec2 a = s.xy;
        vec2 e = s.zw - s.xy;
        float den = cross2(r, e);
        if (abs(den) < 1e-9) continue;
        vec2 ao = a - o;
        float t = cross2(ao, e) / den;
        float u = cross2(ao, r) / den;
        if (t <= 1e-3 || t >= h.t || u < 0.0 || u > 1.0) continue;
        vec3 p = ro + t * rd;
        float dmax;
        if (owner_side(p.xy, dmax) != i && side_d(i, p.xy) < dmax - 1e-3) continue;
        if (corner_open(p.xy)) continue;
        h.t = t;
        h.mat = int(u_segmat[i * NSEG + k] + 0.5);
        h.side = i;
        vec2 en = normalize(vec2(-e.y, e.x));
        if (dot(en, r) > 0.0) en = -en;
        h.n = normalize(vec3(n * en.x, en.y));
    }
}

// Closed corners: vertical miter faces between adjacent sides where one stand is higher than its
// neighbour. Open corners: the vertical end faces of the two stands that stop there.
void hit_corners(vec3 ro, vec3 rd, inout Hit h) {
    for (int c = 0; c < 4; ++c) {
        int ix = c & 1;            // side 0 or 1
        int iy = 2 + (c >> 1);     // side 2 or 3
        vec2 nx = side_normal(ix);
        vec2 ny = side_normal(iy);
        if (u_open_corner[c] != 0) {
            for (int e = 0; e < 2; ++e) {
                // e = 0: end of side iy on the plane d_ix = 0; e = 1: end of side ix on d_iy = 0
                int cut = e == 0 ? ix : iy;
                int stand = e == 0 ? iy : ix;
                float rn = dot(rd.xy, side_normal(cut));
                if (abs(rn) < 1e-9) continue;
                float t = -side_d(cut, ro.xy) / rn;
                if (t <= 1e-3 || t >= h.t) continue;
                vec3 p = ro + t * rd;
                float d = side_d(stand, p.xy);
                if (d < 0.0 || d > u_side_c[stand].y || p.z < 0.0 || p.z > side_surface(stand, d)) continue;
                h.t = t;
                h.mat = MAT_BACK;
                h.side = stand;
                h.n = vec3(side_normal(cut) * (rn > 0.0 ? -1.0 : 1.0), 0.0);
            }
            continue;
        }
        // f(t) = d_x - d_y along the ray
        float f0 = side_d(ix, ro.xy) - side_d(iy, ro.xy);
        float f1 = dot(rd.xy, nx) - dot(rd.xy, ny);
        if (abs(f1) < 1e-9) continue;
        float t = -f0 / f1;
        if (t <= 1e-3 || t >= h.t) continue;
        vec3 p = ro + t * rd;
        float d = side_d(ix, p.xy);
        if (d < 0.0) continue;
        float top = max(side_surface(ix, d), side_surface(iy, d));
        if (p.z < 0.0 || p.z > top) continue;
        h.t = t;
        h.mat = MAT_BACK;
        h.side = f1 > 0.0 ? iy : ix;
        vec2 mn = normalize(nx - ny) * (f1 > 0.0 ? -1.0 : 1.0);
        h.n = vec3(mn, 0.0);
    }
}

// Advertising boards: vertical panels facing the pitch at dot(p, n) = u_side_d[i].z.
void hit_boards(vec3 ro, vec3 rd, inout Hit h) {
    for (int i = 0; i < 4; ++i) {
        vec2 n = side_normal(i);
        float rn = dot(rd.xy, n);
        if (rn <= 1e-6) continue;
        float t = (u_side_d[i].z - dot(ro.xy, n)) / rn;
        if (t <= 1e-3 || t >= h.t) continue;
        vec3 p = ro + t * rd;
        float lat = abs(dot(p.xy, vec2(-n.y, n.x)));
        if (p.z < 0.0 || p.z > u_board_height || lat > u_side_d[i].w) continue;
        if (dot(ro.xy, n) > u_side_d[i].z) continue;  // seen from behind: skip
        h.t = t;
        h.mat = MAT_BOARD;
        h.side = i;
        h.n = vec3(-n, 0.0);
    }
}

// Floodlight masts at the four corners: vertical cylinders with a lamp panel on top.
void hit_masts(vec3 ro, vec3 rd, inout Hit h) {
    if (u_masts == 0) return;
    for (int c = 0; c < 4; ++c) {
        vec2 base = u_mast_pos * vec2((c & 1) == 0 ? 1.0 : -1.0, (c & 2) == 0 ? 1.0 : -1.0);
        // cylinder radius 0.9
        vec2 oc = ro.xy - base;
        float A = dot(rd.xy, rd.xy);
        float B = dot(oc, rd.xy);
        float C = dot(oc, oc) - 0.81;
        float disc = B * B - A * C;
        if (disc > 0.0 && A > 1e-9) {
            float t = (-B - sqrt(disc)) / A;
            if (t > 1e-3 && t < h.t) {
                float z = ro.z + t * rd.z;
                if (z > 0.0 && z < u_mast_height) {
                    h.t = t; h.mat = MAT_MAST; h.side = c;
                    h.n = vec3(normalize(oc + t * rd.xy), 0.0);
                }
            }
        }
        // lamp panel: plane through the mast top facing the pitch centre, 12 x 7 m
        vec3 top = vec3(base, u_mast_height);
        vec3 pn = normalize(vec3(-base, -0.6 * length(base)));
        vec3 pu = normalize(vec3(-pn.y, pn.x, 0.0));
        vec3 pv = cross(pn, pu);
        float den = dot(rd, pn);
        if (abs(den) < 1e-6) continue;
        float t = dot(top - ro, pn) / den;
        if (t <= 1e-3 || t >= h.t) continue;
        vec3 q = ro + t * rd - top;
        float a = dot(q, pu);
        float b = dot(q, pv);
        if (abs(a) < 6.0 && abs(b) < 3.5) {
            h.t = t; h.mat = MAT_LAMP; h.side = c;
            h.n = den < 0.0 ? pn : -pn;
        }
    }
}

// Advertising panel pattern: background, logo blocks and glyphs; q lateral metres, z height 0..1.
vec3 ad_pattern(float q, float z01, float fp, int salt, float panel_len) {
    int panel = int(floor(q / panel_len));
    uint s = uint(salt) * 7919u + u_board_seed;
    float h1 = hash1(panel, s);
    float h2 = hash1(panel, s + 1u);
    float h3 = hash1(panel, s + 2u);
    vec3 bg = 0.6 * pow(vec3(0.5) + 0.5 * cos(6.2832 * (h1 + vec3(0.0, 0.33, 0.67))), vec3(2.2));
    if (h3 < 0.25) bg = vec3(0.02);
    if (h3 > 0.85) bg = vec3(0.8);
    vec3 fg = h2 < 0.5 ? vec3(0.9) : 0.7 * pow(vec3(0.5) + 0.5 * cos(6.2832 * (h2 + vec3(0.5, 0.83, 0.17))), vec3(2.2));
    if (length(fg - bg) < 0.3) fg = vec3(1.0) - bg;
    float local = q / panel_len - float(panel);
    float text_lo = 0.25, text_hi = 0.75;
    float glyph_w = 0.45;
    float cov_mean = 0.35 * step(0.12, local) * step(local, 0.88);
    float detail = 1.0 - smoothstep(0.05, 0.2, fp);
    float cov = cov_mean;
    if (detail > 0.0) {
        float gx = q / glyph_w;
        int gi = int(floor(gx));
        vec2 cell = vec2(fract(gx) * 4.0, (z01 - text_lo) / (text_hi - text_lo) * 5.0);
        float on = 0.0;
        if (cell.y >= 0.0 && cell.y < 5.0 && cell.x < 3.0 && local > 0.12 && local < 0.88) {
            uint bits = hash_u(uint(gi) * 31u + s);
            int bit = int(cell.x) + 3 * int(cell.y);
            on = float((bits >> uint(bit)) & 1u);
        }
        cov = mix(cov_mean, on, detail);
    }
    float in_band = step(text_lo, z01) * step(z01, text_hi);
    return mix(bg, fg, cov * mix(1.0, in_band, detail));
}

// Seats and crowd on a tier; d (profile metres), q (lateral metres), fp footprint (metres).
vec3 seats_albedo(float d, float q, float fp, int side, int tier) {
    uint salt = uint(side * 2 + tier) * 101u + 17u;
    float detail = 1.0 - smoothstep(0.15, 0.5, fp);  // single seats and spectators
    float row_len = 0.8;
    float seat_w = 0.52;
    // sections between aisles
    float sec_len = u_aisle;
    int section = int(floor(q / sec_len));
    vec3 seat = u_seat1;
    if (u_seat_pattern == 1 && (section & 1) == 1) seat = u_seat2;
    if (u_seat_pattern == 2 && (int(floor(d / 6.0)) & 1) == 1) seat = u_seat2;
    vec3 tread = u_concrete * 0.55;
    // mean of the seat part of a row: empty seats and spectators
    vec3 crowd_mean = (0.45 * u_crowd1 + 0.15 * u_crowd2 + vec3(0.05)) * 0.95 + vec3(0.02);
    vec3 col = mix(seat * 0.9, crowd_mean, u_crowd_density);
    float rf = d / row_len;
    float fr = fract(rf);
    if (detail > 0.0) {
        ivec2 cell = ivec2(int(floor(q / seat_w)), int(floor(rf)));
        float fq = fract(q / seat_w);
        vec3 c = seat * (fq > 0.08 && fq < 0.92 ? 1.0 : 0.6);
        float occ = hash2(cell, salt);
        if (occ < u_crowd_density) {
            float pick = hash2(cell, salt + 1u);
            vec3 rnd = pow(vec3(hash2(cell, salt + 2u), hash2(cell, salt + 3u), hash2(cell, salt + 4u)), vec3(2.2));
            vec3 shirt = pick < 0.45 ? u_crowd1 : pick < 0.6 ? u_crowd2 : pick < 0.85 ? vec3(0.02 + 0.05 * rnd.x) : mix(vec3(dot(rnd, vec3(0.33))), rnd, 0.5) * 0.6;
            shirt *= 0.7 + 0.5 * hash2(cell, salt + 6u);
            c = fr > 0.82 ? vec3(0.45, 0.3, 0.22) * (0.5 + hash2(cell, salt + 5u)) : shirt;
            if (fq < 0.12 || fq > 0.88) c = tread;
        }
        col = mix(col, c, detail);
    }
    // rows: the tread (35 % of each 0.8 m row, straight lines along the stand), filtered by the
    // footprint and faded to its mean share once a row is thinner than a pixel
    float tr = band_coverage((fract(rf - 0.175 + 0.5) - 0.5) * row_len, 0.35 * row_len, max(fp, 1e-3));
    tr = mix(tr, 0.35, smoothstep(0.4 * row_len, row_len, fp));
    col = mix(col, tread, tr);
    // aisles (stairs) between sections, filtered by the footprint
    float ap = fract(q / sec_len + 0.5) - 0.5;
    float aisle = band_coverage(ap * sec_len, 1.2, max(fp, 1e-3));
    col = mix(col, u_concrete * 0.7, aisle);
    return col;
}

// Surface albedo of a stand / roof / board hit.
vec3 structure_albedo(Hit h, vec3 p, float fp, out vec3 emit) {
    emit = vec3(0.0);
    int i = h.side;
    vec2 n = side_normal(i);
    float d = dot(p.xy, n) - u_side_a[i].x;
    float q = dot(p.xy, vec2(-n.y, n.x));
    if (h.mat == MAT_SEAT1) return seats_albedo(d, q, fp, i, 0);
    if (h.mat == MAT_SEAT2) return seats_albedo(d, q, fp, i, 1);
    if (h.mat == MAT_FRONT) {
        float z01 = p.z / max(u_side_a[i].y, 0.1);
        if (u_led_boards != 0 && z01 > 0.5) {
            vec3 c = ad_pattern(q, (z01 - 0.5) * 2.0, fp, 40 + i, 14.0);
            if (u_lighting == 2) emit = c * 1.2;
            return c;
        }
        return u_concrete;
    }
    if (h.mat == MAT_BALCONY) {
        float z01 = (p.z - u_side_b[i].z) / max(u_side_b[i].w, 0.1);
        vec3 c = ad_pattern(q, z01, fp, 50 + i, 22.0);
        if (u_led_boards != 0) { emit = c * (u_lighting == 2 ? 1.3 : 0.5); }
        return c;
    }
    if (h.mat == MAT_BOARD) {
        vec3 c = ad_pattern(q, p.z / u_board_height, fp, i, 8.0);
        if (u_led_boards != 0) emit = c * (u_lighting == 2 ? 1.4 : 0.6);
        return c * (u_led_boards != 0 ? 0.5 : 1.0);
    }
    if (h.mat == MAT_BACK || h.mat == MAT_SOFFIT) return u_concrete * 0.45;
    if (h.mat == MAT_ROOF_UNDER) {
        float truss = band_coverage((fract(q / 9.0 + 0.5) - 0.5) * 9.0, 0.8, max(fp, 1e-3));
        return u_roof * (0.8 - 0.5 * truss);
    }
    if (h.mat == MAT_FASCIA) {
        if (u_masts == 0 && u_lighting == 2) {
            float zz = (p.z - u_side_c[i].w) / max(u_side_d[i].y, 0.1);
            float lamp = band_coverage((fract(q / 4.0 + 0.5) - 0.5) * 4.0, 2.0, max(fp, 1e-3)) * step(zz, 0.5);
            emit = vec3(8.0, 7.8, 7.0) * lamp;
        }
        return u_fascia;
    }
    if (h.mat == MAT_ROOF_TOP) return u_roof * 0.9;
    if (h.mat == MAT_MAST) return vec3(0.45);
    if (h.mat == MAT_LAMP) {
        if (u_lighting == 2) emit = vec3(14.0, 13.5, 12.0);
        return vec3(0.7);
    }
    return u_concrete * 0.5;
}
