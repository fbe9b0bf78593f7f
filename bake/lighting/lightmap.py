"""``lighting.target = "lightmap"``: light every texel of the textures stage's lightmap atlas.

The texel machinery (unwrap, texel samples, splat, dilate, seams) is in ``bake/textures/``
(``lightmap.py`` and the modules it names); this module supplies the light: the lighting stage's
own kernels (lights with soft shadows, sky, ambient x AO, and a final gather of bounced light
from the per-triangle solution) evaluated at texel sample points.
"""

from __future__ import annotations

import dataclasses as _dc
import time
from typing import Callable

import numpy as np

from ..errors import ConfigError, StageError
from ..scene import Scene
from ..textures.lightmap import LightmapJob, Shader, bake
from ..textures.seams import seam_error
from . import color as colmod
from .baker import Baker, LightingResult
from .bounce import BounceRays, field_radiance
from .plan import make_plan
from .rays import Tracer
from .sampling import hash_combine
from .targets import Points


def texel_albedo(scene: Scene, base: np.ndarray | None = None) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
    """For a textured scene: the albedo at sample points (``(points, tri_ids) -> (n, 3)``, stored
    values in [0, 1]): the material colour x mean vertex colour of the point's triangle (as the
    triangle albedo) x the texel of its material's texture at the point's UV (the image the
    project holds, nearest texel, repeat addressing). So a ``"color"`` lightmap carries the
    texture, and the reader's textured filler draws texture and light from the lightmap alone
    (docs/formats-textures.md, "Drawing a textured triangle"). None when no material has a
    texture image or the scene has no UVs. ``base``: the unlit (T, 3+) material x vertex colour when
    ``scene`` carries lit vertex colours (the lighting stage's output)."""
    ts = scene.artefacts.textures
    textures = [t for t in getattr(ts, "textures", []) if getattr(t, "image", None) is not None]
    if not textures or scene.tri_uvs is None or scene.n_triangles == 0:
        return None
    base = np.asarray(base if base is not None else scene.replace(face_albedo=None).triangle_albedo(),
                      np.float64)[:, :3]
    mats = np.asarray(scene.tri_material, np.int64)
    image_of: dict[int, np.ndarray] = {}
    for t in textures:
        for m in t.materials:
            image_of[int(m)] = t.image
    pos, tris, uvs = scene.positions, scene.triangles, scene.tri_uvs

    def albedo(points: np.ndarray, tri_ids: np.ndarray) -> np.ndarray:
        tid = np.asarray(tri_ids, np.int64)
        out = base[tid].copy()
        for m, img in image_of.items():
            sel = np.flatnonzero(mats[tid] == m)
            if not len(sel):
                continue
            t = tid[sel]
            a, b, c = (pos[tris[t, k]] for k in range(3))
            # barycentrics of each point in its triangle (least squares in the triangle's plane)
            e1, e2, d = b - a, c - a, np.asarray(points, np.float64)[sel] - a
            d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
            p1, p2 = (d * e1).sum(1), (d * e2).sum(1)
            den = d11 * d22 - d12 * d12
            den = np.where(np.abs(den) > 0, den, 1.0)
            w1, w2 = (d22 * p1 - d12 * p2) / den, (d11 * p2 - d12 * p1) / den
            uv = (1.0 - w1 - w2)[:, None] * uvs[t, 0] + w1[:, None] * uvs[t, 1] + w2[:, None] * uvs[t, 2]
            H, W = img.shape[:2]
            col = np.floor(uv[:, 0] * W).astype(np.int64) % W
            row = np.floor((1.0 - uv[:, 1]) * H).astype(np.int64) % H  # image row 0 at the top, v up
            out[sel] = out[sel] * (img[row, col, :3].astype(np.float64) / 255.0)
        return out

    return albedo


