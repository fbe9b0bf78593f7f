"""The block builder: the encoding it writes is well formed, names are checked, and the real
Scratch VM executes the blocks with the meaning the builder gives them."""

from __future__ import annotations

import json
import math

import pytest

from bake.scratch import sb3
from bake.scratch import blocks as B
from vm_harness import call, vm  # noqa: F401  (vm is a fixture)


def _project(builder_fn, *, variables=(), lists=(), stage_lists=None, costumes=None, compact=False):
    scope = B.Scope("S", variables=list(variables), lists=list(lists), stage_lists=list(stage_lists or {}))
    b = B.Builder(scope, compact=compact)
    builder_fn(b)
    blocks = b.build()
    target = sb3.Target("S", variables={v: 0 for v in variables}, lists={n: [] for n in lists},
                        blocks=blocks, layer_order=1, costumes=costumes or [])
    stage = sb3.Target("Stage", is_stage=True, lists=dict(stage_lists or {}))
    return blocks, stage, target


# --------------------------------------------------------------------------- encoding
def _check_links(blocks):
    """Every reference between blocks is consistent (what the VM's deserializer relies on)."""
    for bid, b in blocks.items():
        if isinstance(b, list):
            continue
        assert set(b) >= {"opcode", "parent"}
        # written only when they say something (blocks._compact)
        assert b.get("shadow", True) is True and b.get("topLevel", True) is True
        assert b.get("inputs", 1) != {} and b.get("fields", 1) != {}
        leaf = "next" not in b  # a reporter or shadow: nothing follows it, nor is it in a stack
        b = {"inputs": {}, "fields": {}, "shadow": False, "topLevel": False, "next": None, **b}
        if leaf:
            p = blocks[b["parent"]]
            assert p.get("next") != bid and not any(
                isinstance(v, list) and v[0] == 2 and v[1] == bid and k.startswith("SUBSTACK")
                for k, v in p.get("inputs", {}).items()), f"{b['opcode']} is in a stack but has no next"
        if b["next"] is not None:
            assert blocks[b["next"]]["parent"] == bid
        if b["parent"] is None:
            assert b["topLevel"] and "x" in b and "y" in b
        else:
            p = blocks[b["parent"]]
            assert p.get("next") == bid or any(isinstance(v, list) and bid in v[1:] for v in p.get("inputs", {}).values()), \
                f"{b['opcode']} is not linked from its parent {p['opcode']}"
        for name, inp in b["inputs"].items():
            assert inp[0] in (1, 2, 3)
            for ref in inp[1:]:
                if isinstance(ref, str):
                    assert blocks[ref]["parent"] == bid, (b["opcode"], name)
                elif isinstance(ref, list):
                    assert ref[0] in (4, 5, 6, 7, 8, 9, 10, 12, 13)


def test_encoding_is_linked_and_deterministic():
    def build(b):
        b.define("f %s and %b", ["x", "ok"], [
            B.if_(B.bool_arg("ok"), [B.set_var("v", B.arg("x") * 2)], [B.change_var("v", 1)]),
            B.repeat(3, [B.add_to("l", B.join("a", B.var("v")))]),
            B.repeat(2, []),
        ])
        b.when_flag([B.call("f %s and %b", 5, B.gt(B.var("v"), 1)), B.switch_costume(B.letter_of(1, "xy"))])
    b1, _, _ = _project(build, variables=["v"], lists=["l"])
    b2, _, _ = _project(build, variables=["v"], lists=["l"])
    assert json.dumps(b1) == json.dumps(b2)
    _check_links(b1)
    protos = [b for b in b1.values() if b["opcode"] == "procedures_prototype"]
    assert len(protos) == 1 and protos[0]["shadow"] is True
    m = protos[0]["mutation"]
    assert json.loads(m["argumentnames"]) == ["x", "ok"] and m["warp"] == "true"
    ids = json.loads(m["argumentids"])
    call_block = next(b for b in b1.values() if b["opcode"] == "procedures_call")
    assert set(call_block["inputs"]) == set(ids) and call_block["mutation"]["proccode"] == "f %s and %b"
    empty = [b for b in b1.values() if b["opcode"] == "control_repeat" and "SUBSTACK" not in b.get("inputs", {})]
    assert len(empty) == 1  # an empty C-block has no substack input, as Scratch saves it


