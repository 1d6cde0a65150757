// glradial stadium.frag: procedural football-stadium panorama, ray-cast per panorama pixel.
//
// Output: equirectangular RGB, longitude 0 at the centre column increasing to the right, latitude
// +90 deg at the top row. Pixel (x, y) of the full panorama (y = u_row0 + gl_FragCoord.y - 0.5 for
// the strip being drawn) has lon = ((x + 0.5) / W - 0.5) * 2 pi, lat = (0.5 - (y + 0.5) / H) * pi.
// Scene in metres: pitch centre at the origin, x along the length, y across, z up (see
// glradial/synthesis/stadium_style.py). The camera at u_cam looks horizontally along azimuth u_yaw at lon 0;
// a direction is cos(lat) (cos(lon) f + sin(lon) r) + sin(lat) up with f = (cos yaw, sin yaw, 0)
// and r = (sin yaw, -cos yaw, 0) (to the right of f).
// Anti-aliasing: markings, stripes, boards, seats, posts and textures are box-filtered by each
// sample's footprint; geometric edges by u_ss x u_ss (rotated grid for 2) samples per pixel, in
// two passes: STADIUM_PASS 1 renders one sample per pixel plus a geometry id (linear colour in an
// RGBA16F strip), STADIUM_PASS 2 supersamples only pixels whose neighbours' ids differ.

#include "common.glsl"

#ifndef STADIUM_PASS
#define STADIUM_PASS 2
#endif

uniform vec2 u_size;
uniform float u_row0;
uniform int u_ss;
uniform vec3 u_cam;
uniform float u_yaw;
uniform int u_lighting;
uniform vec3 u_sun_dir;
uniform vec3 u_sun_color;
uniform vec3 u_ambient;
uniform float u_cloudiness;
uniform float u_exposure;
uniform float u_haze;
uniform vec3 u_fog;
uniform float u_rain;

uniform int u_stripe_pattern;
uniform float u_stripe_width;
uniform float u_stripe_angle;
uniform float u_stripe_contrast;
uniform float u_stripe_offset;
uniform vec3 u_grass;
uniform vec3 u_grass2;
uniform float u_grass_noise;
uniform float u_wear;
uniform vec3 u_surround;
uniform int u_track;
uniform float u_line_width;
uniform float u_line_brightness;

uniform vec4 u_side_a[4];   // inner distance, front height, slope1, depth1
uniform vec4 u_side_b[4];   // upper?, upper front d, upper base z, balcony height
uniform vec4 u_side_c[4];   // slope2, back d, roof?, roof height
uniform vec4 u_side_d[4];   // roof front d, fascia height, board distance, board half length
uniform vec4 u_seg[40];     // profile segments (d0, z0, d1, z1), NSEG per side
uniform float u_segmat[40]; // their materials
uniform int u_nseg[4];      // segments in use per side
uniform int u_open_corner[4]; // 1 where the two stands stop short of the corner
uniform int u_pillars[4];   // 1 where the roof stands on columns at the front of the stand
uniform float u_pillar_spacing;
uniform vec2 u_shadow_corners[24]; // 6 corners (d, z) of each side's upper envelope

uniform float u_board_height;
uniform uint u_board_seed;
uniform int u_led_boards;
uniform int u_masts;
uniform vec2 u_mast_pos;
uniform float u_mast_height;
uniform float u_aisle;
uniform vec3 u_seat1;
uniform vec3 u_seat2;
uniform int u_seat_pattern;
uniform vec3 u_concrete;
uniform vec3 u_crowd1;
uniform vec3 u_crowd2;
uniform float u_crowd_density;
uniform vec3 u_roof;
uniform vec3 u_fascia;
uniform vec4 u_players[24];  // x, y, team, height
uniform int u_nplayers;
uniform vec3 u_team1;
uniform vec3 u_team2;

#include "stadium_noise.glsl"
#include "stadium_sky.glsl"
#include "stadium_pitch.glsl"
#include "stadium_stands.glsl"

out vec4 frag_color;

