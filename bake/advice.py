"""Warnings that need more than one stage's view of a bake, added to the stage records.

Each stage's entry in the registry (``bake.stages``, ``advice``) names its check here; the
pipeline calls it after the stage ran. Each check reads the config, the scene and the records so
far, and says in the stage's record what an author would otherwise find out the hard way:

* **import**: textured materials while ``textures.enabled = false`` -- the model bakes in plain
  material colours (often white) and the textures are not written.
* **bsp**: the splits took the triangle count far past the simplify budget (the budget is not
  changed to count them: how many splits a mesh needs is known only once the tree is built, and
  aiming the simplify stage at it would mean baking both stages over and over; the warning says
  what target would land near the budget); a BSP of a large mesh with no simplify stage.
* **lighting**: a point or spot light from the config without a position (it sits at the origin,
  often inside the model), and any light that reached no surface.
"""

from __future__ import annotations

from .config import Config
from .record import StageRecord
from .scene import Scene

BSP_INFLATION_WARN = 1.25  # BSP output past this x the simplify budget is worth a warning
BSP_LARGE_INPUT = 20_000  # triangles: a painter's engine in Scratch draws a few thousand
SIMPLIFY_MISS = 0.02  # simplify above its target by more than this did not reach it


def unused_textures(cfg: Config, scene: Scene, rec: StageRecord, records: list[StageRecord]) -> None:
    if cfg.textures.enabled:
        return
    textured = [m for m in scene.materials if m.texture is not None or m.texture_data is not None]
    if not textured:
        return
    names = ", ".join(f"'{m.name}'" for m in textured[:3]) + (f" and {len(textured) - 3} more" if len(textured) > 3
                                                              else "")
    white = all(min(m.color[:3]) >= 0.999 for m in textured)
    colour = "white, their base colour" if white else "their base colour"
    rec.warn(f"{len(textured)} material(s) have a texture ({names}) that is not used: textures.enabled = false, so "
             f"they bake in {colour}; set textures.enabled = true to colour each triangle by its texture "
             "(tri colors) and write the textures as lists and costumes (textures.encodings)")


def _simplify_budget(cfg: Config, records: list[StageRecord]) -> tuple[int, str] | None:
    s = cfg.mesh.simplify
    rec = next((r for r in records if r.name == "simplify"), None)
    if rec is None:
        return None
    if s.target_triangles > 0:
        return s.target_triangles, "mesh.simplify.target_triangles"
    if s.target_ratio > 0:
        n_in = int(rec.counts_in.get("triangles", 0))
        return max(1, round(s.target_ratio * n_in)), "mesh.simplify.target_ratio"
    return None


def bsp_size(cfg: Config, scene: Scene, rec: StageRecord, records: list[StageRecord]) -> None:
    n_in = int(rec.counts_in.get("triangles", 0))
    n_out = int(rec.counts_out.get("triangles", scene.n_triangles))
    budget = _simplify_budget(cfg, records)
    if budget is not None:
        asked, key = budget
        if n_out > BSP_INFLATION_WARN * asked:
            said = (f"BSP splits took the triangles from {n_in:,} to {n_out:,}, {n_out / asked:.1f}x the {asked:,} "
                    f"asked by {key}")
            simp = next(r for r in records if r.name == "simplify")
            got = int(simp.counts_out.get("triangles", n_in))
            if got > (1 + SIMPLIFY_MISS) * asked:
                # a lower target cannot help a stage that did not reach this one
                rec.warn(f"{said}; simplify itself stopped at {got:,} (its warnings say why: "
                         "mesh.simplify.defects = \"refuse\", an error_ceiling or seams it kept), so a lower "
                         "target changes nothing there: raise bsp.split_weight to split less")
            else:
                aim = max(1, int(round(asked * asked / max(n_out, 1), -1 if asked < 1000 else -2)))
                rec.warn(f"{said}; to end near {asked:,}, aim simplify lower (at the same inflation, "
                         f"mesh.simplify.target_triangles = {aim}) or raise bsp.split_weight to split less")
    elif not any(r.name == "simplify" for r in records) and n_in > BSP_LARGE_INPUT:
        rec.warn(f"BSP of {n_in:,} triangles ({rec.seconds:.0f} s, {n_out:,} triangles after splits): a painter's "
                 "engine in Scratch draws a few thousand; simplify first (mesh.simplify.enabled = true, "
                 "mesh.simplify.target_triangles = 3000)")


def unplaced_or_dark_lights(cfg: Config, scene: Scene, rec: StageRecord, records: list[StageRecord]) -> None:
    effects = {e.get("name", ""): e for e in rec.effects}
    for i, lt in enumerate(cfg.lighting.lights):
        eff = next((e for n, e in effects.items() if n.startswith(f"light[{i}] ")), None)
        unplaced = lt.kind in ("point", "spot") and f"lighting.lights[{i}].position" not in cfg.given
        dark = eff is not None and not eff.get("ran", True) and "reaches no surface" in str(eff.get("reason", ""))
        if unplaced:
            rec.warn(f"lighting.lights[{i}] ({lt.kind}) has no position, so it sits at {lt.position}"
                     + (" and lights nothing" if dark else "") + f"; set lighting.lights[{i}].position")
        elif dark:
            rec.warn(f"lighting.lights[{i}] ({lt.kind}) lights nothing: it {eff['reason']}")

