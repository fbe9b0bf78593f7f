"""Write the hand-made seed inputs into fuzz/corpus/<target>/seed-*. Run once; the fuzzer's own
finds are added next to them (``fuzz/run.py --merge``). Deterministic output."""

from __future__ import annotations

import base64
import io
import json
import struct
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

OBJ_SEEDS = {
    "seed-materials.obj": b"""# two materials, a quad and a concave pentagon
mtllib m.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0.5 0.2 0
vt 0 0
vt 1 0
vt 1 1
vn 0 0 1
usemtl red
f 1/1/1 2/2/1 3/3/1 4//1
usemtl tex
f -5 -4 -1 -2 -3
#MTL
newmtl red
Kd 1 0 0
d 0.5
newmtl tex
Kd 0.2
Tr 1
map_Kd -s 1 1 1 tex image.png
""",
    "seed-forms.obj": b"v 0 0 0 1 0 0\r\nv 1 0 0 0 255 0\r\nv 1 1 \\\r\n 0 0 0 255\r\nv 0 1 0 1\r\n"
                      b"vt 0.5\r\nvt 0.1 0.2 0.3\r\ng a b\r\ns off\r\no thing\r\n"
                      b"f 1/1 2/2 3/1\r\nf 1 3 4 # comment\r\nl 1 2\r\np 3\r\nusemtl\r\nf -4 -3 -2\r\n",
    "seed-bad-index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    "seed-nan.obj": b"v 0 0 0\nv 1 nan 0\nv 0 1 1.#IND\nf 1 2 3\n",
}


def _gltf(buffer: bytes, accessors, views, meshes, nodes, extra=None) -> dict:
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}],
           "nodes": nodes, "meshes": meshes, "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(buffer)}]}
    doc.update(extra or {})
    return doc


def triangle_doc(uri: bool = True) -> tuple[dict, bytes]:
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    col = bytes([255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255])
    uv = struct.pack("<6f", 0, 0, 1, 0, 0, 1)
    sp_idx = struct.pack("<H", 1) + b"\0\0"
    sp_val = struct.pack("<3f", 2, 0, 0)
    buf = pos + idx + col + uv + sp_idx + sp_val
    o = [0, len(pos), len(pos) + 8, len(pos) + 20, len(pos) + 44, len(pos) + 48]
    views = [{"buffer": 0, "byteOffset": o[0], "byteLength": 36},
             {"buffer": 0, "byteOffset": o[1], "byteLength": 6},
             {"buffer": 0, "byteOffset": o[2], "byteLength": 12},
             {"buffer": 0, "byteOffset": o[3], "byteLength": 24},
             {"buffer": 0, "byteOffset": o[4], "byteLength": 2},
             {"buffer": 0, "byteOffset": o[5], "byteLength": 12}]
    acc = [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
            "min": [0, 0, 0], "max": [1, 1, 0]},
           {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
           {"bufferView": 2, "componentType": 5121, "normalized": True, "count": 3, "type": "VEC4"},
           {"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC2"},
           {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
            "sparse": {"count": 1, "indices": {"bufferView": 4, "componentType": 5123},
                       "values": {"bufferView": 5}}}]
    meshes = [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 2, "TEXCOORD_0": 3},
                               "indices": 1, "material": 0},
                              {"attributes": {"POSITION": 4}, "mode": 5}]}]
    nodes = [{"children": [1], "rotation": [0, 0.7071068, 0, 0.7071068], "scale": [2, 2, 2]},
             {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1]},
             {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 3, 0]}]
    extra = {"materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0.2, 1]},
                            "alphaMode": "MASK", "doubleSided": True}],
             "extensionsUsed": ["KHR_lights_punctual"],
             "extensions": {"KHR_lights_punctual": {"lights": [{"type": "spot", "intensity": 2,
                                                                "spot": {"outerConeAngle": 0.5}}]}}}
    doc = _gltf(buf, acc, views, meshes, nodes, extra)
    doc["scenes"][0]["nodes"] = [0, 2]
    if uri:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    return doc, buf


def glb(doc: dict, buf: bytes) -> bytes:
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    buf = buf + b"\0" * (-len(buf) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(buf), 0x004E4942) + buf
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def sb3_seeds() -> dict[str, bytes]:
    from bake.scratch import sb3

    data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists={"verts": [1, 2, 3]}),
                             sb3.Target("Sprite1", layer_order=1, lists={"own": ["a"]})])
    bare = io.BytesIO()
    with zipfile.ZipFile(bare, "w") as z:
        z.writestr("project.json", json.dumps({"targets": [{"isStage": True, "name": "Stage", "lists": {},
                                                            "variables": {}, "costumes": [], "sounds": [],
                                                            "blocks": {}}]}))
    return {"seed-written.sb3": data, "seed-bare.sb3": bare.getvalue()}


def main() -> None:
    out = HERE / "corpus"
    for name, data in OBJ_SEEDS.items():
        (out / "obj" / name).write_bytes(data)
    doc, buf = triangle_doc(uri=True)
    (out / "gltf" / "seed-triangle.gltf").write_bytes(json.dumps(doc, indent=1).encode())
    doc, buf = triangle_doc(uri=False)
    (out / "gltf" / "seed-triangle.glb").write_bytes(glb(doc, buf))
    for name, data in sb3_seeds().items():
        (out / "sb3" / name).write_bytes(data)


if __name__ == "__main__":
    main()
