"""Seeded style sampling for the procedural stadium panoramas (no GL here).

Convention (scene, metres):
    Pitch centre at the origin, x along the pitch length (goal lines at x = ±52.5), y across it
    (touchlines at y = ±34), z up; the ground is z = 0. The main broadcast stand is on the -y side.
    Stand sides are numbered 0: +x end, 1: -x end, 2: +y (far) side, 3: -y (main) side; side i has
    the outward normal ``SIDE_NORMALS[i]`` and its stand profile is measured by ``d`` (metres beyond
    the stand front) and ``z`` (height).
    The camera looks at the pitch centre: ``yaw`` (degrees, counter-clockwise from +x) is the
    horizontal direction of longitude 0 in the panorama.

Seeds split into train / validation / test by ``seed % 10``: 0-7 train, 8 val, 9 test
(:func:`stadium_split`, :func:`split_seeds`). Everything a panorama looks like is decided here by a
``numpy.random.Generator(PCG64(seed))``, so the same seed always gives the same style.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..pitch.template import default_pitch

#: the pitch the stadiums are built around (glradial.pitch.template holds its markings; the GLSL
#: markings in shaders/stadium_pitch.glsl restate the same default dimensions)
PITCH_LENGTH = default_pitch().length
PITCH_WIDTH = default_pitch().width
HALF_LENGTH = PITCH_LENGTH / 2.0
HALF_WIDTH = PITCH_WIDTH / 2.0

#: outward normals (x, y) of the four stand sides
SIDE_NORMALS = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
#: distance from the pitch centre to the pitch line each side faces (goal line or touchline)
SIDE_LINE = (HALF_LENGTH, HALF_LENGTH, HALF_WIDTH, HALF_WIDTH)

LIGHTING_MODES = ("day", "overcast", "night")
STRIPE_PATTERNS = ("across", "along", "checker", "diagonal", "none")
CAMERA_KINDS = ("main", "tribune", "behind_goal", "pitch_side")
SPLITS = ("train", "val", "test")
MAX_PLAYERS = 24
#: athletics track: straights' half length, inner bend radius, width of 8 lanes (metres)
TRACK_HALF_STRAIGHT = 42.195
TRACK_RADIUS = 36.5
TRACK_WIDTH = 9.76
#: clearance from the pitch lines to the track's outer edge, behind the touchlines and the goal lines
TRACK_SIDE_CLEAR = TRACK_RADIUS + TRACK_WIDTH - HALF_WIDTH
TRACK_END_CLEAR = TRACK_HALF_STRAIGHT + TRACK_RADIUS + TRACK_WIDTH - HALF_LENGTH


def stadium_split(seed: int) -> str:
    """The split a seed belongs to: ``seed % 10`` in 0..7 → "train", 8 → "val", 9 → "test"."""
    seed = _check_seed(seed)
    rest = seed % 10
    return "train" if rest < 8 else ("val" if rest == 8 else "test")


def split_seeds(split: str, n: int, start: int = 0) -> list[int]:
    """The first ``n`` seeds ≥ ``start`` of ``split`` ("train", "val" or "test"), ascending."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    out: list[int] = []
    seed = max(0, int(start))
    while len(out) < n:
        if stadium_split(seed) == split:
            out.append(seed)
        seed += 1
    return out


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int, got {seed!r}")
    if seed < 0 or seed >= 2**63:
        raise ValueError(f"seed must be in [0, 2**63), got {seed}")
    return int(seed)


@dataclass(frozen=True)
class SideProfile:
    """Cross-section of one stand, in metres: ``d`` beyond the stand front, ``z`` up.

    Lower tier: front wall ``front_height`` high at d = 0, seats rising with ``slope1`` up to
    ``depth1``. Optional upper tier: its front face (``balcony`` high) hangs at d = depth1 -
    ``overhang``, its underside ``clearance`` above the lower tier's top, its seats rise with
    ``slope2`` up to ``depth2``. Optional roof: underside at ``roof_height`` from d = ``roof_front``
    to the back, front fascia ``fascia`` high.
    """

    margin: float  # metres from the pitch line to the stand front
    front_height: float
    slope1: float
    depth1: float
    upper: bool
    overhang: float
    clearance: float
    balcony: float
    slope2: float
    depth2: float
    roof: bool
    roof_height: float
    roof_front: float
    fascia: float
    board_offset: float  # metres from the pitch line to the advertising boards

    @property
    def lower_top(self) -> float:
        return self.front_height + self.slope1 * self.depth1

    @property
    def upper_front_d(self) -> float:
        return self.depth1 - self.overhang

    @property
    def upper_base(self) -> float:
        """Height of the upper tier's underside (soffit)."""
        return self.lower_top + self.clearance

    @property
    def back_d(self) -> float:
        return self.depth2 if self.upper else self.depth1

    @property
    def top_height(self) -> float:
        if self.upper:
            return self.upper_base + self.balcony + self.slope2 * (self.depth2 - self.upper_front_d)
        return self.lower_top

    def surface_height(self, d: float) -> float:
        """Height of the seating surface at ``d`` (the highest tier covering ``d``), 0 outside."""
        if d < 0.0 or d > self.back_d:
            return 0.0
        if self.upper and d >= self.upper_front_d:
            return self.upper_base + self.balcony + self.slope2 * (d - self.upper_front_d)
        return self.front_height + self.slope1 * d


