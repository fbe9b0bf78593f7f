"""BSP trees for painter's order (docs/formats-bsp.md).

- ``stage.py``: the ``bsp`` stage, ``stage(scene, BSPConfig) -> (Scene, StageRecord)``;
- ``merge.py``: coplanar neighbours merged into convex source polygons;
- ``split.py``: convex fragments and robust, vectorised plane splitting;
- ``build.py``: the level-by-level builder (priority peeling and leaves, candidate planes);
- ``encode.py``: the tree as the ``bsp nodes`` / ``bsp planes`` lists and the triangle order;
- ``traverse.py``: the reference walk over the exported lists (what the Scratch script does);
- ``verify.py``: the proof of order against the z-buffer rasterizer (``bake/render.py``).
"""
