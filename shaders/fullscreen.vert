// glradial fullscreen.vert: one triangle that covers the viewport, no vertex buffer needed.
// Draw with 3 vertices and an empty vertex array. Fragment programs read gl_FragCoord.xy (pixel
// centres at +0.5) and turn it into texture coordinates; v_uv is the same thing, for convenience.
out vec2 v_uv;

void main() {
    vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    v_uv = corner;
    gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
