"""Procedural football-stadium panoramas, ray-cast per pixel by ``shaders/stadium.frag``.

Convention:
    Output: ``uint8`` array of shape ``(H, W, 3)``, RGB, equirectangular. Column x has longitude
    ``lon = ((x + 0.5) / W - 0.5) * 360°`` (0 at the centre column, positive to the right), row y
    has latitude ``lat = (0.5 - (y + 0.5) / H) * 180°`` (+90° at the top row). Row 0 is the top.
    Scene: metres, pitch centre at the origin, x along the pitch, y across, z up (see
    :mod:`glradial.synthesis.stadium_style`). The camera stands at ``style.camera`` and longitude 0 looks
    horizontally at the pitch centre (azimuth ``style.yaw``, degrees counter-clockwise from +x);
    a direction is ``cos(lat)·(cos(lon)·f + sin(lon)·r) + sin(lat)·up`` with
    ``f = (cos yaw, sin yaw, 0)`` and ``r = (sin yaw, −cos yaw, 0)``.

Seeds: every seed gives one stadium (:func:`glradial.synthesis.stadium_style.sample_style`); the split into
train / val / test is ``seed % 10`` (0-7 / 8 / 9), see :func:`stadium_split` and :func:`split_seeds`.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from ..gl.egl import GLOwner, check_gl_error, max_texture_size, release_objects, thread_context, thread_resource
from ..gl.shaderlib import build_program, preprocess
from . import stadium_style
from .stadium_style import (
    HALF_LENGTH,
    HALF_WIDTH,
    MAX_PLAYERS,
    SIDE_LINE,
    SideProfile,
    StadiumStyle,
    sample_style,
    split_seeds,
    stadium_split,
)

__all__ = [
    "StadiumRenderer",
    "stadium_panorama",
    "stadium_panorama_cached",
    "stadium_cache_path",
    "stadium_code_digest",
    "sample_style",
    "stadium_split",
    "split_seeds",
    "camera_direction",
    "project_point",
]

NSEG = 10  # profile segments per side (must match NSEG in shaders/stadium_stands.glsl)
#: material ids (match the MAT_* defines in shaders/stadium_stands.glsl)
MAT_FRONT, MAT_SEAT1, MAT_BACK, MAT_SOFFIT, MAT_BALCONY, MAT_SEAT2 = 1, 2, 3, 4, 5, 6
MAT_ROOF_UNDER, MAT_FASCIA, MAT_ROOF_TOP = 7, 8, 9
_LIGHTING_ID = {"day": 0, "overcast": 1, "night": 2}
_STRIPE_ID = {"across": 0, "along": 1, "checker": 2, "diagonal": 3, "none": 4}
#: rows drawn per draw call: keeps one llvmpipe draw short and the framebuffer small
STRIP_PIXELS = 1 << 21


def _profile_segments(p: SideProfile) -> list[tuple[tuple[float, float, float, float], int]]:
    """The stand's cross-section as segments ``((d0, z0, d1, z1), material)`` in profile metres."""
    segs: list[tuple[tuple[float, float, float, float], int]] = []
    lt = p.lower_top
    segs.append(((0.0, 0.0, 0.0, p.front_height), MAT_FRONT))
    segs.append(((0.0, p.front_height, p.depth1, lt), MAT_SEAT1))
    top = p.top_height
    back = p.back_d
    if p.upper:
        ufd, ub = p.upper_front_d, p.upper_base
        segs.append(((p.depth1, lt, p.depth1, ub), MAT_BACK))
        segs.append(((ufd, ub, p.depth1, ub), MAT_SOFFIT))
        segs.append(((ufd, ub, ufd, ub + p.balcony), MAT_BALCONY))
        segs.append(((ufd, ub + p.balcony, p.depth2, top), MAT_SEAT2))
    if p.roof:
        segs.append(((back, top, back, p.roof_height + p.fascia), MAT_BACK))
        segs.append(((p.roof_front, p.roof_height, back, p.roof_height), MAT_ROOF_UNDER))
        segs.append(((p.roof_front, p.roof_height, p.roof_front, p.roof_height + p.fascia), MAT_FASCIA))
        segs.append(((p.roof_front, p.roof_height + p.fascia, back, p.roof_height + p.fascia), MAT_ROOF_TOP))
    else:
        segs.append(((back, top, back, top + 2.0), MAT_BACK))
        segs.append(((back - 0.3, top + 2.0, back, top + 2.0), MAT_BACK))
    while len(segs) < NSEG:
        segs.append(((0.0, 0.0, 0.0, 0.0), MAT_BACK))  # padding after the u_nseg used ones
    if len(segs) > NSEG:
        raise AssertionError(f"profile has {len(segs)} segments, NSEG is {NSEG}")
    return segs