// Closest approach of the ray ro + t rd to the line lo + s lu (|lu| = 1): (t, s, distance).
vec3 ray_line(vec3 ro, vec3 rd, vec3 lo, vec3 lu) {
    vec3 w = ro - lo;
    float b = dot(rd, lu);
    float d = dot(rd, w);
    float e = dot(lu, w);
    float den = 1.0 - b * b;
    if (den < 1e-8) return vec3(-1.0, 0.0, 1e9);
    float t = (b * e - d) / den;
    float s = (e - b * d) / den;
    return vec3(t, s, length(w + t * rd - s * lu));
}

// Fraction of direct sunlight reaching p (1 lit, 0 in the stands' shadow), penumbra included.
float sun_visibility(vec3 p) {
    if (u_sun_dir.z <= 0.0) return 0.0;
    float vis = 1.0;
    for (int i = 0; i < 4; ++i) {
        vec2 n = side_normal(i);
        float sn = dot(u_sun_dir.xy, n);
        float dp = dot(p.xy, n) - u_side_a[i].x;
        vec4 c = u_side_c[i];
        vec4 dd = u_side_d[i];
        if (sn <= 1e-4 && (c.z < 0.5 || dp <= dd.x)) continue;
        float slope = u_sun_dir.z / max(abs(sn), 1e-4);
        if (sn > 1e-4) {
            // corners of the stand's upper envelope, each blocks if the sun ray passes below it
            float worst = 1e9;
            float inv_sn = 1.0 / sn;
            for (int k = 0; k < 6; ++k) {
                vec2 corner = u_shadow_corners[i * 6 + k];
                float run = corner.x - dp;
                if (run <= 0.05) continue;
                worst = min(worst, (p.z + slope * run - corner.y) / (0.0093 * run * inv_sn + 0.05));
            }
            vis = min(vis, smoothstep(-0.5, 0.5, worst));
        } else if (c.z > 0.5 && dp > dd.x && sn < -1e-4) {
            // under this side's own roof: lit only if the sun ray leaves below the roof front
            float z = p.z + slope * (dp - dd.x);
            vis = min(vis, smoothstep(0.5, -0.5, (z - c.w) / (0.0093 * (dp - dd.x) + 0.05)));
        }
    }
    return vis;
}

// Sunlight left on ground point g by the players' shadows (1 = none): each player's shadow is the
// segment from its feet away from the sun, 0.4 m wide, box-filtered by the footprint fp (metres).
float player_shadows(vec2 g, float fp) {
    if (u_lighting != 0 || u_nplayers == 0 || u_sun_dir.z <= 0.0) return 1.0;
    vec2 away = -u_sun_dir.xy / u_sun_dir.z;   // shadow offset per metre of height
    float vis = 1.0;
    for (int k = 0; k < u_nplayers; ++k) {
        vec4 pl = u_players[k];
        vec2 tip = pl.xy + away * pl.w;
        if (g.x < pl.x + min(away.x, 0.0) * 2.0 - 0.5) break;  // players are sorted by x ...
        if (g.x > max(pl.x, tip.x) + 0.5) continue;  // ... but a shadow may reach back
        vec2 ab = tip - pl.xy;
        float hh = clamp(dot(g - pl.xy, ab) / max(dot(ab, ab), 1e-6), 0.0, 1.0);
        float dist = length(g - pl.xy - hh * ab);
        vis = min(vis, 1.0 - 0.85 * band_coverage(dist, 0.4, max(fp, 1e-3)));
    }
    return vis;
}

// Light arriving at a point (linear RGB), given its normal and whether it is on the pitch.
vec3 lighting(vec3 p, vec3 n, float open_sky, float shade_vis) {
    if (u_lighting == 2) {
        // floodlights: bright over the pitch, falling off into the stands
        float dx = max(abs(p.x) - 55.0, 0.0);
        float dy = max(abs(p.y) - 37.0, 0.0);
        float fall = exp(-length(vec2(dx, dy)) / 25.0);
        float facing = 0.55 + 0.45 * max(n.z, 0.0);
        return u_sun_color * (0.25 + 0.75 * fall) * facing + u_ambient * open_sky;
    }
    float lit = u_lighting == 0 ? shade_vis * sun_visibility(p) * max(dot(n, u_sun_dir), 0.0) : 0.0;
    return u_sun_color * lit + u_ambient * open_sky * (0.6 + 0.4 * max(n.z, 0.0));
}