def light_function(scene: Scene, lighting_cfg, *, output: str = "light",
                   samples_per_texel: int = 1, albedo=None,
                   per_point: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
                   ) -> tuple[Shader, Callable[[], dict]]:
    """A shading function for :func:`bake` built from ``bake/lighting``: at each sample, direct
    light (soft shadows), sky, ambient x AO (the lighting stage's own kernels), plus a final
    gather of bounced light from the lighting stage's per-triangle solution when
    ``lighting.bounces.count > 0``. Each texel averages about ``samples_per_texel`` samples, so
    every ray count (shadows, AO, sky, bounce) is divided by it: a texel gets the rays a vertex
    would. Returns (shade, ray_stats); ``shade`` gives shown RGB in [0, 1]: the light alone
    (``output = "light"``, as on a white surface; the engine multiplies its texture) or lit
    albedo (``"color"``).

    ``albedo``: the base colour per triangle, a (T, 4) array or a provider ``Scene -> (T, 4)``
    (as the lighting stage's ``albedo=``); by default ``scene``'s own base colour, so ``scene``
    must then be *unlit*: after the lighting stage its vertex colours are lit colours, and
    ``Scene.triangle_albedo`` would multiply them in again (albedo applied twice and the light of
    the per-triangle bake multiplied into every texel; :func:`bake_lightmap` passes the unlit
    albedo, see :func:`scene_albedo`).
    """
    full = _dc.replace(lighting_cfg, target="triangle", subdivide=False)
    provider = _provider(albedo)
    k = max(1, int(samples_per_texel))

    def per(n: int) -> int:
        return max(1, -(-int(n) // k))

    cfg = _dc.replace(full, shadows=_dc.replace(full.shadows, samples=per(full.shadows.samples)),
                      ao=_dc.replace(full.ao, samples=per(full.ao.samples)),
                      sky=_dc.replace(full.sky, samples=per(full.sky.samples)),
                      bounces=_dc.replace(full.bounces, samples=per(full.bounces.samples)))
    plan = make_plan(scene, cfg)
    baker = Baker(scene, cfg, plan, provider)
    rad = None
    field_baker = None
    if plan.bounces:
        field_baker = Baker(scene, full, make_plan(scene, full), provider)
        field_baker.run()  # the per-triangle solution the texels gather bounced light from
        ef = field_baker.local_irradiance(field_baker.F.val) + field_baker.F.val["indirect"]
        alb_lin = colmod.decode(field_baker.albedo()[:, :3], cfg.color_space)
        rad = field_radiance(field_baker.tris, alb_lin, None, ef)
    albedo = baker.albedo()

    def shade(points: np.ndarray, normals: np.ndarray, tri_ids: np.ndarray) -> np.ndarray:
        n = len(points)
        key = (hash_combine(np.arange(n, dtype=np.int64), np.int64(0x4C4D)) & np.uint64((1 << 62) - 1)) \
            | np.uint64(1 << 62)
        pts = Points(np.asarray(points, np.float64), np.asarray(normals, np.float64), key,
                     np.asarray(tri_ids, np.int64))
        val, _ = baker.evaluate(pts)
        e = baker.local_irradiance(val)
        if rad is not None:
            st = baker.stat("bounces")
            g, _ = BounceRays(baker.ctx, pts, cfg.bounces.samples, st).gather(rad)
            e = e + g
        if output == "color" and per_point is not None:  # the texture at each point (texel_albedo)
            alb = colmod.decode(np.clip(per_point(points, tri_ids), 0.0, 1.0), cfg.color_space)
        elif output == "color":
            alb = colmod.decode(albedo[np.asarray(tri_ids, np.int64), :3], cfg.color_space)
        else:
            alb = np.ones((n, 3))
        return colmod.shade(alb, e, cfg.exposure, cfg.tonemap, cfg.color_space)

    def ray_stats() -> dict:
        out = {name: {"rays": int(st.rays), "seconds": round(float(st.seconds), 6)}
               for name, st in baker.stats.items()}
        if field_baker is not None:
            out["bounce field (per triangle)"] = {
                "rays": int(sum(st.rays for st in field_baker.stats.values())),
                "seconds": round(float(sum(st.seconds for st in field_baker.stats.values())), 6)}
        return out

    return shade, ray_stats


def _provider(albedo):
    """An albedo override for :class:`bake.lighting.baker.Baker`: ``None``, a provider, or a
    fixed (T, 4) array (wrapped; checked against the scene's triangle count when used)."""
    if albedo is None or callable(albedo):
        return albedo
    arr = np.asarray(albedo, dtype=np.float64)
    return lambda _scene: arr


def scene_albedo(scene: Scene):
    """The unlit albedo for shading ``scene``'s texels: the one the lighting stage used when
    ``scene`` is its output (``LightingResult.albedo``, same triangles), else ``None`` (the
    scene's own base colour)."""
    res = scene.artefacts.lighting
    if isinstance(res, LightingResult) and res.albedo is not None and len(res.albedo) == scene.n_triangles:
        return res.albedo
    return None


def bake_lightmap(scene: Scene, lighting_cfg, *, name: str = "lightmap", albedo=None,
                  texel_base: np.ndarray | None = None) -> tuple[Scene, dict]:
    """``lighting.target = "lightmap"``: light every texel of the textures stage's atlas with the
    lighting stage's kernels (:func:`light_function`, ``lighting.vertex_output`` = "light" or
    "color"), then splat, dilate and stitch (:func:`bake`). The image (RGBA uint8, opaque) goes
    to ``scene.artefacts.lightmap_image`` and out in the same encodings as the material
    textures (``textures.encodings``; names from the textures ``*_name`` keys with
    ``{material}`` = ``name``). ``albedo`` as for :func:`light_function`; by default the unlit
    albedo the lighting stage recorded when ``scene`` is its output (:func:`scene_albedo`).
    Returns (scene, figures for the lighting record)."""
    from ..textures.encode import ENCODINGS, encode_texture

    job = scene.artefacts.lightmap
    if not isinstance(job, LightmapJob):
        raise StageError("lighting.target = 'lightmap' needs the lightmap atlas: set textures.enabled = true "
                         "and textures.lightmap.enabled = true (the textures stage runs before lighting)",
                         key="lighting.target")
    if job.atlas.n_triangles != scene.n_triangles:
        raise StageError(f"the lightmap atlas has {job.atlas.n_triangles} triangles but the scene has "
                         f"{scene.n_triangles} (a stage changed the triangles after the unwrap; "
                         "lighting.subdivide must be off for lightmaps)", key="lighting.subdivide")
    t0 = time.perf_counter()
    output = "light" if getattr(lighting_cfg, "vertex_output", "color") == "light" else "color"
    if albedo is None:
        albedo = scene_albedo(scene)
    per_point = texel_albedo(scene, texel_base) if output == "color" else None
    shade, ray_stats = light_function(scene, lighting_cfg, output=output,
                                      samples_per_texel=job.config.supersample ** 2, albedo=albedo,
                                      per_point=per_point)
    # samples that start inside or behind geometry are pushed out with rays (the same tracer the
    # textures module would build; the lighting package owns Embree)
    tracer = Tracer(scene.positions, scene.triangles, threads=0, scale=scene.scale()) if job.config.push_out else None
    res = bake(scene, job.atlas, shade, job.config, tracer=tracer)
    rgb = np.clip(res.image[:, :, :3], 0.0, 1.0)
    img8 = np.concatenate([np.rint(rgb * 255.0).astype(np.uint8),
                           np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
    tc = job.textures
    fmt = {"material": name}
    enc = encode_texture(name, img8, list_name=tc.list_name.format(**fmt),
                         size_list_name=tc.size_list_name.format(**fmt),
                         textimage_list_name=tc.textimage_list_name.format(**fmt),
                         costume_name=tc.costume_name.format(**fmt), color_format=tc.color_format,
                         first_row=tc.first_row, textimage_alpha="never")
    written = {}
    for e in ENCODINGS:
        if e not in tc.encodings:
            written[e] = "not requested (textures.encodings)"
        elif e == "costume":
            if enc.sizes["costume"]["under_asset_limit"]:
                scene = scene.with_artefacts(costumes=[*(scene.artefacts.costumes or []), enc.costume])
                written[e] = "written"
            else:
                written[e] = "not written: over the 10 MB asset limit"
        else:
            for lst in enc.lists[e]:
                if lst.name in scene.lists:
                    raise ConfigError(f"lightmap list name '{lst.name}' is already used (a material named "
                                      f"'{name}'?); change the textures.*_name keys", key="textures.list_name")
                scene = scene.with_list(lst)
            written[e] = "written"
    q = seam_error(img8[:, :, :3].astype(np.float64) / 255.0, job.atlas, res.seams)
    figs = dict(res.figures)
    figs.update({"output": output, "seam_error_8bit": q["max"], "rays": ray_stats(),
                 "texture_in_lightmap": per_point is not None,
                 "encodings": {e: {**enc.sizes[e], "written": written[e]} for e in ENCODINGS},
                 "seconds": round(time.perf_counter() - t0, 6)})
    scene = scene.with_artefacts(lightmap_image=img8).with_artefacts(lightmap_encoded=enc)
    return scene, figs
