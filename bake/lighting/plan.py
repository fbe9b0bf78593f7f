"""Which effects a scene and config call for, and why the others are skipped.

An effect runs only when it can change a colour:

* a light runs when its colour x intensity is not black and its direction / position is usable;
  after the sample points are known, a light that faces no point, or reaches none within its
  range or cone, is skipped as "reaches no surface" (no rays are cast for it);
* ``ao`` runs when ``lighting.ao.enabled`` and there is ambient light for it to darken. AO only
  scales the *ambient* term. When AO is on and nothing else lights the scene (no light, no sky,
  ambient black) the ambient is taken as white, so an AO-only bake shows AO;
* ``sky`` runs when ``lighting.sky.enabled`` and its colour x intensity is not black;
* ``bounces`` runs when ``lighting.bounces.count > 0``, something lights the scene and some
  albedo is not black.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..config import LightingConfig
from ..errors import ConfigError
from ..scene import Light, Scene


@dataclass
class LightSpec:
    index: int
    name: str
    kind: str  # sun | point | spot
    color: np.ndarray  # (3,) linear, colour x intensity
    position: np.ndarray | None
    direction: np.ndarray | None  # unit, light -> scene
    half_angle: float  # sun angular radius, radians
    radius: float
    range: float  # 0 = unbounded
    cos_inner: float
    cos_outer: float
    source: str

    @property
    def label(self) -> str:
        return f"light[{self.index}] {self.kind}" + (f" '{self.name}'" if self.name else "")


@dataclass
class Plan:
    lights: list[LightSpec]
    ambient: np.ndarray  # (3,) effective ambient (linear)
    ao: bool
    sky: bool
    bounces: int
    effects: dict[str, dict] = field(default_factory=dict)  # name -> {ran, reason}
    notes: list[str] = field(default_factory=list)

    @property
    def any_light(self) -> bool:
        return bool(self.lights) or self.sky or bool(np.any(self.ambient > 0))


def _unit(v, what: str) -> np.ndarray | None:
    a = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n == 0:
        return None
    return a / n


def check_config(cfg: LightingConfig) -> None:
    """Range checks for the lighting keys (types are checked by the config loader)."""
    def need(cond: bool, key: str, msg: str) -> None:
        if not cond:
            raise ConfigError(msg, key=f"lighting.{key}")

    need(cfg.target in ("vertex", "triangle", "lightmap"), "target", "must be vertex, triangle or lightmap")
    need(not (cfg.target == "lightmap" and cfg.subdivide), "subdivide",
         "must be false with target = 'lightmap' (the atlas was unwrapped for the triangles as they are)")
    need(cfg.exposure >= 0, "exposure", "must be >= 0")
    need(len(cfg.ambient) == 3 and min(cfg.ambient) >= 0, "ambient", "must be [r, g, b] >= 0")
    need(cfg.threads >= 0, "threads", "must be >= 0 (0 = all cores)")
    need(cfg.ao.samples >= 1, "ao.samples", "must be >= 1")
    need(cfg.ao.distance > 0, "ao.distance", "must be > 0 (a fraction of the bbox diagonal)")
    need(0 <= cfg.ao.strength <= 1, "ao.strength", "must be between 0 and 1")
    need(cfg.sky.samples >= 1, "sky.samples", "must be >= 1")
    need(cfg.sky.intensity >= 0, "sky.intensity", "must be >= 0")
    for k in ("color", "horizon", "ground"):
        c = getattr(cfg.sky, k)
        need(len(c) == 3 and min(c) >= 0, f"sky.{k}", "must be [r, g, b] >= 0")
    need(cfg.shadows.samples >= 1, "shadows.samples", "must be >= 1")
    need(cfg.bounces.count >= 0, "bounces.count", "must be >= 0")
    need(cfg.bounces.samples >= 1, "bounces.samples", "must be >= 1")
    need(cfg.face_cell >= 0, "face_cell", "must be >= 0 (a fraction of the bbox diagonal)")
    need(cfg.face_points_max >= 1, "face_points_max", "must be >= 1")
    need(cfg.max_triangles >= 0, "max_triangles", "must be >= 0")
    need(cfg.subdivide_threshold > 0, "subdivide_threshold", "must be > 0")
    need(cfg.subdivide_levels >= 0, "subdivide_levels", "must be >= 0")
    need(cfg.subdivide_min_edge >= 0, "subdivide_min_edge", "must be >= 0")
    for i, lt in enumerate(cfg.lights):
        need(lt.intensity >= 0, f"lights[{i}].intensity", "must be >= 0")
        need(lt.radius >= 0, f"lights[{i}].radius", "must be >= 0")
        need(0 <= lt.angle < 180, f"lights[{i}].angle", "must be in [0, 180) degrees")
        need(lt.range >= 0, f"lights[{i}].range", "must be >= 0 (0 = unbounded)")
        need(0 <= lt.inner_cone <= lt.outer_cone <= 90, f"lights[{i}].outer_cone",
             "cones must satisfy 0 <= inner_cone <= outer_cone <= 90 degrees")
        if lt.kind in ("sun", "spot"):
            need(_unit(lt.direction, "") is not None, f"lights[{i}].direction", "must not be [0, 0, 0]")


def config_lights(cfg: LightingConfig) -> list[Light]:
    out = []
    for lt in cfg.lights:
        out.append(Light(kind=lt.kind, color=tuple(lt.color), intensity=lt.intensity,
                         position=tuple(lt.position), direction=tuple(lt.direction),
                         angle=lt.angle, radius=lt.radius, range=lt.range or None,
                         inner_cone=math.radians(lt.inner_cone), outer_cone=math.radians(lt.outer_cone),
                         name=getattr(lt, "name", ""), source="config"))
    return out


def make_plan(scene: Scene, cfg: LightingConfig) -> Plan:
    effects: dict[str, dict] = {}
    lights: list[LightSpec] = []
    src = config_lights(cfg)
    if scene.lights:
        if cfg.import_lights:
            src = src + list(scene.lights)
        else:
            effects["imported lights"] = {"ran": False, "reason": f"lighting.import_lights = false: "
                                          f"{len(scene.lights)} light(s) in the model ignored"}
    for i, lt in enumerate(src):
        spec_name = f"light[{i}] {lt.kind}" + (f" '{lt.name}'" if lt.name else "")
        col = np.asarray(lt.color, dtype=np.float64).reshape(3) * float(lt.intensity)
        if lt.kind not in ("sun", "point", "spot"):
            effects[spec_name] = {"ran": False, "reason": f"unknown light kind {lt.kind!r}"}
            continue
        if not np.all(np.isfinite(col)) or not np.any(col > 0):
            effects[spec_name] = {"ran": False, "reason": "colour x intensity is black"}
            continue
        d = _unit(lt.direction, "") if lt.direction is not None else None
        if lt.kind in ("sun", "spot") and d is None:
            effects[spec_name] = {"ran": False, "reason": "no usable direction"}
            continue
        p = None
        if lt.kind in ("point", "spot"):
            if lt.position is None or not np.all(np.isfinite(lt.position)):
                effects[spec_name] = {"ran": False, "reason": "no usable position"}
                continue
            p = np.asarray(lt.position, dtype=np.float64).reshape(3)
        inner = float(lt.inner_cone)
        outer = max(float(lt.outer_cone), inner)
        lights.append(LightSpec(
            index=i, name=lt.name, kind=lt.kind, color=col, position=p, direction=d,
            half_angle=math.radians(max(0.0, float(lt.angle))) / 2.0, radius=max(0.0, float(lt.radius)),
            range=float(lt.range or 0.0), cos_inner=math.cos(min(inner, math.pi / 2)),
            cos_outer=math.cos(min(outer, math.pi / 2)), source=lt.source))
    if not src:
        effects["direct"] = {"ran": False, "reason": "no lights: lighting.lights is empty and the model has none"
                             if cfg.import_lights or not scene.lights else
                             "no lights: lighting.lights is empty (model lights ignored)"}

    notes: list[str] = []
    ambient = np.asarray(cfg.ambient, dtype=np.float64).reshape(3)
    sky = bool(cfg.sky.enabled)
    if not cfg.sky.enabled:
        effects["sky"] = {"ran": False, "reason": "lighting.sky.enabled = false"}
    elif cfg.sky.intensity <= 0 or max(max(cfg.sky.color), max(cfg.sky.horizon), max(cfg.sky.ground)) <= 0:
        sky = False
        effects["sky"] = {"ran": False, "reason": "sky colour x intensity is black"}

    ao = bool(cfg.ao.enabled)
    if not cfg.ao.enabled:
        effects["ao"] = {"ran": False, "reason": "lighting.ao.enabled = false"}
    elif cfg.ao.strength <= 0:
        ao = False
        effects["ao"] = {"ran": False, "reason": "lighting.ao.strength = 0"}
    elif not np.any(ambient > 0):
        if lights or sky:
            ao = False
            effects["ao"] = {"ran": False, "reason": "lighting.ambient is black and AO only darkens "
                                                     "ambient light; set lighting.ambient"}
        else:
            ambient = np.ones(3)
            notes.append("AO is the only effect: ambient taken as white [1, 1, 1]")

    bounces = int(cfg.bounces.count)
    if bounces <= 0:
        effects["bounces"] = {"ran": False, "reason": "lighting.bounces.count = 0"}
        bounces = 0
    elif not (lights or sky or np.any(ambient > 0)):
        effects["bounces"] = {"ran": False, "reason": "nothing lights the scene, so nothing bounces"}
        bounces = 0

    return Plan(lights=lights, ambient=ambient, ao=ao, sky=sky, bounces=bounces, effects=effects,
                notes=notes)