vec3 shade(vec3 dir, vec3 dlon, vec3 dlat, float pix, out int id) {
    vec3 ro = u_cam;
    Hit h;
    h.t = 1e7;
    h.mat = MAT_SKY;
    h.side = 0;
    h.n = vec3(0.0, 0.0, 1.0);
    bool ground = false;
    if (dir.z < -1e-6) {
        float tg = -ro.z / dir.z;
        vec3 p = ro + tg * dir;
        float dmax;
        int side = owner_side(p.xy, dmax);
        if (dmax < 0.0) {
            h.t = tg; h.mat = MAT_GROUND; ground = true;
        } else if (dmax > u_side_c[side].y + 1.0 || corner_open(p.xy)) {
            h.t = tg; h.mat = MAT_OUTSIDE;
        }
    }
    // stands: a ray that lands on the field can only have met the camera's own stand or a roof
    // overhanging the field's edge on its way down
    vec2 land = ro.xy + dir.xy * min(h.t, 1e6);
    for (int i = 0; i < 4; ++i) {
        vec2 n = side_normal(i);
        bool own = side_d(i, ro.xy) > -2.0;
        bool ahead = dot(dir.xy, n) > 0.0 && (!ground || side_d(i, land) > min(u_side_d[i].x, 0.0) - 1.0);
        if (own || ahead) hit_side(i, ro, dir, h);
    }
    hit_corners(ro, dir, h);
    hit_boards(ro, dir, h);
    hit_masts(ro, dir, h);

    vec3 col;
    vec3 p = ro + h.t * dir;
    if (h.mat == MAT_SKY) {
        col = sky_color(dir, pix);
    } else {
        float cosi = max(abs(dot(dir, h.n)), 0.12);
        float fp = h.t * pix / cosi;
        vec3 albedo;
        vec3 emit = vec3(0.0);
        float open_sky = 1.0;
        if (h.mat == MAT_GROUND) {
            vec2 jx = (h.t * (dlon - dir * (dlon.z / dir.z))).xy;
            vec2 jy = (h.t * (dlat - dir * (dlat.z / dir.z))).xy;
            float fpg = max(length(jx), length(jy));
            vec2 g = p.xy;
            vec2 v = normalize(dir.xy + vec2(1e-6, 0.0));
            albedo = ground_albedo(g, jx, jy, v, fpg);
            float dmax;
            owner_side(g, dmax);
            open_sky = 1.0 - 0.35 * exp(dmax / 12.0);
        } else if (h.mat == MAT_OUTSIDE) {
            albedo = u_concrete * 0.6;
        } else {
            albedo = structure_albedo(h, p, fp, emit);
            if (h.mat == MAT_SOFFIT || h.mat == MAT_BACK || h.mat == MAT_ROOF_UNDER) open_sky = 0.35;
            else if (h.mat == MAT_SEAT1 || h.mat == MAT_SEAT2) {
                float dd = dot(p.xy, side_normal(h.side)) - u_side_a[h.side].x;
                if (u_side_c[h.side].z > 0.5 && dd > u_side_d[h.side].x) open_sky = 0.45;
                if (u_side_b[h.side].x > 0.5 && h.mat == MAT_SEAT1 && dd > u_side_b[h.side].y) open_sky = 0.25;
            }
        }
        col = albedo * lighting(p, h.n, open_sky, ground ? player_shadows(p.xy, fp) : 1.0) + emit;
    }

    // roof columns: vertical cylinders (radius 0.25 m) standing on the seats 1 m behind the roof
    // front, every u_pillar_spacing metres; the three nearest to where the ray crosses their row
    for (int i = 0; i < 4; ++i) {
        if (u_pillars[i] == 0) continue;
        vec2 n = side_normal(i);
        vec2 lat_axis = vec2(-n.y, n.x);
        float dcol = max(u_side_d[i].x + 1.0, 0.5);
        float rn = dot(dir.xy, n);
        if (abs(rn) < 1e-6) continue;
        float tc = (u_side_a[i].x + dcol - dot(ro.xy, n)) / rn;
        if (tc <= 0.0) continue;
        float qc = dot(ro.xy + tc * dir.xy, lat_axis);
        float half_len = i < 2 ? u_side_a[2].x : u_side_a[0].x;
        float base = side_surface(i, dcol);
        float top = u_side_c[i].w;
        for (int j = -1; j <= 1; ++j) {
            float qk = (round(qc / u_pillar_spacing) + float(j)) * u_pillar_spacing;
            if (abs(qk) > half_len - 2.0) continue;
            vec3 axis = vec3(n * (u_side_a[i].x + dcol) + lat_axis * qk, 0.0);
            vec3 c = ray_line(ro, dir, axis, vec3(0.0, 0.0, 1.0));
            if (c.x <= 0.0 || c.x >= h.t || c.y < base || c.y > top) continue;
            float cov = band_coverage(c.z, 0.5, max(c.x * pix, 1e-4));
            if (cov <= 0.0) continue;
            vec3 cn = vec3(normalize((ro + c.x * dir - axis).xy + 1e-6), 0.0);
            col = mix(col, u_fascia * 0.8 * lighting(vec3(axis.xy, c.y), cn, 0.5, 1.0), cov);
        }
    }

    // goals: posts and crossbars (thin cylinders, coverage from the footprint), nets
    for (int g = 0; g < 2; ++g) {
        float gx = g == 0 ? 52.5 : -52.5;
        float sx = g == 0 ? 1.0 : -1.0;
        vec3 gc = vec3(gx + sx, 0.0, 1.2) - ro;     // bounding sphere of goal and net, radius 5 m
        float tc = dot(gc, dir);
        if (dot(gc, gc) - tc * tc > 25.0 || tc < -5.0) continue;
        vec3 white = vec3(0.9) * lighting(vec3(gx, 0.0, 1.2), vec3(-sx, 0.0, 0.0), 1.0, 1.0);
        // net: back, top and sides of a box 2 m deep; light alpha accumulated per crossing
        float net = 0.0;
        for (int k = 0; k < 4; ++k) {
            vec3 pn = k == 0 ? vec3(1.0, 0.0, 0.0) : k == 1 ? vec3(0.0, 0.0, 1.0) : vec3(0.0, 1.0, 0.0);
            float off = k == 0 ? gx + sx * 2.0 : k == 1 ? 2.44 : (k == 2 ? 3.66 : -3.66);
            float den = dot(dir, pn);
            if (abs(den) < 1e-6) continue;
            float t = (off - dot(ro, pn)) / den;
            if (t <= 0.0 || t >= h.t) continue;
            vec3 q = ro + t * dir;
            float depth = (q.x - gx) * sx;
            if (depth < 0.0 || depth > 2.0 || abs(q.y) > 3.66 || q.z < 0.0 || q.z > 2.44) continue;
            float fpn = t * pix / max(abs(den), 0.1);
            vec2 uv = k == 0 ? q.yz : k == 1 ? q.xy : q.xz;
            float mesh = 0.12;
            float cx = 1.0 - band_coverage((fract(uv.x / mesh + 0.5) - 0.5) * mesh, 0.012, max(fpn, 1e-4));
            float cy = 1.0 - band_coverage((fract(uv.y / mesh + 0.5) - 0.5) * mesh, 0.012, max(fpn, 1e-4));
            net = 1.0 - (1.0 - net) * (1.0 - 0.9 * (1.0 - cx * cy));
        }
        col = mix(col, white * 0.9, net);
        for (int k = 0; k < 3; ++k) {
            vec3 lo = k < 2 ? vec3(gx + sx * 0.06, k == 0 ? 3.72 : -3.72, 0.0) : vec3(gx + sx * 0.06, 0.0, 2.5);
            vec3 lu = k < 2 ? vec3(0.0, 0.0, 1.0) : vec3(0.0, 1.0, 0.0);
            float len = k < 2 ? 2.56 : 3.78;
            vec3 c = ray_line(ro, dir, lo, lu);
            if (c.x <= 0.0 || c.x >= h.t) continue;
            bool inside = k < 2 ? (c.y >= 0.0 && c.y <= len) : abs(c.y) <= len;
            if (!inside) continue;
            float cov = band_coverage(c.z, 0.12, max(c.x * pix, 1e-4));
            col = mix(col, white, cov);
        }
    }
    // players: vertical cylinders with socks, shorts, shirt and head
    // the part of the ray below head height, as an x range (players are sorted by x)
    vec2 hdir = normalize(dir.xy + vec2(1e-7, 0.0));
    float t_top = dir.z < 0.0 ? max((ro.z - 2.2) / -dir.z, 0.0) : (ro.z < 2.2 ? 0.0 : 1e9);
    float t_end = min(h.t, dir.z > 0.0 ? max((2.2 - ro.z) / dir.z, 0.0) : 1e5);
    float xa = ro.x + dir.x * t_top;
    float xb = ro.x + dir.x * t_end;
    float xlo = min(xa, xb) - 0.5;
    float xhi = max(xa, xb) + 0.5;
    for (int k = 0; k < u_nplayers && t_top < t_end; ++k) {
        vec4 pl = u_players[k];
        if (pl.x < xlo) continue;
        if (pl.x > xhi) break;
        vec2 rel = pl.xy - ro.xy;
        if (abs(rel.x * hdir.y - rel.y * hdir.x) > 0.4 || dot(rel, hdir) < 0.0) continue;
        vec3 c = ray_line(ro, dir, vec3(pl.xy, 0.0), vec3(0.0, 0.0, 1.0));
        if (c.x <= 0.0 || c.x >= h.t || c.y < 0.0 || c.y > pl.w) continue;
        float z = c.y / pl.w;
        float r = z > 0.86 ? 0.11 : z > 0.5 ? 0.22 : 0.15;
        float cov = band_coverage(c.z, 2.0 * r, max(c.x * pix, 1e-4));
        if (cov <= 0.0) continue;
        vec3 shirt = pl.z < 0.5 ? u_team1 : u_team2;
        vec3 alb = z > 0.86 ? vec3(0.35, 0.22, 0.15) : z > 0.5 ? shirt : z > 0.3 ? shirt * 0.7 + vec3(0.05) : z > 0.05 ? vec3(0.8) * shirt + vec3(0.1) : vec3(0.05);
        vec3 n = vec3(-hdir, 0.0);
        col = mix(col, alb * lighting(vec3(pl.xy, 1.0), n, 1.0, 1.0), cov);
    }

    // night: glare around the floodlight heads (seen through everything, as in a lens)
    if (u_lighting == 2 && u_masts != 0) {
        for (int c = 0; c < 4; ++c) {
            vec3 head = vec3(u_mast_pos * vec2((c & 1) == 0 ? 1.0 : -1.0, (c & 2) == 0 ? 1.0 : -1.0), u_mast_height);
            vec3 to = head - ro;
            float cosang = dot(dir, to) / length(to);
            float a2 = max(1.0 - cosang, 0.0) * 2.0;   // angle squared (small angles)
            col += vec3(1.0, 0.95, 0.85) * (1.5 * exp(-a2 / 0.0004) + 0.08 * exp(-sqrt(a2) / 0.08));
        }
    }
    id = (h.mat + 1) * 4 + h.side;
    // haze / rain veil along the ray
    if (h.mat != MAT_SKY) {
        float fog = 1.0 - exp(-h.t * u_haze);
        col = mix(col, u_fog, fog);
    }
    // rain: thin near-vertical streaks in direction space (cells 1.1 deg wide, 9 deg tall),
    // box-filtered across by the pixel footprint
    if (u_rain > 0.0) {
        float az = atan(dir.y, dir.x);
        float el = asin(clamp(dir.z, -1.0, 1.0));
        vec2 cellf = vec2(az / 0.02, el / 0.16);
        ivec2 cell = ivec2(floor(cellf));
        float present = step(hash2(cell, 31u), 0.5 * u_rain);
        float x0 = 0.15 + 0.7 * hash2(cell, 32u);
        float y0 = hash2(cell, 33u);
        float along = fract(cellf.y) - y0;
        float len = step(0.0, along) * step(along, 0.45);
        float cov = band_coverage((fract(cellf.x) - x0) * 0.02 * max(cos(el), 0.05), 0.0007, pix);
        col = mix(col, u_fog * 1.6 + vec3(0.04), 0.35 * present * len * cov);
    }
    return col;
}

