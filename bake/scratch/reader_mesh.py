"""Small pieces of the reader's mesh blocks that several parts share (the filler, the textured
filler, the BVH view): how a triangle's numbers are read in the layout the bake wrote
(``readers.MeshNames``, bake/scratch/layout.py)."""

from __future__ import annotations

from typing import Any

from .blocks import add, item


def index(m: Any, rep: Any) -> Any:
    """A vertex or material number as a 1-based item number (0-based lists: + 1)."""
    return rep if m.index_base == 1 else add(rep, 1)


def triangle_walk(m: Any) -> str:
    """How ``_b`` walks the triangles: ``book`` the items of one list of records (4 a
    triangle), ``split`` the triangle's number in per-corner lists, ``soup`` its corners'
    projected points (3 a triangle)."""
    return "soup" if m.soup else "book" if isinstance(m.tris, str) else "split"


def colour(r: Any, t: Any, material: Any) -> Any:
    """The colour number of triangle t (``material``: the reporter of its 1-based material): its
    own (``tri colors``), its material's (``mat colors``), or grey."""
    m = r.spec.mesh
    if m.tri_colors:
        return item(t, r.lst(m.tri_colors))
    if m.mat_colors:
        return item(material, r.lst(m.mat_colors))
    return "#808080"
