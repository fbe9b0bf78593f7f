"""Packed lists (bake/scratch/pack.py): exact round trips, the varint code, and bad texts.

The reference for "exact" is the plain list itself: a packed list must decode to the very items
(the same doubles, the same ints) a JSON reader makes of the plain list's text. The loader blocks
are proven against the same items in scratch-vm (test_pack_vm.py)."""

from __future__ import annotations

import json
import math
import random

import numpy as np
import pytest

from bake.scratch import pack as P
from bake.scratch.numbers import format_numbers


def plain(values, decimals=None):
    """The items a JSON reader makes of the plain list (what the export writes)."""
    return json.loads("[" + ",".join(format_numbers(np.asarray(values), decimals)) + "]")


def same(a, b) -> bool:
    """Item for item, the same double (bit for bit; Scratch, like JSON's readers in JavaScript,
    has one number type, so 1 and 1.0 are the same item)."""
    return len(a) == len(b) and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                    and repr(float(x)) == repr(float(y)) for x, y in zip(a, b))


def roundtrip(name, items, stride=1, **kw):
    pk = P.pack(name, items, stride, **kw)
    assert pk is not None
    u = P.unpack(pk.text, name)
    assert same(u.items, items), name
    assert u.cost.items == len(items)
    return pk, u


RNG = np.random.default_rng(7)


@pytest.mark.parametrize("decimals", [0, 1, 3, 5, 6, 9])
def test_floats_round_trip_bit_for_bit(decimals):
    for scale in (1e-3, 1.0, 37.5, 1e4):
        v = plain(RNG.normal(size=3000) * scale, decimals)
        if scale * 10.0 ** decimals > 1e11:
            # the codes would sum past 2^53 (the loader's check sum must be exact): left plain
            assert P.pack("verts", v, 3) is None
            continue
        roundtrip("verts", v, 3)


def test_every_column_mode_round_trips():
    rows = 500
    const = [7] * rows
    offset = RNG.integers(-50000, 50000, rows).tolist()
    walk = np.cumsum(RNG.integers(-30, 31, rows)).tolist()
    pal = RNG.choice([16777215, 0, 8421504, 255], rows).tolist()
    items = [x for row in zip(const, offset, walk, pal) for x in row]
    pk, u = roundtrip("mixed", items, 4)
    assert [c["mode"] for c in pk.describe()] == ["const", "offset", "delta", "palette"]


def test_index_columns_in_first_use_order():
    # a strip-like mesh: vertices numbered as the triangles first use them
    tris = []
    for t in range(400):
        tris += [t + 1, t + 2, t + 3, 1]
    pk, u = roundtrip("tris", tris, 4, index_columns=(0, 1, 2))
    assert pk.describe()[0]["mode"] == "index" and pk.describe()[0]["columns"] == 3
    # one symbol per corner at most here (new vertex or one of the last few)
    assert pk.describe()[0]["symbols"] == 3 * 400
    # indices that skip ahead are not index-codable: packed another way, still exact
    skip = [5, 1, 2, 1, 3, 4, 9, 1]
    pk2, _ = roundtrip("tris", skip, 4, index_columns=(0, 1, 2))
    assert all(c["mode"] != "index" for c in pk2.describe())


def test_a_prefix_section_before_the_records():
    """A BVH's nodes: a 6-item root box (floats) and then 7-item records (ints): the records
    pack column by column once the prefix is its own section."""
    box = [-1.25, 0.5, -3.0, 2.75, 4.5, 1.0]
    recs = []
    for k in range(300):
        recs += [65535 - k % 7, 7 * k + 7, k + 1, 2 ** 35 + 977 * k, 2 ** 34 + 13 * k, 5 * k, 2 ** 30 - k]
    items = box + recs
    whole = P.pack("bvh nodes", items, 1)
    pk, u = roundtrip("bvh nodes", items, 7, prefix=6)
    assert u.cost.sections == [(6, 1), (300, 7)]
    assert whole is None or pk.chars < whole.chars


def test_index_codes_match_definition():
    v = np.array([1, 2, 3, 2, 4, 1, 5, 5])
    codes = P.index_codes(v)
    m = 0
    for x, c in zip(v, codes):
        if c == 0:
            m += 1
            assert x == m
        else:
            assert x == m + 1 - c
    assert P.index_codes(np.array([2, 1])) is None


def test_lists_that_cannot_be_packed_exactly():
    assert P.pack("s", ["#ffffff", "#000000"]) is None  # text
    assert P.pack("x", [math.pi, 1.0]) is None  # not a short decimal
    assert P.pack("big", [2 ** 60, 1]) is None  # past 2^53
    assert P.pack("inf", [float("inf")]) is None


def test_decimals_of_is_the_fewest():
    d, q = P.decimals_of(np.array([0.5, 1.25, -3.0]))
    assert d == 2 and q.tolist() == [50, 125, -300]
    d, _ = P.decimals_of(np.array([1.0, 2.0]))
    assert d == 0


