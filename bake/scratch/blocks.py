"""A small builder for Scratch 3 blocks (project.json ``blocks`` of one target).

Scripts are written as Python expressions and compiled into the sb3 block encoding described in
shared/docs/scratch.md section 1 ("Blocks encoding"):

* a block is ``{opcode, next, parent, inputs, fields, shadow, topLevel, x?, y?, mutation?}``, written
  without ``shadow``/``topLevel`` when false and ``inputs``/``fields`` when empty (:func:`_compact`);
* an input is ``[1, shadow]``, ``[2, block]`` or ``[3, reporter, shadow]``; literal shadows are
  compressed primitives ``[4..8, "num"]``, ``[9, "#rrggbb"]``, ``[10, "text"]``; a variable or list
  reporter in an input is ``[12, name, id]`` / ``[13, name, id]``;
* a custom block is a ``procedures_definition`` whose ``custom_block`` input holds a shadow
  ``procedures_prototype`` carrying the mutation (proccode, argument ids/names/defaults, warp);
  calls are ``procedures_call`` blocks with the same proccode and argument ids as input names.

Example::

    from bake.scratch import blocks as B
    s = B.Scope("Reader", variables=["i"], lists=["out"])
    b = B.Builder(s)
    i = B.var("i")
    b.define("count to %s", ["n"], [
        B.delete_all("out"),
        B.set_var("i", 1),
        B.repeat(B.arg("n"), [B.add_to("out", i), B.change_var("i", 1)]),
    ])
    b.when_flag([B.call("count to %s", 10)])
    target_blocks = b.build()

Names are checked when the scripts are built: a variable, list, argument or custom block that is
not declared is an error (a typo would otherwise make Scratch silently create a new variable).
Ids are deterministic (derived from the target name and the block's position), so the same scripts
give byte-identical project.json.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence, Union

from .sb3 import ID_ALPHABET, stable_id

# shadow kinds (compressed primitive codes)
NUM, POS, WHOLE, INT, ANGLE, COLOUR, TEXT = 4, 5, 6, 7, 8, 9, 10
BOOL = "bool"  # boolean input: no shadow
STACK = "stack"  # substack input
COSTUME_MENU = "costume"  # menu shadow block looks_costume


class BlockError(ValueError):
    """A script that cannot be built (unknown name, wrong argument count, bad literal)."""


# --------------------------------------------------------------------------- nodes
class Node:
    """A block: reporter, boolean or stack block."""

    shape = "stack"

    def __init__(self, opcode: str, inputs: dict[str, tuple[Any, Any]] | None = None,
                 fields: dict[str, Any] | None = None, mutation: dict[str, Any] | None = None):
        self.opcode = opcode
        self.inputs = inputs or {}  # name -> (value, kind)
        self.fields = fields or {}  # name -> FieldValue
        self.mutation = mutation

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.opcode})"


class Reporter(Node):
    shape = "reporter"

    # arithmetic sugar: a + b -> operator_add(a, b), etc.
    def __add__(self, o): return add(self, o)
    def __radd__(self, o): return add(o, self)
    def __sub__(self, o): return sub(self, o)
    def __rsub__(self, o): return sub(o, self)
    def __mul__(self, o): return mul(self, o)
    def __rmul__(self, o): return mul(o, self)
    def __truediv__(self, o): return div(self, o)
    def __rtruediv__(self, o): return div(o, self)
    def __mod__(self, o): return mod(self, o)
    def __rmod__(self, o): return mod(o, self)
    def __neg__(self): return sub(0, self)


class Boolean(Node):
    shape = "boolean"

    def __and__(self, o): return and_(self, o)
    def __or__(self, o): return or_(self, o)
    def __invert__(self): return not_(self)


class VarRef(Reporter):
    def __init__(self, name: str):
        super().__init__("data_variable")
        self.name = name


class ListRef(Reporter):
    def __init__(self, name: str):
        super().__init__("data_listcontents")
        self.name = name


class ArgRef(Reporter):
    def __init__(self, name: str):
        super().__init__("argument_reporter_string_number")
        self.name = name


class BoolArgRef(Boolean):
    def __init__(self, name: str):
        super().__init__("argument_reporter_boolean")
        self.name = name


@dataclass
class VarField:
    name: str


@dataclass
class ListField:
    name: str


@dataclass
class Menu:
    """A field with a fixed value (``[value, null]``)."""
    value: str


Value = Union[Node, int, float, str]
Stack = Sequence[Node]


# --------------------------------------------------------------------------- reporters
def var(name: str) -> VarRef:
    return VarRef(name)


def list_contents(name: str) -> ListRef:
    return ListRef(name)


def arg(name: str) -> ArgRef:
    """A custom block's number/text argument (use inside its definition)."""
    return ArgRef(name)


