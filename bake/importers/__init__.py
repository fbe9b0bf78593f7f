"""Importers: OBJ (+MTL) and glTF/GLB into a :class:`~bake.scene.Scene` (polygons kept). The stage is
``stage.py``; the formats are ``obj.py`` (its lines read in ``obj_lines.py``, parsed in ``obj_parse.py``,
its material libraries in ``mtl.py``) and ``gltf.py``."""