@pytest.mark.parametrize("fn, message", [
    (lambda b: b.when_flag([B.set_var("nope", 1)]), "variable 'nope' is not declared"),
    (lambda b: b.when_flag([B.add_to("nolist", 1)]), "list 'nolist' is not declared"),
    (lambda b: b.when_flag([B.set_var("v", B.arg("x"))]), "outside a custom block"),
    (lambda b: (b.define("f %s", ["x"], []), b.when_flag([B.call("f %s", 1, 2)])), "takes 1 arguments"),
    (lambda b: b.when_flag([B.call("g")]), "not defined"),
    (lambda b: b.define("f %s", ["x", "y"], []), "2 names"),
    (lambda b: (b.define("f", [], []), b.define("f", [], [])), "defined twice"),
    (lambda b: b.when_flag([B.set_var("v", True)]), "booleans are not Scratch literals"),
    (lambda b: b.when_flag([B.set_pen_color(16711680)]), "colour literal"),
    (lambda b: b.when_flag([B.if_(B.var("v"), [])]), "boolean input needs a boolean"),
    (lambda b: b.when_flag([B.var("v")]), "not a stack block"),
    (lambda b: b.when_flag([B.set_var("v", float("nan"))]), "not a finite number"),
    (lambda b: b.define("f %b", ["x"], [B.set_var("v", B.arg("x"))]), "wrong type"),
])
def test_builder_refuses_what_scratch_would_get_wrong(fn, message):
    with pytest.raises(B.BlockError, match=message):
        _project(fn, variables=["v"])


def test_block_ids_are_short_unique_and_avoid_variable_ids():
    blocks, _, target = _project(lambda b: b.when_flag([B.change_var("v", 1)] * 300), variables=["v"])
    assert len(blocks) == 301 and all(len(k) == B.BLOCK_ID_LENGTH for k in blocks)
    tj = target.to_json()
    assert not set(blocks) & set(tj["variables"])


# --------------------------------------------------------------------------- meaning, in the VM
def _compacted(blocks: dict) -> dict:
    """What the compact encoding (packed projects, issue 41) should make of plainly built blocks,
    worked out from them: the n-th block's id is the n-th counter id ("!", "#", ... in
    sb3.ID_ALPHABET order, then two characters), a leaf (a block without ``next``: reporters and
    shadows) has no ``parent``, and a reporter in an input has no shadow under it (neither a
    literal nor a menu block)."""
    alphabet = sb3.ID_ALPHABET
    names = [c for c in alphabet] + [a + b for a in alphabet for b in alphabet]
    menus = {inp[2] for b in blocks.values() for inp in b.get("inputs", {}).values()
             if inp[0] == 3 and isinstance(inp[2], str)}
    new = dict(zip([bid for bid in blocks if bid not in menus], names))
    out = {}
    for bid, b in blocks.items():
        if bid in menus:
            continue
        b = json.loads(json.dumps(b))
        if "next" not in b:
            b.pop("parent", None)
        for key in ("next", "parent"):
            if b.get(key) is not None:
                b[key] = new[b[key]]
        for name, inp in b.get("inputs", {}).items():
            if inp[0] == 3:
                inp = [2, inp[1]]
            b["inputs"][name] = [new[x] if isinstance(x, str) else x for x in inp]
        out[new[bid]] = b
    return out


def test_compact_blocks_are_the_plain_blocks_lighter():
    """The compact encoding changes only what the runtime never reads: the ids (shortest counter
    ids), a leaf's parent and the shadow under a reporter; the scripts are the same."""
    build, variables, lists, costumes = _semantics_build()
    plain, _, _ = _project(build, variables=variables, lists=lists, costumes=costumes)
    compact, _, target = _project(build, variables=variables, lists=lists, costumes=costumes, compact=True)
    _check_links(plain)
    assert compact == _compacted(plain)
    assert len(sb3.dumps(compact)) < len(sb3.dumps(plain))
    assert not set(compact) & set(target.to_json()["variables"])


def test_vm_runs_compact_blocks_as_built(tmp_path, vm):
    p = _semantics_project(tmp_path, compact=True)
    res = vm({"load": str(p), "runs": [call("S", "main %s %s", 5, 2.5, lists=["out"])]})
    assert res["validation"] == [{"file": str(p), "ok": True, "projectVersion": 3}]
    got = [math.inf if g is None else g for g in res["runs"][0]["lists"]["out"]]
    assert got == EXPECTED


def test_data_ids_keep_clear_of_taken_ids():
    var_ids, list_ids = sb3.data_ids("S", ["a", "b"], ["c"], length=4)
    taken = [var_ids["b"], list_ids["c"]]
    v2, l2 = sb3.data_ids("S", ["a", "b"], ["c"], length=4, taken=taken)
    assert v2["a"] == var_ids["a"]  # only the ids that collide are derived again
    assert not set(v2.values()) & set(taken) and not set(l2.values()) & set(taken)
    assert len(set(v2.values()) | set(l2.values())) == 3


def test_minimal_costume_is_what_scratch_parser_requires():
    asset = sb3.Asset(sb3.SPRITE_SVG, "svg")
    c = sb3.Costume("A", asset, 1, (1.0, 1.0), minimal=True).to_json()
    assert c == {"name": "A", "assetId": asset.md5, "dataFormat": "svg"}
    full = sb3.Costume("A", asset, 1, (1.0, 1.0)).to_json()
    assert full["md5ext"] == f"{asset.md5}.svg" and full["rotationCenterX"] == 1.0