def bool_arg(name: str) -> BoolArgRef:
    return BoolArgRef(name)


def _num2(opcode: str, a: Value, b: Value) -> Reporter:
    return Reporter(opcode, {"NUM1": (a, NUM), "NUM2": (b, NUM)})


def add(a: Value, b: Value) -> Reporter: return _num2("operator_add", a, b)
def sub(a: Value, b: Value) -> Reporter: return _num2("operator_subtract", a, b)
def mul(a: Value, b: Value) -> Reporter: return _num2("operator_multiply", a, b)
def div(a: Value, b: Value) -> Reporter: return _num2("operator_divide", a, b)
def mod(a: Value, b: Value) -> Reporter: return _num2("operator_mod", a, b)


def round_(a: Value) -> Reporter:
    return Reporter("operator_round", {"NUM": (a, NUM)})


MATHOPS = ("abs", "floor", "ceiling", "sqrt", "sin", "cos", "tan", "asin", "acos", "atan", "ln", "log",
           "e ^", "10 ^")


def mathop(op: str, a: Value) -> Reporter:
    if op not in MATHOPS:
        raise BlockError(f"unknown math operation {op!r} (one of {', '.join(MATHOPS)})")
    return Reporter("operator_mathop", {"NUM": (a, NUM)}, {"OPERATOR": Menu(op)})


def floor(a: Value) -> Reporter: return mathop("floor", a)
def abs_(a: Value) -> Reporter: return mathop("abs", a)
def sqrt(a: Value) -> Reporter: return mathop("sqrt", a)


def join(a: Value, b: Value) -> Reporter:
    return Reporter("operator_join", {"STRING1": (a, TEXT), "STRING2": (b, TEXT)})


def letter_of(i: Value, s: Value) -> Reporter:
    return Reporter("operator_letter_of", {"LETTER": (i, WHOLE), "STRING": (s, TEXT)})


def length_of(s: Value) -> Reporter:
    return Reporter("operator_length", {"STRING": (s, TEXT)})


def lt(a: Value, b: Value) -> Boolean:
    return Boolean("operator_lt", {"OPERAND1": (a, TEXT), "OPERAND2": (b, TEXT)})


def gt(a: Value, b: Value) -> Boolean:
    return Boolean("operator_gt", {"OPERAND1": (a, TEXT), "OPERAND2": (b, TEXT)})


def eq(a: Value, b: Value) -> Boolean:
    """Scratch ``=``: numeric if both sides look like numbers, else case-insensitive text."""
    return Boolean("operator_equals", {"OPERAND1": (a, TEXT), "OPERAND2": (b, TEXT)})


def and_(a: Boolean, b: Boolean) -> Boolean:
    return Boolean("operator_and", {"OPERAND1": (a, BOOL), "OPERAND2": (b, BOOL)})


def or_(a: Boolean, b: Boolean) -> Boolean:
    return Boolean("operator_or", {"OPERAND1": (a, BOOL), "OPERAND2": (b, BOOL)})


def not_(a: Boolean) -> Boolean:
    return Boolean("operator_not", {"OPERAND": (a, BOOL)})


def item(i: Value, lst: str) -> Reporter:
    return Reporter("data_itemoflist", {"INDEX": (i, INT)}, {"LIST": ListField(lst)})