def camera_direction(style: StadiumStyle, lon_deg: float, lat_deg: float) -> np.ndarray:
    """World direction (unit 3-vector) of panorama longitude/latitude (degrees) for ``style``."""
    yaw = math.radians(style.yaw)
    lon, lat = math.radians(lon_deg), math.radians(lat_deg)
    f = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    r = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    return math.cos(lat) * (math.cos(lon) * f + math.sin(lon) * r) + math.sin(lat) * up


def project_point(style: StadiumStyle, point: tuple[float, float, float]) -> tuple[float, float]:
    """(longitude, latitude) in degrees at which the scene point ``point`` (metres) appears."""
    v = np.asarray(point, dtype=float) - np.asarray(style.camera, dtype=float)
    yaw = math.radians(style.yaw)
    fwd = v[0] * math.cos(yaw) + v[1] * math.sin(yaw)
    right = v[0] * math.sin(yaw) - v[1] * math.cos(yaw)
    lon = math.degrees(math.atan2(right, fwd))
    lat = math.degrees(math.atan2(v[2], math.hypot(fwd, right)))
    return lon, lat


def _lighting_params(style: StadiumStyle) -> dict[str, Any]:
    az, el = math.radians(style.sun_azimuth), math.radians(style.sun_elevation)
    sun_dir = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))
    if style.lighting == "day":
        sun, amb, fog = (1.7, 1.58, 1.4), (0.33, 0.38, 0.48), (0.55, 0.63, 0.76)
    elif style.lighting == "overcast":
        sun, amb, fog = (0.0, 0.0, 0.0), (0.82, 0.84, 0.88), (0.6, 0.62, 0.65)
    else:
        sun, amb, fog = (1.55, 1.55, 1.5), (0.015, 0.017, 0.025), (0.06, 0.06, 0.07)
    haze = style.haze + 0.01 * style.rain
    return {"u_sun_dir": sun_dir, "u_sun_color": sun, "u_ambient": amb, "u_fog": fog, "u_haze": haze}


def _uniforms(style: StadiumStyle) -> dict[str, Any]:
    """Every uniform of stadium.frag for ``style`` (except size, strip row and supersampling)."""
    u = _surface_uniforms(style)
    u.update(_lighting_params(style))
    u.update(_stand_uniforms(style))
    u.update(_mast_and_player_uniforms(style))
    return u


def _surface_uniforms(style: StadiumStyle) -> dict[str, Any]:
    """Camera, sky, pitch, boards, seats and colours: the uniforms read straight from ``style``."""
    return {
        "u_cam": style.camera,
        "u_yaw": math.radians(style.yaw),
        "u_lighting": _LIGHTING_ID[style.lighting],
        "u_cloudiness": style.cloudiness,
        "u_exposure": style.exposure,
        "u_rain": style.rain,
        "u_stripe_pattern": _STRIPE_ID[style.stripe_pattern],
        "u_stripe_width": style.stripe_width,
        "u_stripe_angle": math.radians(style.stripe_angle),
        "u_stripe_contrast": style.stripe_contrast,
        "u_stripe_offset": style.stripe_offset,
        "u_grass": style.grass_color,
        "u_grass2": style.grass_color2,
        "u_grass_noise": style.grass_noise,
        "u_wear": style.wear,
        "u_surround": style.surround,
        "u_track": int(style.track),
        "u_open_corner": [int(c) for c in style.open_corners],
        "u_line_width": style.line_width,
        "u_line_brightness": style.line_brightness,
        "u_board_height": style.board_height,
        "u_board_seed": style.board_palette_seed & 0x7FFFFFFF,
        "u_led_boards": int(style.led_boards),
        "u_aisle": 14.0 + (style.seed % 7),
        "u_seat1": style.seat_colors[0],
        "u_seat2": style.seat_colors[1],
        "u_seat_pattern": style.seat_pattern,
        "u_concrete": style.concrete,
        "u_crowd1": style.crowd_colors[0],
        "u_crowd2": style.crowd_colors[1],
        "u_crowd_density": style.crowd_density,
        "u_roof": style.roof_color,
        "u_fascia": style.fascia_color,
        "u_team1": style.team_colors[0],
        "u_team2": style.team_colors[1],
    }


