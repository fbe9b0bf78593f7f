"""List layouts for authors' own engines (docs/engines.md "Your own engine").

The export stage makes every mesh list in one layout, the book's (x, y, z interleaved in
``verts``; ``v1, v2, v3, material`` 1-based in ``tris``; ...), and this module rearranges it into
the layout the config asks for:

* **split**: ``export.names.<key>`` given as an array of ``k`` names writes one list per
  component; list ``j`` holds items ``j, j + k, j + 2k, ...`` of each record
  (:data:`SPLITS` says which lists split and into how many);
* **index base**: ``export.index_base = 0`` writes vertex and material numbers from 0 (made by
  ``lists.py`` directly);
* **soup**: ``export.faces = "soup"`` writes each triangle's corner positions instead of vertex
  numbers (made by ``lists.py``), and may be split like the rest.

:func:`join` turns the lists of any layout back into the book's, item for item: the report's
preview, the reader's camera and the round-trip tests read it. The reader sprite reads the split
lists themselves (``bake.scratch.readers.MeshNames``).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from ..scene import ScratchList

# The lists that may be split into one list per component (export.names.<key> = an array of
# names): key -> (components of one record, the record's name), per faces mode. Component j of
# an array of k names holds items j, j + k, j + 2k, ... of each record (:func:`split`);
# ``bake.config.schema.split_problems`` checks a config against it.
SPLITS: dict[str, dict[int, tuple[str, str]]] = {
    "vertices": {3: ("x y z", "vertex")},
    "triangles": {4: ("v1 v2 v3 material", "triangle")},
    "uvs": {6: ("u1 v1 u2 v2 u3 v3", "triangle"), 2: ("u v", "corner")},
    "lightmap_uvs": {6: ("u1 v1 u2 v2 u3 v3", "triangle"), 2: ("u v", "corner")},
    "quads": {5: ("v1 v2 v3 v4 material", "quad")},
}
SOUP_SPLITS: dict[str, dict[int, tuple[str, str]]] = {
    **SPLITS,
    "vertices": {9: ("x1 y1 z1 x2 y2 z2 x3 y3 z3", "triangle"), 3: ("x y z", "corner")},
    "triangles": {},  # one material number per triangle: nothing to split
}


# the book's names of the lists that may be split (ListNames' defaults)
DEFAULT_NAMES = {"vertices": "verts", "triangles": "tris", "uvs": "tri uvs", "lightmap_uvs": "lightmap uvs",
                 "quads": "quads", "materials": "mat colors", "triangle_colors": "tri colors",
                 "vertex_colors": "vert colors", "two_sided": "mat two-sided"}


def names_of(names: Any) -> dict[str, Any]:
    """``export.names`` as a dict (from the config's dataclass or report.json's table), every key
    present (defaults filled in)."""
    if dataclasses.is_dataclass(names):
        names = dataclasses.asdict(names)
    return {**DEFAULT_NAMES, **dict(names or {})}


def placeholder(value: str | list[str]) -> str:
    """The name a list goes by until it is split (one name: its own)."""
    return value if isinstance(value, str) else " + ".join(value)


def split(lists: list[ScratchList], names: Any, faces: str, index_base: int = 1) -> list[ScratchList]:
    """Each list whose role is given an array of names, as one list per component (in the array's
    order, where the list was)."""
    names = names_of(names)
    table = SOUP_SPLITS if faces == "soup" else SPLITS
    out: list[ScratchList] = []
    for lst in lists:
        value = names.get(lst.role) if lst.role else None
        if value is None or isinstance(value, str):
            out.append(lst)
            continue
        k = len(value)
        comps, record = table[lst.role][k]
        labels = comps.split()
        S = lst.stride
        strings = isinstance(lst.values, tuple)
        grid = np.asarray(lst.values, dtype=object if strings else None).reshape(-1, S)
        for j, name in enumerate(value):
            col = grid[:, j::k].ravel()  # component j of each record, in record order
            # every component of a triangle or quad record is a vertex or material number
            base = f" ({index_base}-based)" if lst.role in ("triangles", "quads") else ""
            out.append(dataclasses.replace(
                lst, name=name, values=tuple(col.tolist()) if strings else np.ascontiguousarray(col),
                stride=1, doc=f"{labels[j]}{base} per {record}", pack_stride=0))
    return out


# --------------------------------------------------------------------------- back to the book's layout
def _gather(lists: Mapping[str, list], value: str | list[str]) -> list | None:
    """One list, or the split parts interleaved back into one (None if a part is missing)."""
    if isinstance(value, str):
        return list(lists[value]) if value in lists else None
    parts = [lists.get(n) for n in value]
    if any(p is None for p in parts):
        return None
    k = len(parts)
    n = len(parts[0])
    if any(len(p) != n for p in parts):
        raise ValueError(f"the lists {', '.join(repr(v) for v in value)} differ in length "
                         f"({', '.join(str(len(p)) for p in parts)})")
    out: list = [None] * (n * k)
    # list j holds items j, j + k, ... of each record: interleaving restores the record order
    for j, p in enumerate(parts):
        out[j::k] = list(p)
    return out


def join(lists: Mapping[str, list], names: Any = None, faces: str = "triangles", index_base: int = 1
         ) -> dict[str, list]:
    """The mesh lists of any layout in the book's (role -> items): ``vertices`` x, y, z per vertex
    and ``triangles`` v1, v2, v3, material 1-based; ``uvs`` / ``lightmap_uvs`` six numbers per
    triangle; ``quads`` 1-based; the one-item lists as they are. A soup comes back with one vertex
    per corner (``triangles`` numbers them 1, 2, 3, 4, ...). Roles the lists do not have are
    left out."""
    names = names_of(names)
    out: dict[str, list] = {}
    for role, value in names.items():
        if role not in DEFAULT_NAMES:
            continue
        items = _gather(lists, value)
        if items is not None:
            out[role] = items
    shift = 1 - int(index_base)
    if faces == "soup":
        if "triangles" in out:
            mats = np.asarray(out["triangles"], np.int64) + shift
            t = np.arange(1, 3 * len(mats) + 1, dtype=np.int64).reshape(-1, 3)
            out["triangles"] = np.c_[t, mats.reshape(-1, 1)].ravel().tolist()
    elif shift:
        for role in ("triangles", "quads"):
            if role in out:
                out[role] = (np.asarray(out[role], np.int64) + shift).tolist()
    return out