def item_number(x: Value, lst: str) -> Reporter:
    """``item # of x in list`` (case-insensitive, see scratch.md 4a)."""
    return Reporter("data_itemnumoflist", {"ITEM": (x, TEXT)}, {"LIST": ListField(lst)})


def list_length(lst: str) -> Reporter:
    return Reporter("data_lengthoflist", {}, {"LIST": ListField(lst)})


def list_contains(lst: str, x: Value) -> Boolean:
    return Boolean("data_listcontainsitem", {"ITEM": (x, TEXT)}, {"LIST": ListField(lst)})


def costume_number() -> Reporter:
    return Reporter("looks_costumenumbername", {}, {"NUMBER_NAME": Menu("number")})


def costume_name() -> Reporter:
    return Reporter("looks_costumenumbername", {}, {"NUMBER_NAME": Menu("name")})


def x_position() -> Reporter:
    return Reporter("motion_xposition")


def y_position() -> Reporter:
    return Reporter("motion_yposition")


# --------------------------------------------------------------------------- stack blocks
def set_var(name: str, v: Value) -> Node:
    return Node("data_setvariableto", {"VALUE": (v, TEXT)}, {"VARIABLE": VarField(name)})


def change_var(name: str, v: Value) -> Node:
    return Node("data_changevariableby", {"VALUE": (v, NUM)}, {"VARIABLE": VarField(name)})


def add_to(lst: str, v: Value) -> Node:
    return Node("data_addtolist", {"ITEM": (v, TEXT)}, {"LIST": ListField(lst)})


def delete_all(lst: str) -> Node:
    return Node("data_deletealloflist", {}, {"LIST": ListField(lst)})


def delete_item(lst: str, i: Value) -> Node:
    return Node("data_deleteoflist", {"INDEX": (i, INT)}, {"LIST": ListField(lst)})


def insert_at(lst: str, i: Value, v: Value) -> Node:
    return Node("data_insertatlist", {"ITEM": (v, TEXT), "INDEX": (i, INT)}, {"LIST": ListField(lst)})


def replace_item(lst: str, i: Value, v: Value) -> Node:
    return Node("data_replaceitemoflist", {"INDEX": (i, INT), "ITEM": (v, TEXT)}, {"LIST": ListField(lst)})


def repeat(n: Value, body: Stack) -> Node:
    return Node("control_repeat", {"TIMES": (n, WHOLE), "SUBSTACK": (list(body), STACK)})


def repeat_until(cond: Boolean, body: Stack) -> Node:
    return Node("control_repeat_until", {"CONDITION": (cond, BOOL), "SUBSTACK": (list(body), STACK)})


def while_(cond: Boolean, body: Stack) -> Node:
    return Node("control_while", {"CONDITION": (cond, BOOL), "SUBSTACK": (list(body), STACK)})


def forever(body: Stack) -> Node:
    return Node("control_forever", {"SUBSTACK": (list(body), STACK)})


def if_(cond: Boolean, body: Stack, else_: Stack | None = None) -> Node:
    if else_ is None:
        return Node("control_if", {"CONDITION": (cond, BOOL), "SUBSTACK": (list(body), STACK)})
    return Node("control_if_else", {"CONDITION": (cond, BOOL), "SUBSTACK": (list(body), STACK),
                                    "SUBSTACK2": (list(else_), STACK)})


STOP_OPTIONS = ("all", "this script", "other scripts in sprite")


def stop(option: str = "this script") -> Node:
    if option not in STOP_OPTIONS:
        raise BlockError(f"unknown stop option {option!r}")
    hasnext = "true" if option == "other scripts in sprite" else "false"
    return Node("control_stop", {}, {"STOP_OPTION": Menu(option)},
                {"tagName": "mutation", "children": [], "hasnext": hasnext})


def wait(seconds: Value) -> Node:
    return Node("control_wait", {"DURATION": (seconds, POS)})


def goto_xy(x: Value, y: Value) -> Node:
    return Node("motion_gotoxy", {"X": (x, NUM), "Y": (y, NUM)})


