// glradial correct.frag: lens correction (undistortion). No inverse is needed: each output pixel
// shows the undistorted lens point p_u = u_scale * q (q: its own lens coordinates) and samples the
// distorted input at p_d = distort_point(p_u, k).
//
// Uniforms:
//   u_k          vec2   (k1, k2), width-normalised lens units (docs/DESIGN.md)
//   u_centre     vec2   principal point offset from the image centre, width units (0, 0 = centred)
//   u_pixel_aspect float fy / fx (1 = square pixels; must be set, GL's default 0 is invalid)
//   u_scale      float  fit scale (1 = "same": the centre keeps its scale)
//   u_out_rect   vec4   (x0, y0, width, height) of the output rectangle in framebuffer pixels
//   u_aspect_out float  output H / W;  u_aspect_in float  input H / W
//   u_source, u_fill    see sampling.glsl
// Output row y (memory row, top = 0) is gl_FragCoord.y - 0.5 - y0: no flip.

#include "common.glsl"
#include "sampling.glsl"

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
    vec2 p_u = lens_from_uv(uv, u_aspect_out, u_centre, u_pixel_aspect) * u_scale;
    vec2 p_d = distort_point(p_u, u_k);
    frag_color = sample_source(uv_from_lens(p_d, u_aspect_in, u_centre, u_pixel_aspect));
}