// Colour of one sample at panorama position xy (pixels, full panorama); id: geometry class.
vec3 sample_at(vec2 xy, float sub, out int id) {
    vec3 f = vec3(cos(u_yaw), sin(u_yaw), 0.0);
    vec3 r = vec3(sin(u_yaw), -cos(u_yaw), 0.0);
    vec3 up = vec3(0.0, 0.0, 1.0);
    float step_lon = 6.283185307 / u_size.x;
    float step_lat = 3.141592654 / u_size.y;
    float lon = ((xy.x + 0.5) / u_size.x - 0.5) * 6.283185307;
    float lat = clamp((0.5 - (xy.y + 0.5) / u_size.y) * 3.141592654, -1.5707963, 1.5707963);
    float cl = cos(lat), sl = sin(lat), co = cos(lon), so = sin(lon);
    vec3 hd = co * f + so * r;
    vec3 dir = cl * hd + sl * up;
    vec3 dlon = cl * (-so * f + co * r) * step_lon * sub;
    vec3 dlat = (-sl * hd + cl * up) * step_lat * sub;
    float pa = max(step_lat, step_lon * cl) * sub;
    return shade(dir, dlon, dlat, pa, id);
}

#if STADIUM_PASS == 1
// Pass 1: one sample per pixel at its centre; alpha carries the geometry id for pass 2.
// The strip has one extra row above and below (row u_row0 - 1 is drawn at gl_FragCoord.y = 0.5).
void main() {
    vec2 xy = vec2(gl_FragCoord.x - 0.5, u_row0 + gl_FragCoord.y - 1.5);
    int id;
    vec3 col = sample_at(xy, 1.0, id);
    frag_color = vec4(col, float(id));
}
#else
// Pass 2: pixels whose 4 neighbours all have the centre's geometry id keep the pass-1 colour;
// the others (geometric edges) are re-rendered with u_ss x u_ss samples (rotated grid for 2).
uniform sampler2D u_first;