def _semantics_project(tmp_path, compact=False):
    build, variables, lists, costumes = _semantics_build()
    blocks, stage, target = _project(build, variables=variables, lists=lists, costumes=costumes, compact=compact)
    target.lists["words"] = ["alpha", "beta"]
    data, _ = sb3.write_sb3([stage, target])
    p = tmp_path / "semantics.sb3"
    p.write_bytes(data)
    return p


def _semantics_build():
    """A sprite whose custom block exercises operators, lists, control flow, arguments, nested and
    recursive calls, costumes and the pen. Expected values are worked out by hand below."""
    names = ["Alpha", "alpha", "7", "b"]
    costumes = [sb3.Costume(n, sb3.Asset(sb3.SPRITE_SVG, "svg"), 1, (1, 1)) for n in names]
    v, out = B.var, "out"

    def build(b):
        b.define("fact %s", ["n"], [
            B.if_(B.lt(B.arg("n"), 2), [B.set_var("acc", 1)], [
                B.call("fact %s", B.arg("n") - 1),
                B.set_var("acc", B.mul(v("acc"), B.arg("n"))),
            ]),
        ])
        b.define("main %s %s", ["a", "b"], [
            B.delete_all(out),
            B.add_to(out, B.arg("a") + B.arg("b")),                 # 7.5 (text args added as numbers)
            B.add_to(out, B.join(B.arg("a"), B.arg("b"))),          # "52.5"
            B.add_to(out, B.mod(-7, 3)),                             # 2 (floored)
            B.add_to(out, B.round_(2.5)),                            # 3
            B.add_to(out, B.round_(-2.5)),                           # -2 (Math.round)
            B.add_to(out, B.floor(-0.5)),                            # -1
            B.add_to(out, B.mathop("sin", 30)),                      # 0.5 (degrees, 10 decimals)
            B.add_to(out, B.div(1, 0)),                              # Infinity
            B.add_to(out, B.letter_of(2, "héllo")),                  # "é"
            B.add_to(out, B.length_of("héllo")),                     # 5
            B.if_(B.eq("A", "a"), [B.add_to(out, "eq-ci")]),         # = ignores case
            B.if_(B.lt("10", "9"), [], [B.add_to(out, "numeric")]),  # numbers compare as numbers
            B.add_to(out, B.item_number("ALPHA", "words")),          # 1: item # of is case-insensitive
            B.switch_costume("alpha"), B.add_to(out, B.costume_number()),   # 2: names match exactly
            B.switch_costume("7"), B.add_to(out, B.costume_number()),       # 3: a name before a number
            B.switch_costume(B.join("", 4)), B.add_to(out, B.costume_number()),  # 4: "4" is no name
            B.set_var("i", 0),
            B.repeat_until(B.gt(v("i"), 4), [B.change_var("i", 2)]),
            B.add_to(out, v("i")),                                   # 6
            B.call("fact %s", 6), B.add_to(out, v("acc")),           # 720 (recursion)
            B.replace_item("words", 2, "B"), B.insert_at("words", 1, "z"), B.delete_item("words", 2),  # z, B
            B.add_to(out, B.list_length("words")),                   # 2
            B.add_to(out, B.item("last", "words")),                  # "B"
            B.if_(B.and_(B.list_contains("words", "b"), B.not_(B.or_(B.gt(1, 2), B.lt(3, 2)))),  # "b" = "B"
                  [B.add_to(out, "bool")]),
            B.set_pen_color(B.join("#", "ff8000")), B.set_pen_size(3),
            B.goto_xy(0, 0), B.pen_down(), B.goto_xy(10, -5), B.pen_up(), B.goto_xy(50, 50),
        ])

    return build, ["i", "acc"], ["out", "words"], costumes


EXPECTED = [7.5, "52.5", 2, 3, -2, -1, 0.5, math.inf, "é", 5, "eq-ci", "numeric", 1, 2, 3, 4, 6, 720, 2, "B",
            "bool"]


def test_vm_runs_blocks_as_built(tmp_path, vm):
    p = _semantics_project(tmp_path)
    res = vm({"load": str(p), "runs": [call("S", "main %s %s", 5, 2.5, lists=["out"], pen=True)]})
    assert res["validation"] == [{"file": str(p), "ok": True, "projectVersion": 3}]
    run = res["runs"][0]
    got = run["lists"]["out"]
    got = [math.inf if g is None else g for g in got]  # JSON has no Infinity: the harness prints null
    assert got == EXPECTED
    # the pen: one dot where the pen went down, one stroke to (10, -5), orange, size 3; none after pen up
    # (the pen keeps its colour as HSV, so a channel can come back 1 off: 128 -> 127)
    assert [s[:5] for s in run["pen"]] == [[0, 0, 0, 0, 3], [0, 0, 10, -5, 3]]
    for s in run["pen"]:
        assert all(abs(a - b) <= 1 for a, b in zip(s[5:], (255, 128, 0, 255))), s
    assert run["blocks"] > 60 and run["done"]
