// glradial stadium_sky.glsl: sky colour (linear RGB) for a world direction (z up).
// Needs from stadium.frag: u_lighting (0 day, 1 overcast, 2 night), u_sun_dir, u_cloudiness.

vec3 sky_color(vec3 dir, float fp_angle) {
    float h = clamp(dir.z, -0.2, 1.0);
    float up = max(h, 0.0);
    vec3 col;
    float cloud = 0.0;
    if (dir.z > 0.015) {
        // clouds on a plane 1 km up, filtered by the pixel footprint there
        float dist = 1000.0 / dir.z;
        vec2 q = dir.xy * dist;
        float fp = fp_angle * dist / max(dir.z, 0.05);
        float n = 0.5 * filtered_noise(q, 600.0, fp, 11u) + 0.3 * filtered_noise(q, 190.0, fp, 12u)
                + 0.2 * filtered_noise(q, 60.0, fp, 13u);
        cloud = smoothstep(1.0 - 0.9 * u_cloudiness, 1.25 - 0.9 * u_cloudiness, n + 0.25);
        cloud *= smoothstep(0.015, 0.12, dir.z);
    }
    if (u_lighting == 0) {
        vec3 zenith = vec3(0.06, 0.16, 0.48);
        vec3 horizon = vec3(0.55, 0.66, 0.82);
        col = mix(horizon, zenith, pow(up, 0.55));
        float s = max(dot(dir, u_sun_dir), 0.0);
        col += vec3(1.0, 0.85, 0.6) * (0.25 * pow(s, 8.0) + 0.6 * pow(s, 200.0));
        col = mix(col, vec3(0.85, 0.86, 0.88) * (0.7 + 0.3 * up), cloud * 0.85);
        if (s > 0.99996) col = vec3(30.0);
    } else if (u_lighting == 1) {
        col = mix(vec3(0.62, 0.64, 0.67), vec3(0.42, 0.44, 0.48), pow(up, 0.7));
        col *= 0.85 + 0.3 * cloud;
    } else {
        col = mix(vec3(0.03, 0.03, 0.04), vec3(0.004, 0.006, 0.018), pow(up, 0.4));
        col += vec3(0.02, 0.012, 0.004) * cloud;
    }
    // distant skyline (buildings and trees), seen through open corners and over low stands
    float az = atan(dir.y, dir.x);
    float cell = floor(az * 30.0);
    float hb = hash1(int(cell) + 1000, 21u);
    float skyline = 0.004 + (hb > 0.55 ? 0.035 * hb * hb : 0.0) + 0.012 * value_noise(vec2(az * 40.0, 0.5), 22u);
    if (dir.z < skyline) {
        vec3 far = u_lighting == 2 ? vec3(0.006, 0.006, 0.008) : (u_lighting == 1 ? vec3(0.32, 0.34, 0.36) : vec3(0.2, 0.24, 0.3));
        col = mix(far, col, 0.35);
    }
    if (dir.z < 0.0) col *= 0.6;
    return col;
}