@dataclass(frozen=True)
class StadiumStyle:
    """Everything that decides how one procedural stadium panorama looks (see module docstring)."""

    seed: int
    camera_kind: str
    camera: tuple[float, float, float]  # metres
    yaw: float  # degrees, direction of longitude 0 (counter-clockwise from +x)
    sides: tuple[SideProfile, SideProfile, SideProfile, SideProfile]
    lighting: str
    sun_azimuth: float  # degrees counter-clockwise from +x
    sun_elevation: float  # degrees
    exposure: float
    haze: float  # extinction per metre
    cloudiness: float  # 0..1
    rain: float  # 0..1
    grass_color: tuple[float, float, float]  # linear RGB
    grass_color2: tuple[float, float, float]  # second grass tone (patches)
    stripe_pattern: str
    stripe_width: float  # metres
    stripe_angle: float  # degrees, for "diagonal"
    stripe_contrast: float  # view-dependent part
    stripe_offset: float  # view-independent part
    grass_noise: float
    wear: float
    line_width: float  # metres
    line_brightness: float
    seat_colors: tuple[tuple[float, float, float], tuple[float, float, float]]
    seat_pattern: int  # 0 one colour, 1 alternating sections, 2 horizontal bands
    crowd_density: float
    crowd_colors: tuple[tuple[float, float, float], tuple[float, float, float]]
    concrete: tuple[float, float, float]
    roof_color: tuple[float, float, float]
    fascia_color: tuple[float, float, float]
    board_palette_seed: int
    board_height: float
    led_boards: bool
    masts: bool  # corner floodlight masts (else lights along the roof edge)
    mast_height: float
    surround: tuple[float, float, float]  # ground beyond the grass (track, concrete)
    track: bool
    players: tuple[tuple[float, float, float, float], ...] = field(default=())  # (x, y, team, height)
    team_colors: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0.8, 0.05, 0.05), (0.9, 0.9, 0.9))
    open_corners: tuple[bool, bool, bool, bool] = (False, False, False, False)  # corner c: x-side c & 1, y-side 2 + (c >> 1)
    pillars: tuple[bool, bool, bool, bool] = (False, False, False, False)  # roof columns in front of a stand
    pillar_spacing: float = 16.0  # metres between roof columns
    supersample: int = 2

    def with_overrides(self, **style: Any) -> "StadiumStyle":
        """A copy with some fields replaced; unknown names raise ``TypeError`` naming them."""
        names = {f.name for f in fields(self)}
        unknown = sorted(set(style) - names)
        if unknown:
            raise TypeError(f"unknown style parameters {unknown}; known: {sorted(names)}")
        if "lighting" in style and style["lighting"] not in LIGHTING_MODES:
            raise ValueError(f"lighting must be one of {LIGHTING_MODES}, got {style['lighting']!r}")
        if "stripe_pattern" in style and style["stripe_pattern"] not in STRIPE_PATTERNS:
            raise ValueError(f"stripe_pattern must be one of {STRIPE_PATTERNS}, got {style['stripe_pattern']!r}")
        if "supersample" in style and (not isinstance(style["supersample"], int) or not 1 <= style["supersample"] <= 4):
            raise ValueError(f"supersample must be an int in 1..4, got {style['supersample']!r}")
        if "camera_kind" in style or "camera" in style:
            raise ValueError("choose the camera through the seed (camera positions depend on the stands)")
        return replace(self, **style)


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float]:
    """HSV (all 0..1) to linear RGB (approximately: sRGB decoded by a 2.2 power)."""
    i = int(h * 6.0) % 6
    f = h * 6.0 - int(h * 6.0)
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    rgb = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return tuple(float(c) ** 2.2 for c in rgb)  # type: ignore[return-value]