def test_varint_lengths_and_best_t_against_brute_force():
    for _ in range(100):
        n = RNG.integers(0, RNG.choice([3, 90, 9000, 10 ** 7]), RNG.integers(1, 200))
        T, size = P.best_t(n)
        brute = min(int(P.varint_lengths(n, t).sum()) for t in range(1, 92) if not (t == 91 and n.max() // t > 1000))
        assert size == brute
        table, lengths = P.encode_varints(n, T)
        assert lengths.tolist() == P.varint_lengths(n, T).tolist()
        # decode the table by the definition: continuation digits then a final digit
        C = 92 - T
        for row, val in zip(table, n):
            a = 0
            digits = [s for s in row if s >= 0]
            for s in digits[:-1]:
                assert s >= T
                a = a * C + s - T + 1
            assert digits[-1] < T and a * T + digits[-1] == val


def test_alphabet_has_no_json_escapes_and_maps_costumes():
    assert len(P.ALPHABET) == 92 and '"' not in P.ALPHABET and "\\" not in P.ALPHABET
    assert json.dumps(P.ALPHABET) == '"' + P.ALPHABET + '"'  # one byte per symbol in project.json
    sym = P.costume_symbols()
    assert len(sym) == 94
    for k in range(1, 95):  # costume k is chr(32 + k)
        ch = chr(32 + k)
        if ch in P.ALPHABET:
            assert sym[k - 1] == P.ALPHABET.index(ch)


def test_names_with_any_characters():
    for name in ("tri colors", "ünïcødé", "emoji 🐇", 'quote " and \\'):
        pk, u = roundtrip(name, [1, 2, 3, 5, 8])
        assert P.header_name(pk.text) == name and u.name == name


def test_empty_and_tiny_lists():
    roundtrip("one", [42])
    roundtrip("neg", [-1, -1, -1])
    pk = P.pack("empty", [])
    assert pk is not None and P.unpack(pk.text, "empty").items == []


# --------------------------------------------------------------------------- bad texts
def good():
    items = plain(RNG.normal(size=900) * 10, 3)
    return P.pack("verts", items, 3).text, items


def test_truncated_texts_are_errors_naming_the_list():
    text, _ = good()
    for cut in (len(text) - 1, len(text) - 7, len(text) // 2, 12, 6, 3):
        with pytest.raises(P.PackError, match="verts|'\\?'"):
            P.unpack(text[:cut])
    with pytest.raises(P.PackError, match="packed list 'verts'"):
        P.unpack(text[:-1], "verts")


def test_every_single_character_edit_is_caught():
    """CRC-32 catches every single-symbol change; each one is a PackError, never a hang or a
    different list."""
    text, items = good()
    rnd = random.Random(3)
    positions = rnd.sample(range(len(P.MAGIC), len(text)), 300)
    for pos in positions:
        ch = text[pos]
        new = rnd.choice([c for c in P.ALPHABET + ' "\\é' if c != ch])
        edited = text[:pos] + new + text[pos + 1:]
        with pytest.raises(P.PackError):
            P.unpack(edited, "verts")
    # inserted and deleted characters too
    for pos in positions[:50]:
        with pytest.raises(P.PackError):
            P.unpack(text[:pos] + "!" + text[pos:], "verts")
        with pytest.raises(P.PackError):
            P.unpack(text[:pos] + text[pos + 1:], "verts")


def test_wrong_name_and_foreign_text():
    text, _ = good()
    with pytest.raises(P.PackError, match="holds the list 'verts'"):
        P.unpack(text, "tris")
    with pytest.raises(P.PackError, match="not a scratch-bake packed list"):
        P.unpack("hello", "verts")
    with pytest.raises(P.PackError):
        P.unpack(123, "verts")


def test_header_is_checked_beyond_the_crc():
    """A text whose CRC was recomputed after an edit (a crafted text) still fails a structural
    check instead of decoding garbage or looping."""
    import zlib

    def forge(body_fields):
        name = "x"
        body = P.varint_text([1]) + name + P.varint_text(body_fields)
        crc = zlib.crc32(name.encode() + body.encode())
        return P.MAGIC + P.varint_text([crc]) + body

    with pytest.raises(P.PackError, match="section count"):
        P.unpack(forge([40]))
    with pytest.raises(P.PackError, match="stride"):
        P.unpack(forge([1, 3, 0]))
    with pytest.raises(P.PackError, match="column mode"):
        P.unpack(forge([1, 1, 1, 9]))
    with pytest.raises(P.PackError, match="T"):
        P.unpack(forge([1, 1, 1, 1, 1, 0]))  # T = 0 would loop for ever in Scratch
    with pytest.raises(P.PackError, match="ends too early"):
        P.unpack(forge([1, 5, 1, 1, 1, 10, 0, 0, 0]))  # 5 rows, no data
