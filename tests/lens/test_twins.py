"""Every GLSL lens function in shaders/common.glsl against its NumPy twin in glradial.lens.lensfuncs.

Each GLSL function is evaluated per texel of a float32 texture of inputs and read back as float32.
Tolerance: the GLSL side runs in float32 (relative round-off ~6e-8 per operation, a few dozen
operations), so 2e-6 lens units absolute (0.004 px of a 1920-wide frame) bounds it with margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from glradial.gl.egl import release_objects
from glradial.gl.shaderlib import preprocess
from glradial.lens import lensfuncs

PROBE_MAIN = """
uniform sampler2D u_input;
uniform vec2 u_k;
uniform float u_aspect_hw;
uniform vec2 u_centre;
uniform float u_pixel_aspect;
out vec4 result;
void main() {
    vec4 x = texelFetch(u_input, ivec2(gl_FragCoord.xy), 0);
    vec2 p = x.xy;
#if PROBE == 0
    result = vec4(distort_point(p, u_k), radial_factor(dot(p, p), u_k), radial_slope(length(p), u_k));
#elif PROBE == 1
    result = vec4(undistort_point_drap(p, u_k), fold_radius(u_k), 0.0);
#elif PROBE == 2
    result = vec4(undistort_point_exact(p, u_k), 0.0);
#elif PROBE == 3
    result = vec4(lens_from_uv(p, u_aspect_hw), uv_from_lens(p, u_aspect_hw));
#elif PROBE == 5
    result = vec4(lens_from_uv(p, u_aspect_hw, u_centre, u_pixel_aspect),
                  uv_from_lens(p, u_aspect_hw, u_centre, u_pixel_aspect));
#else
    result = drap_coefficients(u_k);
#endif
}
"""

LENSES = [(-0.7, 0.805 * 0.49 - 0.7 * 0.019), (-0.3, 0.06), (0.0, 0.0), (0.3, 0.08), (-0.2, -0.05)]


def run_probe(
    ctx,
    probe: int,
    points: np.ndarray,
    k: tuple[float, float],
    aspect_hw: float = 9 / 16,
    centre: tuple[float, float] = (0.0, 0.0),
    pixel_aspect: float = 1.0,
):
    source = preprocess("common.glsl", {"PROBE": probe}).text + PROBE_MAIN
    vertex = preprocess("fullscreen.vert").text
    program = ctx.program(vertex_shader=vertex, fragment_shader=source)
    n = points.shape[0]
    data = np.zeros((1, n, 4), np.float32)
    data[0, :, :2] = points
    texture = ctx.texture((n, 1), 4, data.tobytes(), dtype="f4")
    texture.filter = (ctx.NEAREST, ctx.NEAREST)
    target = ctx.texture((n, 1), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    vao = ctx.vertex_array(program, [])
    try:
        texture.use(0)
        if "u_input" in program:
            program["u_input"] = 0
        if "u_k" in program:
            program["u_k"] = k
        if "u_aspect_hw" in program:
            program["u_aspect_hw"] = aspect_hw
        if "u_centre" in program:
            program["u_centre"] = centre
            program["u_pixel_aspect"] = pixel_aspect
        fbo.use()
        fbo.viewport = (0, 0, n, 1)
        vao.render(vertices=3)
        return np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(n, 4).astype(np.float64)
    finally:
        release_objects(ctx, vao, fbo, target, texture, program)


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(0)
    return rng.uniform(-0.5, 0.5, size=(257, 2)) * np.array([1.0, 9 / 16])


@pytest.mark.parametrize("k", LENSES)
def test_forward_twins(ctx, points, k):
    out = run_probe(ctx, 0, points, k)
    np.testing.assert_allclose(out[:, :2], lensfuncs.distort_point(points, *k), atol=2e-6)
    r2 = np.sum(points**2, axis=1)
    np.testing.assert_allclose(out[:, 2], lensfuncs.radial_factor(r2, *k), atol=2e-6)
    np.testing.assert_allclose(out[:, 3], lensfuncs.radial_slope(np.sqrt(r2), *k), atol=2e-6)


@pytest.mark.parametrize("k", LENSES)
def test_inverse_twins(ctx, points, k):
    drap = run_probe(ctx, 1, points, k)
    np.testing.assert_allclose(drap[:, :2], lensfuncs.undistort_point_drap(points, *k), atol=2e-6)
    fold = lensfuncs.fold_radius(*k)
    np.testing.assert_allclose(drap[:, 2], np.float32(fold), rtol=1e-5)
    exact = run_probe(ctx, 2, points, k)
    p_u, valid = lensfuncs.undistort_point_exact(points, *k)
    np.testing.assert_array_equal(exact[:, 2] > 0.5, valid)
    np.testing.assert_allclose(exact[valid, :2], p_u[valid], atol=2e-6)


def test_coordinate_and_coefficient_twins(ctx, points):
    uv = points + 0.5
    out = run_probe(ctx, 3, uv, (0.0, 0.0), aspect_hw=9 / 16)
    np.testing.assert_allclose(out[:, :2], lensfuncs.lens_from_uv(uv, 9 / 16), atol=1e-6)
    np.testing.assert_allclose(out[:, 2:], lensfuncs.uv_from_lens(uv, 9 / 16), atol=1e-6)
    for k in LENSES:
        coeffs = run_probe(ctx, 4, points[:1], k)[0]
        np.testing.assert_allclose(coeffs, lensfuncs.drap_coefficients(*k), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("centre, pixel_aspect", [((0.0, 0.0), 1.0), ((0.104, -0.0625), 1.0), ((-0.03, 0.02), 0.9955)])
def test_principal_point_and_pixel_aspect_twins(ctx, points, centre, pixel_aspect):
    """The four-argument lens_from_uv / uv_from_lens (principal point, pixel aspect) in both twins;
    the centred defaults give the two-argument functions, and the pair are inverses."""
    uv = points + 0.5
    out = run_probe(ctx, 5, uv, (0.0, 0.0), aspect_hw=9 / 16, centre=centre, pixel_aspect=pixel_aspect)
    lens_points = lensfuncs.lens_from_uv(uv, 9 / 16, centre, pixel_aspect)
    np.testing.assert_allclose(out[:, :2], lens_points, atol=1e-6)
    np.testing.assert_allclose(out[:, 2:], lensfuncs.uv_from_lens(uv, 9 / 16, centre, pixel_aspect), atol=1e-6)
    np.testing.assert_allclose(lensfuncs.uv_from_lens(lens_points, 9 / 16, centre, pixel_aspect), uv, atol=1e-15)
    # known answer: the principal point (pixel offset centre * W from the image centre) is lens (0, 0)
    pp_uv = np.array([0.5 + centre[0], 0.5 + centre[1] * 16 / 9])
    np.testing.assert_allclose(lensfuncs.lens_from_uv(pp_uv, 9 / 16, centre, pixel_aspect), [0.0, 0.0], atol=1e-15)
    if centre == (0.0, 0.0) and pixel_aspect == 1.0:
        np.testing.assert_array_equal(lens_points, lensfuncs.lens_from_uv(uv, 9 / 16))


def test_exact_inverse_reports_unreachable_radii(ctx):
    """A strong barrel lens with small k2 folds over; radii beyond its largest distorted radius have
    no undistorted point, in both twins."""
    k = (-0.9, 0.05)
    r_fold = lensfuncs.fold_radius(*k)
    r_max = r_fold * lensfuncs.radial_factor(r_fold**2, *k)
    radii = np.array([0.5 * r_max, 0.99 * r_max, 1.02 * r_max, 1.5 * r_max])
    pts = np.stack([radii, np.zeros_like(radii)], axis=1)
    _, valid = lensfuncs.undistort_point_exact(pts, *k)
    assert valid.tolist() == [True, True, False, False]
    out = run_probe(ctx, 2, pts, k)
    assert (out[:, 2] > 0.5).tolist() == [True, True, False, False]