def switch_costume(c: Value) -> Node:
    """``switch costume to``: a text value is looked up by name first, exactly (``===``)."""
    return Node("looks_switchcostumeto", {"COSTUME": (c, COSTUME_MENU)})


def hide() -> Node: return Node("looks_hide")
def show() -> Node: return Node("looks_show")
def pen_clear() -> Node: return Node("pen_clear")
def pen_down() -> Node: return Node("pen_penDown")
def pen_up() -> Node: return Node("pen_penUp")


def set_pen_color(c: Value) -> Node:
    """``set pen color to (c)``: a colour number (ARGB, alpha 0 = opaque) or ``#rrggbb``."""
    return Node("pen_setPenColorToColor", {"COLOR": (c, COLOUR)})


def set_pen_size(s: Value) -> Node:
    return Node("pen_setPenSizeTo", {"SIZE": (s, NUM)})


class Call(Node):
    def __init__(self, proccode: str, args: Sequence[Value]):
        super().__init__("procedures_call")
        self.proccode = proccode
        self.args = list(args)


def call(proccode: str, *args: Value) -> Call:
    return Call(proccode, args)


# --------------------------------------------------------------------------- scope
@dataclass
class Scope:
    """The names a target's scripts may use: its own variables/lists and the stage's.

    ``variables``/``lists`` map a name to its id (or give names only: ids are derived the way
    :class:`bake.scratch.sb3.Target` derives them)."""

    target: str
    variables: dict[str, str] | Iterable[str] = field(default_factory=dict)
    lists: dict[str, str] | Iterable[str] = field(default_factory=dict)
    stage_variables: dict[str, str] | Iterable[str] = field(default_factory=dict)
    stage_lists: dict[str, str] | Iterable[str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        def ids(names, owner, kind):
            if isinstance(names, dict):
                return dict(names)
            return {n: stable_id(owner, kind, n) for n in names}
        self.variables = ids(self.variables, self.target, "var")
        self.lists = ids(self.lists, self.target, "list")
        self.stage_variables = ids(self.stage_variables, "Stage", "var")
        self.stage_lists = ids(self.stage_lists, "Stage", "list")

    def var_id(self, name: str) -> str:
        for d in (self.variables, self.stage_variables):
            if name in d:
                return d[name]
        raise BlockError(f"{self.target}: variable {name!r} is not declared")

    def list_id(self, name: str) -> str:
        for d in (self.lists, self.stage_lists):
            if name in d:
                return d[name]
        raise BlockError(f"{self.target}: list {name!r} is not declared")


# --------------------------------------------------------------------------- builder
def format_number(x: float | int) -> str:
    if isinstance(x, bool):
        raise BlockError("booleans are not Scratch literals; use a comparison")
    if isinstance(x, int):
        return str(x)
    if not math.isfinite(x):
        raise BlockError(f"{x!r} is not a finite number")
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _literal(v: Any) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (int, float)):
        return format_number(v)
    raise BlockError(f"cannot use {v!r} as a Scratch literal")


_PROC_ARG = re.compile(r"%[sb]")
BLOCK_ID_LENGTH = 3


@dataclass
class _Proc:
    proccode: str
    arg_names: list[str]
    arg_ids: list[str]
    arg_kinds: list[str]  # "s" | "b"
    warp: bool