vec3 encode(vec3 col) {
    col *= u_exposure;
    col = col / (1.0 + 0.12 * col);              // gentle highlight roll-off
    return pow(clamp(col, 0.0, 1.0), vec3(1.0 / 2.2));
}

void main() {
    ivec2 ip = ivec2(gl_FragCoord.xy - 0.5);
    int w = int(u_size.x);
    ivec2 c = ip + ivec2(0, 1);
    vec4 centre = texelFetch(u_first, c, 0);
    int idc = int(centre.a + 0.5);
    bool edge = false;
    for (int k = 0; k < 4; ++k) {
        ivec2 q = k == 0 ? ivec2((c.x + 1) % w, c.y) : k == 1 ? ivec2((c.x + w - 1) % w, c.y)
                : k == 2 ? ivec2(c.x, c.y + 1) : ivec2(c.x, c.y - 1);
        if (int(texelFetch(u_first, q, 0).a + 0.5) != idc) edge = true;
    }
    vec3 col = centre.rgb;
    int n = max(u_ss, 1);
    if (edge && n > 1) {
        vec2 pix = vec2(gl_FragCoord.x - 0.5, u_row0 + gl_FragCoord.y - 0.5);
        vec3 acc = vec3(0.0);
        int id;
        for (int k = 0; k < n * n; ++k) {
            vec2 o;
            if (n == 2) {
                o = k == 0 ? vec2(-0.125, -0.375) : k == 1 ? vec2(0.375, -0.125) : k == 2 ? vec2(0.125, 0.375) : vec2(-0.375, 0.125);
            } else {
                o = (vec2(float(k % n), float(k / n)) + 0.5) / float(n) - 0.5;
            }
            acc += sample_at(pix + o, 1.0 / float(n), id);
        }
        col = acc / float(n * n);
    }
    frag_color = vec4(encode(col), 1.0);
}
#endif
