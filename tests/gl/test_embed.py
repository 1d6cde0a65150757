"""Embedding: a caller's moderngl texture corrected/distorted into the caller's framebuffer with no
CPU round trip (Remapper(ctx).render_texture) equals glradial.correct/distort; the standalone GLSL
example (common.glsl + examples/standalone_correct.frag, no Python-injected defines) compiles and
matches too."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

import glradial
from glradial.gl.egl import release_objects
from glradial.gl.shaderlib import shader_path

ROOT = Path(__file__).resolve().parents[2]
K1, K2 = -0.28, 0.06  # a broadcast barrel lens near the Lopez-Antequera manifold


@pytest.fixture(scope="module")
def frame(road):
    """A real photo, 128×72 RGBA uint8 (small: llvmpipe is slow)."""
    small = cv2.resize(road, (128, 72), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(np.dstack([small, np.full(small.shape[:2], 255, np.uint8)]))


@pytest.mark.parametrize("direction", ["undistort", "distort"])
def test_render_texture_into_caller_fbo_equals_library(ctx, frame, direction):
    height, width = frame.shape[:2]
    source = ctx.texture((width, height), 4, frame.tobytes())
    color = ctx.texture((width, height), 4)
    fbo = ctx.framebuffer(color_attachments=[color])
    remapper = glradial.Remapper(ctx)
    try:
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        remapper.render_texture(source, fbo, K1, K2, direction=direction)
        out = np.frombuffer(fbo.read(components=4), np.uint8).reshape(height, width, 4)
    finally:
        remapper.release()
        release_objects(ctx, fbo, color, source)
    function = glradial.correct if direction == "undistort" else glradial.distort
    expected_gl = function(frame, K1, K2, backend="gl")
    # the same shader on the same context: identical up to the last bit of 8-bit rounding
    assert np.abs(out.astype(int) - expected_gl).max() <= 1
    # the CPU backend (cv2.remap with fixed-point maps, 1/32 px) differs by interpolation rounding
    # only: a few levels at sharp edges, well under 1 level on average
    expected_cpu = function(frame, K1, K2, backend="cpu").astype(int)
    difference = np.abs(out.astype(int) - expected_cpu)
    assert difference.mean() < 0.5 and np.percentile(difference, 99) <= 4
    assert ctx.error == "GL_NO_ERROR"


def test_render_texture_into_viewport_leaves_rest_untouched(ctx, frame):
    height, width = frame.shape[:2]
    source = ctx.texture((width, height), 4, frame.tobytes())
    color = ctx.texture((width + 20, height + 10), 4)
    fbo = ctx.framebuffer(color_attachments=[color])
    remapper = glradial.Remapper(ctx)
    try:
        fbo.use()
        fbo.clear(1.0, 0.0, 1.0, 1.0)
        remapper.render_texture(source, fbo, K1, K2, viewport=(12, 4, width, height))
        out = np.frombuffer(fbo.read(components=4), np.uint8).reshape(height + 10, width + 20, 4)
    finally:
        remapper.release()
        release_objects(ctx, fbo, color, source)
    inside = out[4 : 4 + height, 12 : 12 + width]
    assert np.abs(inside.astype(int) - glradial.correct(frame, K1, K2, backend="gl")).max() <= 1
    outside = out.copy()
    outside[4 : 4 + height, 12 : 12 + width] = (255, 0, 255, 255)
    assert np.all(outside == np.array([255, 0, 255, 255], np.uint8))
    # the caller's context stays usable after the Remapper is released
    assert ctx.error == "GL_NO_ERROR"
    probe = ctx.texture((2, 2), 4)
    release_objects(ctx, probe)


def test_standalone_example_compiles_and_matches(ctx, frame):
    """The documented standalone recipe: '#version 330 core' + common.glsl + the example fragment
    program, with any covering vertex shader; no glradial preprocessing."""
    common = shader_path("common.glsl").read_text()
    example = (ROOT / "examples" / "standalone_correct.frag").read_text()
    vertex = "#version 330 core\n" + shader_path("fullscreen.vert").read_text()
    program = ctx.program(vertex_shader=vertex, fragment_shader="#version 330 core\n" + common + "\n" + example)
    height, width = frame.shape[:2]
    source = ctx.texture((width, height), 4, frame.tobytes())
    source.filter = (ctx.LINEAR, ctx.LINEAR)
    source.repeat_x = source.repeat_y = False
    color = ctx.texture((width, height), 4)
    fbo = ctx.framebuffer(color_attachments=[color])
    vao = ctx.vertex_array(program, [])
    try:
        program["u_k"].value = (K1, K2)
        program["u_size"].value = (width, height)
        source.use(0)
        program["u_image"].value = 0
        fbo.use()
        vao.render(vertices=3)
        out = np.frombuffer(fbo.read(components=4), np.uint8).reshape(height, width, 4).astype(int)
    finally:
        release_objects(ctx, vao, program, fbo, color, source)
    expected = glradial.correct(frame, K1, K2, backend="cpu").astype(int)
    # pixels whose source lies at least 1 px inside the frame (the example clamps at the border
    # where glradial blends towards the fill value)
    map_x, map_y = glradial.Lens(K1, K2).maps((width, height))
    inside = (map_x >= 1) & (map_y >= 1) & (map_x <= width - 2) & (map_y <= height - 2)
    assert inside.mean() > 0.8
    difference = np.abs(out - expected)[inside]
    # hardware bilinear filtering uses 8-bit weights: at most a few levels at sharp edges
    assert difference.mean() < 0.5 and difference.max() <= 4
    # outside the source the example writes transparent black
    assert np.all(out[~inside & ((map_x < -1) | (map_y < -1) | (map_x > width) | (map_y > height))] == 0)