class Builder:
    """Collects the scripts of one target and compiles them to its ``blocks`` dict."""

    def __init__(self, scope: Scope, *, compact: bool = False):
        self.scope = scope
        self.compact = compact
        self._procs: dict[str, _Proc] = {}
        self._scripts: list[tuple[str, Any]] = []  # (kind, payload)

    # ---- declaring scripts
    def define(self, proccode: str, arg_names: Sequence[str], body: Stack, *, warp: bool = True) -> None:
        """``define <proccode>``: ``%s`` marks a number/text argument, ``%b`` a boolean one, in
        the order of ``arg_names``. ``warp`` = "run without screen refresh"."""
        kinds = [m[1] for m in _PROC_ARG.findall(proccode)]
        if len(kinds) != len(arg_names):
            raise BlockError(f"{proccode!r}: {len(kinds)} argument slots but {len(arg_names)} names")
        if len(set(arg_names)) != len(arg_names):
            raise BlockError(f"{proccode!r}: argument names must differ")
        if proccode in self._procs:
            raise BlockError(f"custom block {proccode!r} is defined twice")
        ids = [stable_id(self.scope.target, "arg", proccode, n) for n in arg_names]
        self._procs[proccode] = _Proc(proccode, list(arg_names), ids, kinds, warp)
        self._scripts.append(("define", (proccode, list(body))))

    def when_flag(self, body: Stack) -> None:
        self._scripts.append(("flag", list(body)))

    @property
    def procedures(self) -> dict[str, _Proc]:
        return dict(self._procs)

    # ---- compiling
    def build(self) -> dict[str, dict[str, Any]]:
        self._blocks: dict[str, dict[str, Any]] = {}
        self._leaves: set[str] = set()  # reporters and shadows: never followed by a next block
        self._n = 0
        self._ids = 0  # the next counter id (compact)
        # block ids must not collide with the target's variable/list ids either
        self._reserved = set(self.scope.variables.values()) | set(self.scope.lists.values())
        y = 0
        for index, (kind, payload) in enumerate(self._scripts):
            self._proc: _Proc | None = None
            if kind == "define":
                proccode, body = payload
                self._proc = self._procs[proccode]
                top = self._define_block(self._proc, body)
                n_body = _count(body)
            else:
                top = self._new("event_whenflagclicked", None)
                self._link_stack(payload, top, first_field=None)
                n_body = _count(payload)
            blk = self._blocks[top]
            blk["topLevel"] = True
            blk["x"] = 0
            blk["y"] = y
            y += 120 + 48 * n_body
        for bid, blk in self._blocks.items():
            _compact(blk, leaf=bid in self._leaves, bare=self.compact)
        return self._blocks

    def _id(self) -> str:
        # 3 characters (Scratch's own are 20; 86^3 = 636,056 of them): ids appear 2-4 times per
        # block in project.json; unique within the target (checked), which is all Scratch needs
        self._n += 1
        if self.compact:  # the shortest ids: the block's number in base 86 (1 character, then 2 ...)
            return self._counter_id()
        bid = stable_id(self.scope.target, "block", str(self._n), length=BLOCK_ID_LENGTH)
        salt = 0
        while bid in self._blocks or bid in self._reserved:
            salt += 1
            bid = stable_id(self.scope.target, "block", str(self._n), str(salt), length=BLOCK_ID_LENGTH)
        return bid

    def _counter_id(self) -> str:
        while True:
            n, digits = self._ids, []
            self._ids += 1
            base = len(ID_ALPHABET)
            while True:  # bijective base 86: "!" .. "9", then "!!" ..
                n, r = divmod(n, base)
                digits.append(ID_ALPHABET[r])
                if n == 0:
                    break
                n -= 1
            bid = "".join(reversed(digits))
            if bid not in self._blocks and bid not in self._reserved:
                return bid

    def _new(self, opcode: str, parent: str | None, *, shadow: bool = False) -> str:
        bid = self._id()
        self._blocks[bid] = {"opcode": opcode, "next": None, "parent": parent, "inputs": {}, "fields": {},
                             "shadow": shadow, "topLevel": False}
        if shadow:
            self._leaves.add(bid)
        return bid

    def _define_block(self, proc: _Proc, body: Stack) -> str:
        d = self._new("procedures_definition", None)
        p = self._new("procedures_prototype", d, shadow=True)
        self._blocks[d]["inputs"]["custom_block"] = [1, p]
        proto = self._blocks[p]
        for name, aid, k in zip(proc.arg_names, proc.arg_ids, proc.arg_kinds):
            op = "argument_reporter_string_number" if k == "s" else "argument_reporter_boolean"
            r = self._new(op, p, shadow=True)
            self._blocks[r]["fields"]["VALUE"] = [name, None]
            proto["inputs"][aid] = [1, r]
        proto["mutation"] = {
            "tagName": "mutation", "children": [], "proccode": proc.proccode,
            "argumentids": json.dumps(proc.arg_ids), "argumentnames": json.dumps(proc.arg_names),
            "argumentdefaults": json.dumps(["" if k == "s" else "false" for k in proc.arg_kinds]),
            "warp": "true" if proc.warp else "false"}
        self._link_stack(body, d, first_field=None)
        return d

    def _link_stack(self, stmts: Stack, parent: str, *, first_field: str | None) -> str | None:
        """Compile a stack under ``parent``: the first block becomes ``parent.next`` (or the
        substack input ``first_field``); returns the first block's id."""
        prev = parent
        first = None
        for st in stmts:
            if not isinstance(st, Node) or st.shape != "stack":
                raise BlockError(f"{st!r} is not a stack block")
            bid = self._compile(st, prev)
            if first is None:
                first = bid
                if first_field is None:
                    self._blocks[parent]["next"] = bid
            else:
                self._blocks[prev]["next"] = bid
            prev = bid
        return first

    def _compile(self, node: Node, parent: str) -> str:
        if isinstance(node, (VarRef, ListRef)):
            raise BlockError("variable/list reporters are only compiled as inputs")
        if isinstance(node, (ArgRef, BoolArgRef)):
            self._check_arg(node)
        if isinstance(node, Call):
            return self._compile_call(node, parent)
        bid = self._new(node.opcode, parent)
        if node.shape != "stack":
            self._leaves.add(bid)
        blk = self._blocks[bid]
        for name, (value, kind) in node.inputs.items():
            compiled = self._input(value, kind, bid)
            if compiled is not None:
                blk["inputs"][name] = compiled
        for name, f in node.fields.items():
            blk["fields"][name] = self._field(f)
        if isinstance(node, (ArgRef, BoolArgRef)):
            blk["fields"]["VALUE"] = [node.name, None]
        if node.mutation is not None:
            blk["mutation"] = node.mutation
        return bid

    def _check_arg(self, node: ArgRef | BoolArgRef) -> None:
        proc = self._proc
        if proc is None or node.name not in proc.arg_names:
            where = f"custom block {proc.proccode!r}" if proc else "a script outside a custom block"
            raise BlockError(f"argument {node.name!r} is not an argument of {where}")
        kind = proc.arg_kinds[proc.arg_names.index(node.name)]
        if (kind == "b") != isinstance(node, BoolArgRef):
            raise BlockError(f"argument {node.name!r} of {proc.proccode!r} is used with the wrong type")

    def _compile_call(self, node: Call, parent: str) -> str:
        proc = self._procs.get(node.proccode)
        if proc is None:
            raise BlockError(f"custom block {node.proccode!r} is not defined in {self.scope.target}")
        if len(node.args) != len(proc.arg_ids):
            raise BlockError(f"{node.proccode!r} takes {len(proc.arg_ids)} arguments, got {len(node.args)}")
        bid = self._new("procedures_call", parent)
        blk = self._blocks[bid]
        for v, aid, k in zip(node.args, proc.arg_ids, proc.arg_kinds):
            blk["inputs"][aid] = self._input(v, TEXT if k == "s" else BOOL, bid)
        blk["mutation"] = {"tagName": "mutation", "children": [], "proccode": proc.proccode,
                           "argumentids": json.dumps(proc.arg_ids), "warp": "true" if proc.warp else "false"}
        return bid

    def _field(self, f: Any) -> list:
        if isinstance(f, VarField):
            return [f.name, self.scope.var_id(f.name)]
        if isinstance(f, ListField):
            return [f.name, self.scope.list_id(f.name)]
        if isinstance(f, Menu):
            return [f.value, None]
        raise BlockError(f"bad field {f!r}")

    def _input(self, value: Any, kind: Any, parent: str) -> list | None:
        if kind == STACK:
            if not value:
                return None  # an empty C-block has no substack input (as Scratch saves it)
            first = self._link_stack(value, parent, first_field="SUBSTACK")
            return [2, first]
        if kind == BOOL:
            if not isinstance(value, Node) or value.shape != "boolean":
                raise BlockError(f"a boolean input needs a boolean block, not {value!r}")
            return [2, self._compile(value, parent)]
        if kind == COSTUME_MENU:
            if isinstance(value, Node) and self.compact:  # the reporter alone, no menu under it
                return [2, self._reporter(value, parent)]
            menu = self._new("looks_costume", parent, shadow=True)
            if isinstance(value, Node):
                self._blocks[menu]["fields"]["COSTUME"] = ["", None]
                return [3, self._reporter(value, parent), menu]
            self._blocks[menu]["fields"]["COSTUME"] = [_literal(value), None]
            return [1, menu]
        default = "#000000" if kind == COLOUR else ""
        if isinstance(value, Node):
            if self.compact:  # no shadow under a reporter: [2, reporter] (see _compact)
                return [2, self._reporter(value, parent)]
            return [3, self._reporter(value, parent), [kind, default]]
        text = _literal(value)
        if kind == COLOUR and not re.fullmatch(r"#[0-9a-fA-F]{6}", text):
            # a colour input only takes "#rrggbb" as a literal; numbers go through a reporter
            raise BlockError(f"colour literal must be '#rrggbb', got {text!r} (use join(n, '') for a number)")
        return [1, [kind, text]]

    def _reporter(self, value: Node, parent: str) -> Any:
        if value.shape == "stack":
            raise BlockError(f"{value!r} is a stack block, not a reporter")
        if isinstance(value, VarRef):
            return [12, value.name, self.scope.var_id(value.name)]
        if isinstance(value, ListRef):
            return [13, value.name, self.scope.list_id(value.name)]
        return self._compile(value, parent)


