// glradial distort.frag: applies a lens to an undistorted image (crop synthesis, graphics overlays).
// Each output pixel is the distorted lens point p_d = q (its own lens coordinates); it samples the
// undistorted input at inverse(p_d) / u_scale, the exact inverse of correct.frag with the same scale.
//
// Defines: LENS_INVERSE_EXACT 1 (default): bounded Newton (undistort_point_exact); pixels that no
// undistorted point reaches (beyond the lens's largest distorted radius) get u_fill.
//          LENS_INVERSE_EXACT 0: the paper's Drap-Lefevre polynomial (undistort_point_drap).
// Uniforms: as correct.frag (u_k, u_centre, u_pixel_aspect, u_scale, u_out_rect, u_aspect_out,
// u_aspect_in, u_source, u_fill).

#include "common.glsl"
#include "sampling.glsl"

#ifndef LENS_INVERSE_EXACT
#define LENS_INVERSE_EXACT 1
#endif

uniform vec2 u_k;
uniform vec2 u_centre;
uniform float u_pixel_aspect;
uniform float u_scale;
uniform vec4 u_out_rect;
uniform float u_aspect_out;
uniform float u_aspect_in;

out vec4 frag_color;

void main() {
    vec2 uv = (gl_FragCoord.xy - u_out_rect.xy) / u_out_rect.zw;
    vec2 p_d = lens_from_uv(uv, u_aspect_out, u_centre, u_pixel_aspect);
#if LENS_INVERSE_EXACT
    vec3 inverse = undistort_point_exact(p_d, u_k);
    if (inverse.z < 0.5) {
        frag_color = u_fill;
        return;
    }
    vec2 p_u = inverse.xy;
#else
    vec2 p_u = undistort_point_drap(p_d, u_k);
#endif
    frag_color = sample_source(uv_from_lens(p_u / u_scale, u_aspect_in, u_centre, u_pixel_aspect));
}