def _team_color(rng: np.random.Generator) -> tuple[float, float, float]:
    kind = rng.random()
    if kind < 0.12:
        return _hsv(0.0, 0.0, rng.uniform(0.85, 0.97))  # white
    if kind < 0.2:
        return _hsv(0.0, 0.0, rng.uniform(0.08, 0.2))  # black
    return _hsv(rng.random(), rng.uniform(0.6, 0.95), rng.uniform(0.45, 0.9))


def _side_profile(rng: np.random.Generator, side: int, scale: float, main: bool) -> SideProfile:
    along = side >= 2  # touchline side
    margin = rng.uniform(5.0, 11.0) if along else rng.uniform(6.0, 14.0)
    board_offset = min(margin - 1.5, rng.uniform(3.0, 6.0))
    front = rng.uniform(1.2, 3.0)
    slope1 = rng.uniform(0.42, 0.68)
    depth1 = rng.uniform(14.0, 26.0) * scale
    upper = bool(rng.random() < (0.85 if main else 0.55) * min(1.0, scale + 0.2))
    overhang = rng.uniform(0.0, 7.0)
    clearance = rng.uniform(2.8, 5.0)
    balcony = rng.uniform(1.5, 3.2)
    slope2 = rng.uniform(0.55, 0.8)
    depth2 = depth1 + rng.uniform(12.0, 24.0) * scale
    back = depth2 if upper else depth1
    top = front + slope1 * depth1
    if upper:
        top = top + clearance + balcony + slope2 * (depth2 - (depth1 - overhang))
    roof = bool(rng.random() < (0.97 if main else 0.8))
    roof_front = rng.uniform(-4.0, 0.35 * back)
    roof_height = top + rng.uniform(3.0, 9.0)
    fascia = rng.uniform(1.5, 4.5)
    return SideProfile(
        margin=margin, front_height=front, slope1=slope1, depth1=depth1, upper=upper,
        overhang=overhang, clearance=clearance, balcony=balcony, slope2=slope2, depth2=depth2,
        roof=roof, roof_height=roof_height, roof_front=roof_front, fascia=fascia,
        board_offset=board_offset,
    )


def _camera(rng: np.random.Generator, sides: list[SideProfile]) -> tuple[str, tuple[float, float, float], list[SideProfile]]:
    """Pick a broadcast/tribune camera position; may deepen the stand it stands in."""
    roll = rng.random()
    kind = "main" if roll < 0.45 else "tribune" if roll < 0.7 else "behind_goal" if roll < 0.85 else "pitch_side"

    def place(side: int, dist_from_line: float, lateral: float, above: float) -> tuple[float, float, float]:
        prof = sides[side]
        d = dist_from_line - prof.margin
        need_back = d + 4.0
        if prof.back_d < need_back:  # the camera stands inside the stand: make the stand deep enough
            extra = need_back - prof.back_d
            prof = replace(prof, depth1=prof.depth1 + (0 if prof.upper else extra), depth2=prof.depth2 + extra)
        # broadcast cameras look down on the pitch at 15-35 deg: cap the height, lowering the stand
        # (all its heights scaled together) when its seats would rise above the camera
        z_cap = max(3.0, dist_from_line * math.tan(math.radians(rng.uniform(16.0, 34.0))))
        surface = prof.surface_height(d)
        if surface + above > z_cap and surface > 0.0:
            k = max(0.35, (z_cap - above) / surface)
            prof = replace(prof, front_height=prof.front_height * k, slope1=prof.slope1 * k,
                           clearance=prof.clearance * k, balcony=prof.balcony * k, slope2=prof.slope2 * k,
                           roof_height=prof.roof_height * k)
        z = prof.surface_height(d) + above
        # a clear line of sight over the tiers in front of the camera down to the near pitch line
        # (broadcast gantries hang at the front of a tier or under the roof)
        if d > 0.0:
            corners = [(0.0, prof.front_height), (prof.depth1, prof.lower_top)]
            if prof.upper:
                corners.append((prof.upper_front_d, prof.upper_base + prof.balcony))
            run = d + prof.margin
            for cd, cz in corners:
                if cd < d - 0.5:
                    z = max(z, (cz + 0.8) * run / (cd + prof.margin))
        if prof.roof:
            roof_h = max(prof.roof_height, z + 4.0, prof.top_height + 3.0)
            roof_front = min(prof.roof_front, d - 2.0) if d > 0 else prof.roof_front
            prof = replace(prof, roof_height=roof_h, roof_front=roof_front)
        sides[side] = prof
        nx, ny = SIDE_NORMALS[side]
        line = SIDE_LINE[side] + dist_from_line
        if side >= 2:
            return (lateral, ny * line, z)
        return (nx * line, lateral, z)

    if kind == "main":
        pos = place(3, rng.uniform(30.0, 70.0), rng.uniform(-2.0, 2.0), rng.uniform(1.5, 6.0))
    elif kind == "tribune":
        side = 3 if rng.random() < 0.6 else int(rng.integers(0, 3))
        lat_max = 40.0 if side >= 2 else 20.0
        pos = place(side, rng.uniform(15.0, 60.0), rng.uniform(-lat_max, lat_max), rng.uniform(1.5, 8.0))
    elif kind == "behind_goal":
        side = int(rng.integers(0, 2))
        pos = place(side, rng.uniform(15.0, 45.0), rng.uniform(-6.0, 6.0), rng.uniform(2.0, 8.0))
    else:
        side = 3 if rng.random() < 0.7 else int(rng.integers(0, 3))
        prof = sides[side]
        off = rng.uniform(1.0, max(1.2, prof.board_offset - 0.6))
        lat = rng.uniform(-40.0, 40.0) if side >= 2 else rng.uniform(-12.0, 12.0)
        nx, ny = SIDE_NORMALS[side]
        line = SIDE_LINE[side] + off
        z = rng.uniform(1.0, 2.6)
        pos = (lat, ny * line, z) if side >= 2 else (nx * line, lat, z)
    return kind, (float(pos[0]), float(pos[1]), float(pos[2])), sides