def _compact(blk: dict[str, Any], *, leaf: bool = False, bare: bool = False) -> None:
    """Leave out the members whose absence means the same to the loaders: ``shadow`` and
    ``topLevel`` when false, ``inputs`` and ``fields`` when empty, and ``next: null`` of a
    ``leaf`` (a reporter, boolean or shadow block: nothing ever follows one). scratch-parser's
    schema requires only ``opcode``; scratch-vm's and TurboWarp's deserializer (sb3.js
    ``deserializeBlocks``) turn missing inputs/fields into ``{}`` and test ``shadow``/``topLevel``
    for truth only (the TurboWarp packager itself drops false ``shadow``/``topLevel``); ``next`` is
    read only when a stack is walked (``getNextBlock``, the compiler's ``walkStack``, ``blockToXML``
    tests it for truth), which never reaches a reporter. ``parent`` stays, ``null`` included: the
    VM compares it with ``null`` (``getTopLevelScript``), and so does ``next`` of a stack block
    (``deleteBlock``).

    ``bare`` (the compact blocks of packed projects, issue 41) also leaves out ``parent`` of a
    leaf: the runtime never reads a reporter's parent (``getTopLevelScript``, the editor's glow,
    walks up from stack blocks only, whose parents stay; the editor's moves take the old parent
    from its own event), and a reporter in a number or text input goes without the shadow under
    it (``[2, reporter]``, as Scratch writes a boolean input): both loaders read it as an input
    whose block is the reporter; the editor shows an empty slot if it is dragged out."""
    if leaf and blk.get("next", 0) is None:
        del blk["next"]
    if bare and leaf and blk.get("parent") is not None:
        del blk["parent"]
    for key in ("shadow", "topLevel"):
        if blk.get(key) is False:
            del blk[key]
    for key in ("inputs", "fields"):
        if blk.get(key) == {}:
            del blk[key]


def _count(stmts: Stack) -> int:
    n = 0
    for s in stmts:
        n += 1
        for value, kind in s.inputs.values():
            if kind == STACK:
                n += _count(value) + 1
    return n