def _stand_uniforms(style: StadiumStyle) -> dict[str, Any]:
    """The four stands: profiles, roof and board lines, profile segments, shadow corners, pillars."""
    u: dict[str, Any] = {}
    a, b, c, d, seg, mat, nseg = [], [], [], [], [], [], []
    for i, p in enumerate(style.sides):
        a.append((SIDE_LINE[i] + p.margin, p.front_height, p.slope1, p.depth1))
        b.append((float(p.upper), p.upper_front_d, p.upper_base, p.balcony))
        c.append((p.slope2, p.back_d, float(p.roof), p.roof_height))
        other = style.sides[2] if i < 2 else style.sides[0]
        half = (HALF_WIDTH if i < 2 else HALF_LENGTH) + 0.6 * other.margin
        d.append((p.roof_front, p.fascia, SIDE_LINE[i] + p.board_offset, half))
        segments = _profile_segments(p)
        nseg.append(1 + max(k for k, (s, _) in enumerate(segments) if s[:2] != s[2:]))
        for s, m in segments:
            seg.append(s)
            mat.append(float(m))
    corners = []
    for p in style.sides:
        env = [(0.0, p.front_height), (p.depth1, p.lower_top)]
        env.append((p.upper_front_d, p.upper_base + p.balcony) if p.upper else env[-1])
        env.append((p.back_d, p.top_height))
        env.append((p.roof_front, p.roof_height + p.fascia) if p.roof else env[-1])
        env.append((p.back_d, p.roof_height + p.fascia) if p.roof else env[-1])
        corners += env
    u["u_shadow_corners"] = corners
    u["u_nseg"] = nseg
    u["u_pillars"] = [int(v) for v in style.pillars]
    u["u_pillar_spacing"] = style.pillar_spacing
    u.update({"u_side_a": a, "u_side_b": b, "u_side_c": c, "u_side_d": d, "u_seg": seg, "u_segmat": mat})
    return u


def _mast_and_player_uniforms(style: StadiumStyle) -> dict[str, Any]:
    """Floodlight masts (behind the corners, above the roofs) and the players on the pitch."""
    u: dict[str, Any] = {}
    x0 = HALF_LENGTH + style.sides[0].margin + 0.5 * style.sides[0].back_d
    y0 = HALF_WIDTH + style.sides[2].margin + 0.5 * style.sides[2].back_d
    roof_top = max(p.roof_height + p.fascia if p.roof else p.top_height for p in style.sides)
    u["u_masts"] = int(style.masts)
    u["u_mast_pos"] = (x0, y0)
    u["u_mast_height"] = max(style.mast_height, roof_top + 10.0)
    players = sorted(style.players, key=lambda pl: pl[0])[:MAX_PLAYERS]  # the shader stops past the ray's x range
    u["u_nplayers"] = len(players)
    u["u_players"] = [tuple(pl) for pl in players] + [(0.0, 0.0, 0.0, 0.0)] * (MAX_PLAYERS - len(players))
    return u


def _parse_size(size: Any) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise TypeError(f"size must be (W, H) integers, got {size!r}") from None
    if w < 8 or h < 4 or w > 65536 or h > 32768:
        raise ValueError(f"size must be (W, H) with 8 <= W <= 65536 and 4 <= H <= 32768, got {size!r}")
    return w, h


