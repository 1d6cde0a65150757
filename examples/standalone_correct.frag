// glradial standalone_correct.frag: the smallest lens correction, for use outside Python.
//
// Build the fragment shader from three pieces, concatenated in this order:
//   1. a version line:  #version 330 core   (or any GLSL >= 1.30 / GLSL ES 3.00 with a precision line)
//   2. shaders/common.glsl                   (the lens functions; it needs nothing defined)
//   3. this file
// and pair it with any vertex shader that covers the output (e.g. shaders/fullscreen.vert, drawn as
// 3 vertices with no vertex buffer). Set u_image's sampler to LINEAR filtering, clamp to edge.
//
// Conventions (DESIGN.md): u_image row 0 is the top of the picture and is drawn to framebuffer
// row 0 (gl_FragCoord.y = 0.5); flip v yourself if your texture is stored bottom-up. The lens
// (k1, k2) is width-normalised: image width = 1, origin at the image centre.

uniform sampler2D u_image;  // the distorted frame
uniform vec2 u_k;           // (k1, k2)
uniform vec2 u_size;        // output size in pixels (width, height); the input has the same size

out vec4 frag_color;

void main() {
    vec2 uv = gl_FragCoord.xy / u_size;                  // this output pixel, texture units
    float aspect_hw = u_size.y / u_size.x;
    vec2 p_u = lens_from_uv(uv, aspect_hw);              // undistorted lens point shown here
    vec2 src = uv_from_lens(distort_point(p_u, u_k), aspect_hw);  // where the lens put it
    bool inside = all(greaterThanEqual(src, vec2(0.0))) && all(lessThanEqual(src, vec2(1.0)));
    frag_color = inside ? texture(u_image, src) : vec4(0.0);
}
