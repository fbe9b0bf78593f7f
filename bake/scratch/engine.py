"""What an author's engine does with the lists a bake writes into it (``export.into``).

The project is read as it was before the merge (its own scripts; sprites the bake adds are not
the engine). For every list the bake writes: the blocks and sprites that read it (``item``,
``length``, ``contents``, ``item #``, ``contains``, and the list reporter), write it (``add``,
``insert``, ``replace``, ``delete``) and empty it (``delete all``). A block names a list by id
(and name); a sprite's list hides the stage's list of the same name, as in Scratch.

Three things are said, each as a warning naming the lists (a problem under ``--strict``):

* a written list no block of the engine reads (the engine will not see it; not said when the bake
  adds its own reader or loader sprite, which reads them, nor when a block names the list in a
  text input -- a custom block or an extension given the list's name may read it by name;
  ``named_by`` counts those; an extension's list menu holding the list's id is a read);
* a list the bake replaces whose **parallel lists** stay behind: lists the bake does not write that
  had the replaced list's length before the merge, in the same sprite or on the stage (the
  engine's ``Y`` and ``Z`` keep 8 items while ``X`` now has 505);
* a green-flag script (following the broadcasts it sends, into the scripts that receive them, in
  the order they run) whose first use of a written list is ``delete all of``: the baked items are
  gone before anything reads them;
* a list the bake fills with numbers that held **text records** before (an item that is not a
  number, such as a JSON array per vertex): an engine that parses its items will not read plain
  numbers (seen in a public renderer whose ``Model`` list holds ``["x","y","z","u","v",nx,ny,nz]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator

READ = frozenset({"data_itemoflist", "data_lengthoflist", "data_listcontents", "data_itemnumoflist",
                  "data_listcontainsitem"})
WRITE = frozenset({"data_addtolist", "data_insertatlist", "data_replaceitemoflist", "data_deleteoflist"})
EMPTY = frozenset({"data_deletealloflist"})
LIST_PRIMITIVE = 13  # [13, name, id]: a list reporter in an input, or a loose one on the canvas
TEXT_PRIMITIVE = 10  # [10, text]: a text typed into an input
BROADCASTS = frozenset({"event_broadcast", "event_broadcastandwait"})


def _d(x: Any) -> dict:
    """``x`` if it is a dict, else an empty one (an author's project may hold anything)."""
    return x if isinstance(x, dict) else {}


def _targets(proj: dict) -> list[dict]:
    ts = proj.get("targets") if isinstance(proj, dict) else None
    return [t for t in ts if isinstance(t, dict)] if isinstance(ts, list) else []


@dataclass
class _Owner:
    """A target's lists: id -> (name, length), and id -> the first item that is text, not a
    number (None when every item is a number)."""

    name: str
    is_stage: bool
    lists: dict[str, tuple[str, int]] = field(default_factory=dict)
    text: dict[str, str | None] = field(default_factory=dict)


def _text_item(items: list, sample: int = 200) -> str | None:
    """The first of a list's first ``sample`` items that Scratch would not read as a number (an
    empty item is neither), or None (a list of records is text from its first item)."""
    for x in items[:sample]:
        if isinstance(x, str) and x.strip():
            try:
                float(x)
            except ValueError:
                return x
    return None


def _owners(proj: dict) -> list[_Owner]:
    out = []
    for t in _targets(proj):
        o = _Owner(str(t.get("name", "")), bool(t.get("isStage")))
        for lid, entry in _d(t.get("lists")).items():
            if isinstance(entry, list) and entry and isinstance(entry[0], str):
                items = entry[1] if len(entry) > 1 and isinstance(entry[1], list) else []
                o.lists[str(lid)] = (entry[0], len(items))
                o.text[str(lid)] = _text_item(items)
        out.append(o)
    return out


def _list_of(block: Any) -> tuple[str, str] | None:
    """(name, id) of the list a block names in its LIST field, or a list primitive's."""
    if isinstance(block, list):
        if len(block) >= 3 and block[0] == LIST_PRIMITIVE:
            return str(block[1]), str(block[2])
        return None
    f = _d(block.get("fields")).get("LIST") if isinstance(block, dict) else None
    if isinstance(f, list) and f:
        return str(f[0]), str(f[1]) if len(f) > 1 and f[1] is not None else ""
    return None


def _inputs_primitives(block: dict) -> Iterator[tuple[str, str]]:
    for value in _d(block.get("inputs")).values():
        if isinstance(value, list):
            for part in value[1:]:
                if isinstance(part, list):
                    found = _list_of(part)
                    if found:
                        yield found


class _Resolver:
    """Which list (owner name, list id) a block of a target means: its id when the target or the
    stage holds it, else its name (a sprite's own list first, then the stage's)."""

    def __init__(self, owners: list[_Owner]):
        self.stage = next((o for o in owners if o.is_stage), _Owner("Stage", True))
        self.by_name = {o.name: o for o in owners}

    def resolve(self, target: str, name: str, lid: str) -> tuple[str, str] | None:
        own = self.by_name.get(target)
        for o in ([own] if own is not None and not own.is_stage else []) + [self.stage]:
            if lid and lid in o.lists:
                return o.name, lid
        for o in ([own] if own is not None and not own.is_stage else []) + [self.stage]:
            for i, (n, _) in o.lists.items():
                if name and n == name:
                    return o.name, i
        return None


def _uses(proj: dict, resolver: _Resolver) -> Iterator[tuple[str, str, str, tuple[str, str]]]:
    """(sprite, block id, kind: read | write | empty, list) for every list use in the project."""
    for t in _targets(proj):
        sprite = str(t.get("name", ""))
        for bid, block in _d(t.get("blocks")).items():
            for kind, (name, lid) in _block_uses(block):
                ref = resolver.resolve(sprite, name, lid)
                if ref is not None:
                    yield sprite, str(bid), kind, ref


def _block_uses(block: Any) -> Iterator[tuple[str, tuple[str, str]]]:
    if isinstance(block, list):  # a loose list reporter on the canvas reads nothing when it runs alone
        return
    if not isinstance(block, dict):
        return
    op = block.get("opcode", "")
    named = _list_of(block)
    if named is not None:
        if op in READ:
            yield "read", named
        elif op in WRITE:
            yield "write", named
        elif op in EMPTY:
            yield "empty", named
    for named in _inputs_primitives(block):
        yield "read", named
    for key, value in _d(block.get("fields")).items():
        # an extension's list menu holds the list's id (a JSON or data extension reading it)
        if key != "LIST" and isinstance(value, list) and value and isinstance(value[0], str):
            yield "read", ("", value[0])
    for value in _d(block.get("inputs")).values():
        # a list named in text (a custom block or an extension given the list's name): it may be
        # read by name, which no block shows; said apart from the reads
        for part in value[1:] if isinstance(value, list) else ():
            if isinstance(part, list) and len(part) >= 2 and part[0] == TEXT_PRIMITIVE and isinstance(part[1], str):
                yield "named", (part[1], "")


def _first_uses(proj: dict, resolver: _Resolver, wanted: set[tuple[str, str]]) -> list[tuple[str, tuple[str, str]]]:
    """(sprite, list) for each green-flag script whose first use of a wanted list empties it. A
    script runs its inputs' reporters before its block, then its substacks, then the next block;
    a broadcast runs the scripts that receive it at that point (each message once per path)."""
    scripts: dict[str, list[tuple[str, dict, str]]] = {}  # message -> (sprite, blocks, top id)
    flags: list[tuple[str, dict, str]] = []
    for t in _targets(proj):
        blocks = _d(t.get("blocks"))
        for bid, b in blocks.items():
            if not isinstance(b, dict) or not b.get("topLevel"):
                continue
            if b.get("opcode") == "event_whenflagclicked":
                flags.append((str(t.get("name", "")), blocks, str(bid)))
            elif b.get("opcode") == "event_whenbroadcastreceived":
                opt = _d(b.get("fields")).get("BROADCAST_OPTION")
                msg = opt[0] if isinstance(opt, list) and opt else ""
                scripts.setdefault(str(msg).lower(), []).append((str(t.get("name", "")), blocks, str(bid)))
    out: list[tuple[str, tuple[str, str]]] = []
    for sprite, blocks, top in flags:
        first: dict[tuple[str, str], str] = {}
        _walk(sprite, blocks, blocks[top].get("next"), resolver, scripts, first, frozenset(), depth=0)
        out.extend((sprite, ref) for ref, kind in first.items() if kind == "empty" and ref in wanted)
    return out


def _walk(sprite: str, blocks: dict, bid: Any, resolver: _Resolver, scripts: dict, first: dict,
          sent: set, depth: int) -> None:
    seen: set[str] = set()  # (a malformed project may chain its blocks in a circle)
    while isinstance(bid, str) and bid in blocks and bid not in seen and depth < 64:
        seen.add(bid)
        b = blocks[bid]
        if not isinstance(b, dict):
            return
        inputs = _d(b.get("inputs"))
        for key, value in inputs.items():  # reporters first (they run before the block)
            if key.startswith("SUBSTACK") or not isinstance(value, list) or len(value) < 2:
                continue
            if isinstance(value[1], str) and value[1] in blocks:
                _walk_reporter(sprite, blocks, value[1], resolver, first)
        for kind, (name, lid) in _block_uses(b):
            ref = resolver.resolve(sprite, name, lid)
            if ref is not None:
                first.setdefault(ref, kind)
        if b.get("opcode") in BROADCASTS:
            msg = _message(blocks, inputs.get("BROADCAST_INPUT"))
            if msg is not None and msg not in sent:
                sent = sent | {msg}
                for other, oblocks, top in scripts.get(msg, []):
                    _walk(other, oblocks, oblocks[top].get("next"), resolver, scripts, first, sent, depth + 1)
        for key in ("SUBSTACK", "SUBSTACK2"):
            value = inputs.get(key)
            if isinstance(value, list) and len(value) > 1 and isinstance(value[1], str):
                _walk(sprite, blocks, value[1], resolver, scripts, first, sent, depth + 1)
        bid = b.get("next")


def _walk_reporter(sprite: str, blocks: dict, bid: str, resolver: _Resolver, first: dict, depth: int = 0) -> None:
    b = blocks.get(bid)
    if not isinstance(b, dict):
        return
    for value in _d(b.get("inputs")).values():
        if isinstance(value, list) and len(value) > 1 and isinstance(value[1], str) and value[1] in blocks \
                and depth < 64:
            _walk_reporter(sprite, blocks, value[1], resolver, first, depth + 1)
    for kind, (name, lid) in _block_uses(b):
        ref = resolver.resolve(sprite, name, lid)
        if ref is not None:
            first.setdefault(ref, kind)


def _message(blocks: dict, value: Any) -> str | None:
    """The message a broadcast block sends (its menu, or a fixed text), lowercased as Scratch
    matches them; None when it is computed."""
    if not isinstance(value, list) or len(value) < 2:
        return None
    part = value[1]
    if isinstance(part, list) and len(part) >= 2:  # [11, name, id]: a broadcast primitive
        return str(part[1]).lower()
    if isinstance(part, str) and isinstance(blocks.get(part), dict):
        menu = blocks[part]
        f = _d(menu.get("fields")).get("BROADCAST_OPTION")
        if menu.get("opcode") == "event_broadcast_menu" and isinstance(f, list) and f:
            return str(f[0]).lower()
    return None


def check(proj: dict, target: str, written: dict[str, int], *, reader_added: bool,
          numbers: set[str] | frozenset[str] = frozenset()) -> dict[str, Any]:
    """The engine check of ``proj`` (the author's project.json before the merge) for the lists the
    bake writes into ``target`` ("Stage" or a sprite): ``written`` maps each list name to the items
    it now holds; ``numbers`` names those that hold numbers only. Returns the report's ``engine``
    section: per list the sprites and blocks that read, write and empty it, and ``warnings`` (each
    a line naming the lists)."""
    owners = _owners(proj)
    resolver = _Resolver(owners)
    where = "Stage" if target in ("Stage", "_stage_") else target
    refs: dict[str, tuple[str, str] | None] = {n: resolver.resolve(where, n, "") for n in written}
    table: dict[str, dict[str, Any]] = {n: {"read_by": {}, "written_by": {}, "emptied_by": {}, "named_by": {},
                                            "replaced": refs[n] is not None} for n in written}
    back = {ref: n for n, ref in refs.items() if ref is not None}
    for sprite, _bid, kind, ref in _uses(proj, resolver):
        if ref in back:
            slot = table[back[ref]][{"read": "read_by", "write": "written_by", "empty": "emptied_by",
                                     "named": "named_by"}[kind]]
            slot[sprite] = slot.get(sprite, 0) + 1
    warnings: list[str] = []
    unread = sorted(n for n in written if not table[n]["read_by"] and not table[n]["named_by"])
    if unread and not reader_added:
        it = "it" if len(unread) == 1 else "them"
        warnings.append(f"export.into: no block of the project reads {_names(unread)}: the engine will not see "
                        f"{it} (rename {it} under [export.names] to the lists the engine reads, or add a block that "
                        f"reads {it})")
    by_owner = {o.name: o for o in owners}
    parallel: dict[str, list[str]] = {}
    written_refs = set(back)
    for n, ref in refs.items():
        if ref is None:
            continue
        owner = by_owner[ref[0]]
        old = owner.lists[ref[1]][1]
        if old == written[n]:
            continue
        visible = [owner] + ([by_owner[where]] if where in by_owner and by_owner[where] is not owner else []) \
            + ([resolver.stage] if resolver.stage is not owner else [])
        left = sorted({name for o in visible for lid, (name, length) in o.lists.items()
                       if (o.name, lid) not in written_refs and length == old and old > 0})
        if left:
            parallel[n] = left
            warnings.append(f"export.into: '{n}' now holds {written[n]:,} items where it had {old:,}, but "
                            f"{_names(left)} beside it still {'has' if len(left) == 1 else 'have'} {old:,} (lists "
                            "the engine reads in step with it: bake them too under [export.names], or the engine "
                            "reads the new list against the old ones)")
    was_text: dict[str, str] = {}
    for n, ref in refs.items():
        sample = by_owner[ref[0]].text.get(ref[1]) if ref is not None and n in numbers else None
        if sample is not None:
            was_text[n] = sample
            shown = sample if len(sample) <= 40 else sample[:37] + "..."
            warnings.append(f"export.into: '{n}' held text items (such as {shown!r}) and now holds numbers: an "
                            "engine that parses its items (JSON arrays, joined records) will not read them (the "
                            "layouts the bake writes: docs/engines.md)")
    emptied = sorted({(s, back[ref]) for s, ref in _first_uses(proj, resolver, written_refs)})
    for sprite, n in emptied:
        warnings.append(f"export.into: a green-flag script of '{sprite}' empties '{n}' (delete all of) before "
                        "any block reads it: the baked items are gone when the engine starts (remove that block, "
                        "or bake into the list the engine fills it from)")
    for n in table:
        for k in ("read_by", "written_by", "emptied_by", "named_by"):
            table[n][k] = [{"sprite": s, "blocks": c} for s, c in sorted(table[n][k].items())]
    return {"target": where, "lists": table, "unread": unread if not reader_added else [],
            "parallel": parallel, "emptied_at_start": [{"sprite": s, "list": n} for s, n in emptied],
            "text_replaced": was_text,
            "warnings": warnings}


def _names(names: list[str]) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:8])
    return shown + (f" and {len(names) - 8} more" if len(names) > 8 else "")