class StadiumRenderer:
    """Owns the stadium GL program and a strip framebuffer; renders panoramas of any size.

    Large panoramas are drawn in horizontal strips (at most ``STRIP_PIXELS`` pixels each, never
    wider than the texture limit allows) into one reused framebuffer and read back into the output
    array. Use as a context manager or call :meth:`release`. One renderer belongs to the thread
    that made it (its context is ``ctx`` or the thread's glradial context).

    Args:
        ctx: a moderngl context (default: the thread's glradial context).

    Raises:
        TypeError: ``ctx`` is neither ``None`` nor a moderngl context.
        glradial.GLUnavailableError: no GL context can be made.

    Example:
        >>> import glradial
        >>> from glradial.synthesis.stadium_style import sample_style
        >>> with glradial.StadiumRenderer() as renderer:
        ...     panorama = renderer.render(sample_style(3), (64, 32))
        >>> panorama.shape, panorama.dtype
        ((32, 64, 3), dtype('uint8'))
    """

    def __init__(self, ctx: moderngl.Context | None = None):
        if ctx is not None and not isinstance(ctx, moderngl.Context):
            raise TypeError(f"ctx must be a moderngl.Context or None, got {type(ctx).__name__} {ctx!r}")
        self.ctx = ctx if ctx is not None else thread_context()
        self._owner = GLOwner("StadiumRenderer", self.ctx)
        self._owner.enter()
        self._max_tex = max_texture_size(self.ctx)
        self.first = build_program(self.ctx, "fullscreen.vert", "stadium.frag", {"STADIUM_PASS": 1})
        self.program = build_program(self.ctx, "fullscreen.vert", "stadium.frag", {"STADIUM_PASS": 2})
        self.vao_first = self.ctx.vertex_array(self.first, [])
        self.vao = self.ctx.vertex_array(self.program, [])
        self._fbo: moderngl.Framebuffer | None = None
        self._tex: moderngl.Texture | None = None
        self._fbo1: moderngl.Framebuffer | None = None
        self._tex1: moderngl.Texture | None = None
        self._strip: tuple[int, int] | None = None

    def __enter__(self) -> "StadiumRenderer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Free the program, vertex array and framebuffer (idempotent)."""
        if self.program is None:
            return
        self._owner.enter()
        release_objects(self.ctx, self._fbo, self._tex, self._fbo1, self._tex1, self.vao, self.vao_first,
                        self.program, self.first)
        self._fbo = self._tex = self._fbo1 = self._tex1 = None
        self.vao = self.program = self.vao_first = self.first = None  # type: ignore[assignment]

    def _targets(self, width: int, rows: int) -> tuple[moderngl.Framebuffer, moderngl.Framebuffer]:
        """Pass-1 strip (linear colour + geometry id, one spare row above and below) and output strip."""
        if self._strip != (width, rows):
            release_objects(self.ctx, self._fbo, self._tex, self._fbo1, self._tex1)
            self._tex1 = self.ctx.texture((width, rows + 2), 4, dtype="f2")
            self._tex1.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbo1 = self.ctx.framebuffer(color_attachments=[self._tex1])
            self._tex = self.ctx.texture((width, rows), 4)
            self._fbo = self.ctx.framebuffer(color_attachments=[self._tex])
            self._strip = (width, rows)
        assert self._fbo is not None and self._fbo1 is not None
        return self._fbo1, self._fbo

    def render(
        self,
        style: StadiumStyle,
        size: tuple[int, int] = (8192, 4096),
        out: np.ndarray | None = None,
        rows: tuple[int, int] | None = None,
    ) -> np.ndarray:
        """Render ``style`` as an H×W×3 uint8 RGB panorama (see the module's Convention block).

        ``rows = (y0, y1)`` renders only panorama rows ``y0 <= y < y1`` (same pixels as in the full
        render); the other rows of ``out`` are left as they are (zeros when ``out`` is None).
        """
        if self.program is None:
            raise RuntimeError("StadiumRenderer was released")
        self._owner.enter()
        if not isinstance(style, StadiumStyle):
            raise TypeError(f"style must be a StadiumStyle, got {type(style).__name__}")
        w, h = _parse_size(size)
        if w > self._max_tex:
            raise ValueError(f"panorama width {w} exceeds the GL texture limit {self._max_tex}")
        if rows is None:
            first, last = 0, h
        else:
            first, last = (int(v) for v in rows)
            if not 0 <= first < last <= h:
                raise ValueError(f"rows must be (y0, y1) with 0 <= y0 < y1 <= {h}, got {rows!r}")
        if out is None:
            out = (np.empty if rows is None else np.zeros)((h, w, 3), dtype=np.uint8)
        elif out.shape != (h, w, 3) or out.dtype != np.uint8 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous uint8 array of shape {(h, w, 3)}, got {out.shape} {out.dtype}")
        uniforms = _uniforms(style)
        uniforms["u_size"] = (float(w), float(h))
        uniforms["u_ss"] = int(style.supersample)
        for prog in (self.first, self.program):
            for name, value in uniforms.items():
                if name in prog:
                    prog[name].value = value
        if "u_first" in self.program:
            self.program["u_first"].value = 0
        strip = max(1, min(last - first, STRIP_PIXELS // w, self._max_tex - 2))
        fbo1, fbo = self._targets(w, strip)
        for y0 in range(first, last, strip):
            n = min(strip, last - y0)
            self.first["u_row0"].value = float(y0)
            fbo1.use()
            fbo1.viewport = (0, 0, w, n + 2)
            self.vao_first.render(vertices=3)
            self._tex1.use(location=0)
            self.program["u_row0"].value = float(y0)
            fbo.use()
            fbo.viewport = (0, 0, w, n)
            self.vao.render(vertices=3)
            fbo.read_into(out[y0:y0 + n], viewport=(0, 0, w, n), components=3, alignment=1)
        check_gl_error(self.ctx, "stadium render")
        return out


def stadium_panorama(seed: int, size: tuple[int, int] = (8192, 4096), **style: Any) -> np.ndarray:
    """Procedural football-stadium panorama for ``seed`` as H×W×3 uint8 RGB (equirectangular).

    ``size`` is (W, H) in pixels (normally W = 2H). ``style`` overrides fields of the seed's
    :class:`~glradial.synthesis.stadium_style.StadiumStyle` (e.g. ``lighting="night"``, ``supersample=1``);
    the camera position always comes from the seed. Deterministic: the same seed, size and
    overrides give the same pixels on one driver. Uses the calling thread's GL context.

    Args:
        seed: the stadium's seed (>= 0).
        size: ``(W, H)`` pixels.
        **style: :class:`~glradial.synthesis.stadium_style.StadiumStyle` fields to override.

    Returns:
        H×W×3 uint8 RGB array.

    Raises:
        ValueError: a bad seed, size or style field.

    Example:
        >>> import numpy as np, glradial
        >>> a = glradial.stadium_panorama(5, (64, 32), supersample=1)
        >>> a.shape, bool(np.array_equal(a, glradial.stadium_panorama(5, (64, 32), supersample=1)))
        ((32, 64, 3), True)
    """
    st = sample_style(seed)
    if style:
        st = st.with_overrides(**style)
    return thread_resource("stadium_renderer", StadiumRenderer).render(st, size)


#: the shader files a panorama is drawn with (both passes; their includes are followed)
STADIUM_SHADERS = ("fullscreen.vert", "stadium.frag")


def stadium_code_digest() -> str:
    """12 hex digits of SHA-256 over what a panorama's pixels depend on besides its seed and size:
    the stadium shaders with their includes expanded (:data:`STADIUM_SHADERS`) and the Python source
    that turns a seed into the shaders' uniforms (``stadium_style.py``, this module). Part of
    :func:`stadium_cache_path`, so a changed shader or style never serves a stale panorama."""
    digest = hashlib.sha256()
    for name in STADIUM_SHADERS:
        digest.update(preprocess(name).text.encode("utf-8"))
    for source in (stadium_style.__file__, __file__):
        digest.update(Path(source).read_bytes())
    return digest.hexdigest()[:12]


def stadium_cache_path(seed: int, size: tuple[int, int], cache_dir: str | os.PathLike) -> Path:
    """Where :func:`stadium_panorama_cached` keeps the panorama of ``seed`` at ``size = (W, H)``:
    ``<cache_dir>/stadium_<seed>_<W>x<H>_<code>.npy``, ``<code>`` the :func:`stadium_code_digest`."""
    width, height = _parse_size(size)
    return Path(cache_dir) / f"stadium_{seed}_{width}x{height}_{stadium_code_digest()}.npy"


def stadium_panorama_cached(seed: int, size: tuple[int, int], cache_dir: str | os.PathLike | None) -> np.ndarray:
    """:func:`stadium_panorama` of ``seed`` at ``size = (W, H)`` (default style), rendered once and
    kept at :func:`stadium_cache_path` (written atomically); ``cache_dir=None`` renders without
    caching. The file's name holds the shaders' and the style code's digest: after a change of
    either, the panorama is rendered again (older files are left for the user to delete)."""
    width, height = _parse_size(size)
    path = stadium_cache_path(seed, size, cache_dir) if cache_dir is not None else None
    if path is not None and path.exists():
        return np.load(path)
    pano = np.ascontiguousarray(stadium_panorama(seed, size=(width, height)))
    if pano.ndim != 3 or pano.shape[:2] != (height, width) or pano.dtype != np.uint8:
        raise RuntimeError(f"stadium_panorama({seed}) returned {pano.dtype} {pano.shape}, expected {height}x{width}x3 uint8")
    pano = np.ascontiguousarray(pano[:, :, :3])
    if path is not None:
        from ..media.atomic import atomic_path

        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            np.save(tmp, pano)
    return pano