def sample_style(seed: int) -> StadiumStyle:
    """The deterministic style of panorama ``seed`` (a ``StadiumStyle``)."""
    seed = _check_seed(seed)
    rng = np.random.Generator(np.random.PCG64(seed))
    # the draws happen in one fixed order (the helpers below, in this order): a seed is a stadium
    sides, track = _sample_sides(rng)
    kind, cam, sides = _camera(rng, sides)
    yaw = math.degrees(math.atan2(-cam[1], -cam[0]))
    look = _sample_pitch_and_stands(rng, track)
    grey = look.pop("_grey")
    style = StadiumStyle(seed=seed, camera_kind=kind, camera=cam, yaw=float(yaw), sides=tuple(sides),  # type: ignore[arg-type]
                         track=track, **look, **_sample_weather_and_dressing(rng, look, grey))
    # some stadiums (older grounds) have open corners between their stands
    if rng.random() < 0.3:
        style = replace(style, open_corners=tuple(bool(rng.random() < 0.8) for _ in range(4)))  # type: ignore[arg-type]
    # older roofs stand on columns at the front of the stand (never in front of the camera)
    cam_side = _camera_side(cam)
    pillars = tuple(bool(p.roof and i != cam_side and rng.random() < 0.3) for i, p in enumerate(style.sides))
    style = replace(style, pillars=pillars, pillar_spacing=float(rng.uniform(11.0, 22.0)))  # type: ignore[arg-type]
    return style


def _sample_sides(rng: np.random.Generator) -> tuple[list, bool]:
    """The four stands (symmetric or not) and whether an athletics track surrounds the pitch."""
    scale = rng.uniform(0.55, 1.25)  # stadium size
    sym = rng.random() < 0.5  # symmetric stadium: the ends match, the sides match
    sides = [_side_profile(rng, i, scale, main=(i == 3)) for i in range(4)]
    if sym:
        sides[1] = sides[0]
        sides[2] = replace(sides[3])
    # an athletics track (400 m, 8 lanes) around the pitch pushes the stands and boards back
    track = bool(rng.random() < 0.12)
    if track:
        for i, p in enumerate(sides):
            end = i < 2
            sides[i] = replace(p, margin=rng.uniform(38.5, 44.0) if end else rng.uniform(14.5, 18.0),
                               board_offset=(TRACK_END_CLEAR if end else TRACK_SIDE_CLEAR) + rng.uniform(0.3, 1.2))
    return sides, track


