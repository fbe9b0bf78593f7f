"""Importers: OBJ (+MTL) and glTF/GLB into a :class:`~bake.scene.Scene` (polygons kept). The stage is
``stage.py``; the formats are ``obj.py`` and ``gltf.py``."""
