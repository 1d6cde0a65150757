"""One home for the football pitch template (IFAB Law 1 markings, configurable dimensions).

Convention:
    Pitch coordinates in metres: origin at the centre spot, ``x`` along the touchlines (positive toward
    the goal on the right of the main camera's view; goal lines at ``x = ±length/2``), ``y`` across
    (positive toward the far touchline; touchlines at ``y = ±width/2``), ``z`` up (the pitch is
    ``z = 0``). Markings are described by their centre lines (painted lines are ~0.12 m wide).

What it holds:
    * :class:`Element`: one marking, a straight ``"segment"`` (``a`` to ``b``) or a circular ``"arc"``
      (``centre``, ``radius``, angles ``start`` to ``stop`` in degrees counter-clockwise from +x), with a
      label (``"near_touchline"``, ``"left_box_front"``, ``"centre_circle"``, ...).
    * :meth:`PitchTemplate.elements`: the 17 segments and 3 circles/arcs of a pitch (touchlines, goal
      lines, halfway line, both penalty and goal areas, the centre circle, both penalty arcs outside the
      areas); :meth:`PitchTemplate.spots`: the centre and penalty spots.
    * :meth:`PitchTemplate.polylines`: each element sampled every ``step`` metres, with its label.
    * :meth:`PitchTemplate.keypoints`: the 32 keypoints in the order of the Bundesliga labels
      (``shared/data/broadcast_bundesliga/keypoints/keypoints.json``), ``32 x 3`` (z = 0), with
      :data:`KEYPOINT_NAMES`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

#: Names of the 32 keypoints, in the order of :meth:`PitchTemplate.keypoints`.
KEYPOINT_NAMES = (
    "left goal line x far touchline (corner)", "left goal line x far penalty-box line",
    "left goal line x far goal-area line", "left goal line x near goal-area line",
    "left goal line x near penalty-box line", "left goal line x near touchline (corner)",
    "left goal area, far corner in the field", "left goal area, near corner in the field",
    "left penalty spot", "left penalty box, far corner in the field",
    "left penalty arc x penalty-box line, far", "left penalty arc x penalty-box line, near",
    "left penalty box, near corner in the field", "halfway line x far touchline",
    "halfway line x centre circle, far", "halfway line x centre circle, near",
    "halfway line x near touchline", "right penalty box, far corner in the field",
    "right penalty arc x penalty-box line, far", "right penalty arc x penalty-box line, near",
    "right penalty box, near corner in the field", "right penalty spot",
    "right goal area, far corner in the field", "right goal area, near corner in the field",
    "right goal line x far touchline (corner)", "right goal line x far penalty-box line",
    "right goal line x far goal-area line", "right goal line x near goal-area line",
    "right goal line x near penalty-box line", "right goal line x near touchline (corner)",
    "centre circle x centre line of the pitch, left", "centre circle x centre line of the pitch, right",
)


@dataclass(frozen=True)
class Element:
    """One pitch marking (metres, pitch coordinates; see the module docstring): ``kind`` is
    ``"segment"`` (from ``a`` to ``b``) or ``"arc"`` (``centre``, ``radius``, from ``start`` to ``stop``
    degrees counter-clockwise from +x)."""

    label: str
    kind: str
    a: tuple[float, float] = (0.0, 0.0)
    b: tuple[float, float] = (0.0, 0.0)
    centre: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0
    start: float = 0.0
    stop: float = 0.0

    def sample(self, step: float) -> np.ndarray:
        """Points along the element at most ``step`` metres apart (both ends included), ``N x 2``."""
        if self.kind == "segment":
            a, b = np.asarray(self.a, float), np.asarray(self.b, float)
            n = max(2, int(math.ceil(np.linalg.norm(b - a) / step)) + 1)
            t = np.linspace(0.0, 1.0, n)[:, None]
            return a * (1.0 - t) + b * t
        span = math.radians(self.stop - self.start)
        n = max(3, int(math.ceil(abs(span) * self.radius / step)) + 1)
        t = np.linspace(math.radians(self.start), math.radians(self.stop), n)
        return np.stack([self.centre[0] + self.radius * np.cos(t), self.centre[1] + self.radius * np.sin(t)], axis=1)


def _positive(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number of metres, got {value!r}")
    if not math.isfinite(float(value)) or float(value) <= 0.0:
        raise ValueError(f"{name} must be a positive finite number of metres, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class PitchTemplate:
    """A pitch's dimensions in metres (defaults: 105 x 68 m and the IFAB markings). ``box_*`` is the
    penalty area, ``goal_area_*`` the goal area (``*_depth`` from the goal line into the field,
    ``*_width`` across, centred), ``penalty_spot`` the spot's distance from the goal line,
    ``circle_radius`` the centre circle's and the penalty arcs' radius."""

    length: float = field(default=105.0, metadata={"doc": "goal line to goal line (m)"})
    width: float = field(default=68.0, metadata={"doc": "touchline to touchline (m)"})
    box_depth: float = field(default=16.5, metadata={"doc": "penalty area, from the goal line into the field (m)"})
    box_width: float = field(default=40.32, metadata={"doc": "penalty area, across (m)"})
    goal_area_depth: float = field(default=5.5, metadata={"doc": "goal area, from the goal line into the field (m)"})
    goal_area_width: float = field(default=18.32, metadata={"doc": "goal area, across (m)"})
    penalty_spot: float = field(default=11.0, metadata={"doc": "penalty spot from the goal line (m)"})
    circle_radius: float = field(default=9.15, metadata={"doc": "centre circle and penalty arcs (m)"})

    def __post_init__(self) -> None:
        for name in ("length", "width", "box_depth", "box_width", "goal_area_depth", "goal_area_width",
                     "penalty_spot", "circle_radius"):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        if not (self.goal_area_depth < self.penalty_spot < self.box_depth < self.length / 2):
            raise ValueError(f"pitch needs goal_area_depth < penalty_spot < box_depth < length/2, got "
                             f"{self.goal_area_depth}, {self.penalty_spot}, {self.box_depth}, {self.length / 2}")
        if not (self.goal_area_width < self.box_width < self.width):
            raise ValueError(f"pitch needs goal_area_width < box_width < width, got {self.goal_area_width}, "
                             f"{self.box_width}, {self.width}")
        if not (self.box_depth - self.penalty_spot < self.circle_radius < self.width / 2):
            raise ValueError(f"circle_radius must exceed box_depth - penalty_spot and stay inside the pitch, "
                             f"got {self.circle_radius}")

    @property
    def half_length(self) -> float:
        return self.length / 2.0

    @property
    def half_width(self) -> float:
        return self.width / 2.0

    def arc_half_angle(self) -> float:
        """Half the angle (degrees) of a penalty arc: the part of the spot's circle outside the area."""
        return math.degrees(math.acos((self.box_depth - self.penalty_spot) / self.circle_radius))

    def elements(self) -> tuple[Element, ...]:
        """Every line and circle of the markings (see the module docstring), the same each call."""
        return _elements(self)

    def spots(self) -> np.ndarray:
        """The left penalty spot, the centre spot and the right penalty spot, ``3 x 2`` metres."""
        s = self.half_length - self.penalty_spot
        return np.array([[-s, 0.0], [0.0, 0.0], [s, 0.0]])

    def polylines(self, step: float = 0.5) -> list[tuple[str, np.ndarray]]:
        """``(label, N x 2 points)`` of every element sampled at most ``step`` metres apart."""
        step = _positive("step", step)
        return [(e.label, e.sample(step)) for e in self.elements()]

    def sampled_points(self, step: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
        """``(points M x 2, labels M)``: every element sampled at most ``step`` metres apart (metres,
        pitch coordinates), one integer label per element (its index in :meth:`elements`): the form
        :func:`glradial.camera.first_guess.first_guess` takes."""
        lines = self.polylines(step)
        labels = np.concatenate([np.full(len(xy), k, dtype=np.int64) for k, (_, xy) in enumerate(lines)])
        return np.concatenate([xy for _, xy in lines]), labels

    def keypoints(self) -> np.ndarray:
        """The 32 keypoints (order of :data:`KEYPOINT_NAMES`), ``32 x 3`` metres with z = 0."""
        hl, hw = self.half_length, self.half_width
        bw, gw = self.box_width / 2, self.goal_area_width / 2
        box_x, goal_x, spot_x = hl - self.box_depth, hl - self.goal_area_depth, hl - self.penalty_spot
        arc_y = math.sqrt(self.circle_radius ** 2 - (self.box_depth - self.penalty_spot) ** 2)
        r = self.circle_radius
        left = [(-hl, hw), (-hl, bw), (-hl, gw), (-hl, -gw), (-hl, -bw), (-hl, -hw), (-goal_x, gw), (-goal_x, -gw),
                (-spot_x, 0.0), (-box_x, bw), (-box_x, arc_y), (-box_x, -arc_y), (-box_x, -bw)]
        middle = [(0.0, hw), (0.0, r), (0.0, -r), (0.0, -hw)]
        right = [(box_x, bw), (box_x, arc_y), (box_x, -arc_y), (box_x, -bw), (spot_x, 0.0), (goal_x, gw),
                 (goal_x, -gw), (hl, hw), (hl, bw), (hl, gw), (hl, -gw), (hl, -bw), (hl, -hw)]
        xy = np.array(left + middle + right + [(-r, 0.0), (r, 0.0)])
        return np.column_stack([xy, np.zeros(len(xy))])


@lru_cache(maxsize=16)
def _elements(p: PitchTemplate) -> tuple[Element, ...]:
    hl, hw = p.half_length, p.half_width
    out = [Element("near_touchline", "segment", (-hl, -hw), (hl, -hw)),
           Element("far_touchline", "segment", (-hl, hw), (hl, hw)),
           Element("left_goal_line", "segment", (-hl, -hw), (-hl, hw)),
           Element("right_goal_line", "segment", (hl, -hw), (hl, hw)),
           Element("halfway_line", "segment", (0.0, -hw), (0.0, hw))]
    for side, s in (("left", -1.0), ("right", 1.0)):
        for name, depth, half in (("box", p.box_depth, p.box_width / 2), ("goal_area", p.goal_area_depth,
                                                                         p.goal_area_width / 2)):
            x0, x1 = s * hl, s * (hl - depth)
            out += [Element(f"{side}_{name}_near", "segment", (x0, -half), (x1, -half)),
                    Element(f"{side}_{name}_front", "segment", (x1, -half), (x1, half)),
                    Element(f"{side}_{name}_far", "segment", (x1, half), (x0, half))]
    out.append(Element("centre_circle", "arc", centre=(0.0, 0.0), radius=p.circle_radius, start=0.0, stop=360.0))
    half = p.arc_half_angle()
    spot = hl - p.penalty_spot
    out.append(Element("left_arc", "arc", centre=(-spot, 0.0), radius=p.circle_radius, start=-half, stop=half))
    out.append(Element("right_arc", "arc", centre=(spot, 0.0), radius=p.circle_radius, start=180.0 - half,
                       stop=180.0 + half))
    return tuple(out)


def default_pitch() -> PitchTemplate:
    """The standard 105 x 68 m pitch."""
    return PitchTemplate()