def _sample_pitch_and_stands(rng: np.random.Generator, track: bool) -> dict:
    """Lighting, grass and stripes, team and seat colours, players, the surround (``StadiumStyle``
    fields) and ``"_grey"`` (the concrete's value, drawn here)."""
    lighting = LIGHTING_MODES[int(rng.choice(3, p=[0.5, 0.2, 0.3]))]
    sun_az = rng.uniform(0.0, 360.0)
    sun_el = rng.uniform(8.0, 62.0) if lighting == "day" else rng.uniform(20.0, 60.0)
    grass_h = rng.uniform(0.22, 0.32)
    grass = _hsv(grass_h, rng.uniform(0.45, 0.75), rng.uniform(0.38, 0.6))
    grass2 = _hsv(grass_h + rng.uniform(-0.04, 0.02), rng.uniform(0.35, 0.7), rng.uniform(0.3, 0.55))
    pattern = STRIPE_PATTERNS[int(rng.choice(5, p=[0.5, 0.15, 0.12, 0.1, 0.13]))]
    if pattern == "across":
        width = PITCH_LENGTH / int(rng.integers(9, 13)) / 2.0
    elif pattern == "along":
        width = PITCH_WIDTH / int(rng.integers(5, 9)) / 2.0
    else:
        width = rng.uniform(4.0, 9.0)
    team = (_team_color(rng), _team_color(rng))
    seat1 = team[0] if rng.random() < 0.6 else _hsv(rng.random(), rng.uniform(0.2, 0.9), rng.uniform(0.3, 0.8))
    seat2 = _team_color(rng)
    grey = rng.uniform(0.35, 0.7)
    n_players = int(rng.integers(0, MAX_PLAYERS + 1)) if rng.random() < 0.6 else 0
    players = tuple(
        (float(rng.uniform(-50, 50)), float(rng.uniform(-32, 32)), float(i % 2), float(rng.uniform(1.7, 1.95)))
        for i in range(n_players)
    )
    surround = _hsv(0.03, 0.6, 0.45) if track else (grass if rng.random() < 0.7 else _hsv(0.1, 0.1, 0.5))
    return dict(lighting=lighting, sun_azimuth=float(sun_az), sun_elevation=float(sun_el), grass_color=grass,
                grass_color2=grass2, stripe_pattern=pattern, stripe_width=float(width), seat_colors=(seat1, seat2),
                surround=surround, players=players, team_colors=team, _grey=grey)


def _sample_weather_and_dressing(rng: np.random.Generator, look: dict, grey: float) -> dict:
    """Exposure and weather, stripe details, wear and lines, crowd, concrete, roofs, boards and
    masts (``StadiumStyle`` fields, drawn in this order)."""
    team = look["team_colors"]
    return dict(
        exposure=float(rng.uniform(0.85, 1.2)),
        haze=float(rng.uniform(0.0, 0.0015) if rng.random() < 0.75 else rng.uniform(0.0015, 0.004)),  # per metre
        cloudiness=float(rng.uniform(0.0, 1.0)),
        rain=float(rng.uniform(0.2, 0.8) if (look["lighting"] != "day" and rng.random() < 0.2) else 0.0),
        stripe_angle=float(rng.uniform(20.0, 60.0) * rng.choice([-1, 1])),
        stripe_contrast=float(rng.uniform(0.05, 0.25)),
        stripe_offset=float(rng.uniform(0.0, 0.08)),
        grass_noise=float(rng.uniform(0.3, 1.0)),
        wear=float(rng.uniform(0.0, 1.0) ** 1.5),
        line_width=float(rng.uniform(0.10, 0.13)),
        line_brightness=float(rng.uniform(0.7, 0.95)),
        seat_pattern=int(rng.integers(0, 3)),
        crowd_density=float(rng.uniform(0.0, 1.0) ** 0.5),
        crowd_colors=(team[0], _team_color(rng)),
        concrete=_hsv(rng.uniform(0.05, 0.15), rng.uniform(0.0, 0.15), grey),
        roof_color=_hsv(0.6, rng.uniform(0.0, 0.2), rng.uniform(0.25, 0.6)),
        fascia_color=team[0] if rng.random() < 0.3 else _hsv(0.6, rng.uniform(0.0, 0.1), rng.uniform(0.6, 0.95)),
        board_palette_seed=int(rng.integers(0, 2**31 - 1)),
        board_height=float(rng.uniform(0.8, 1.1)),
        led_boards=bool(rng.random() < 0.6),
        masts=bool(rng.random() < 0.5),
        mast_height=float(rng.uniform(35.0, 60.0)),
    )


def _camera_side(cam: tuple[float, float, float]) -> int:
    """The stand side the camera stands on or in front of (largest outward coordinate)."""
    x, y, _ = cam
    scores = [x - HALF_LENGTH, -x - HALF_LENGTH, y - HALF_WIDTH, -y - HALF_WIDTH]
    return int(np.argmax(scores))
