// glradial crop.vert: one quad per crop tile of a vertical atlas, drawn instanced (4 vertices as a
// triangle strip per instance). Tile t covers rows [t * h, (t + 1) * h) of a w-wide target, where
// (w, h) = u_tile_size and t = in_s2.w (a per-instance attribute, so that one batch can be drawn
// by two programs, each with its own crops). The crop's parameters are per-instance attributes
// passed to crop.frag as flat varyings:
//   in_r0 = (R00, R01, R02, f), in_r1 = (R10, R11, R12, k1), in_r2 = (R20, R21, R22, k2),
// R = R_pan * R_tilt * R_roll (camera ray -> world ray), f = focal length in lens units;
//   in_s0, in_s1, in_s2.xyz = the 11 Chebyshev coefficients c0..c10 of the lens's inverse series
// (glradial/lens/inverse_series.py; read only with CROP_INVERSE_SERIES).

uniform ivec2 u_tile_size;  // (w, h) of one tile in pixels
uniform int u_tiles;        // tiles in the target (its height is u_tiles * h)

in vec4 in_r0;
in vec4 in_r1;
in vec4 in_r2;
in vec4 in_s0;
in vec4 in_s1;
in vec4 in_s2;

flat out vec4 v_r0;
flat out vec4 v_r1;
flat out vec4 v_r2;
flat out vec4 v_s0;
flat out vec4 v_s1;
flat out vec4 v_s2;
flat out float v_top;  // first row of this tile in the target

void main() {
    vec2 corner = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    float top = in_s2.w * float(u_tile_size.y);
    float rows = float(u_tiles * u_tile_size.y);
    float y = (top + corner.y * float(u_tile_size.y)) / rows;
    gl_Position = vec4(corner.x * 2.0 - 1.0, y * 2.0 - 1.0, 0.0, 1.0);
    v_r0 = in_r0;
    v_r1 = in_r1;
    v_r2 = in_r2;
    v_s0 = in_s0;
    v_s1 = in_s1;
    v_s2 = in_s2;
    v_top = top;
}
