"""Number formatting: shortest text that reads back as the rounded value; never NaN/Inf."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from bake.errors import StageError
from bake.scratch.numbers import decimals_for, format_numbers


def test_shortest_forms():
    vals = np.array([1.0, -0.0, 0.1234567, -2.5, 3.0, 1e20, 100.0])
    assert format_numbers(vals, 3) == ["1", "0", "0.123", "-2.5", "3", "1e+20", "100"]
    assert format_numbers(np.array([1, 2, -3])) == ["1", "2", "-3"]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e12, max_value=1e12),
                min_size=1, max_size=50), st.integers(0, 8))
def test_reads_back_as_rounded_value(values, dec):
    a = np.array(values)
    out = format_numbers(a, dec)
    back = np.array([float(s) for s in out])
    assert np.array_equal(back, np.round(a, dec) + 0.0)
    for s in out:  # never longer than the fixed-point form
        assert len(s) <= len(f"{float(s):.{dec}f}") or "e" in s


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_refused_with_list_name(bad):
    with pytest.raises(StageError, match="list 'verts'.*item 2"):
        format_numbers(np.array([1.0, bad]), 3, name="verts")


def test_decimals_for():
    assert decimals_for(0.002) == 3 and decimals_for(0.001) == 3 and decimals_for(1.0) == 0
    assert decimals_for(20.0) == 0 and decimals_for(0.0) == 6


def test_a_lists_estimated_bytes_are_what_it_adds_to_a_written_project_json():
    """``project_json_bytes`` (what the report and the limit bars add up per list) against the
    project.json our writer makes: the bytes one more list adds, as written (20-character ids).
    A user's review found the report 2 bytes above ``bake check`` per list; the constant counted
    the items' brackets twice."""
    import io
    import zipfile

    from bake.scratch import sb3
    from bake.scratch.numbers import json_array, project_json_bytes

    def size(lists):
        data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists)])
        return len(zipfile.ZipFile(io.BytesIO(data)).read("project.json"))

    base = {"verts": [1.5, -2, 3]}
    for name, items in (("tris", [1, 2, 3, 4]), ("mat colors", [16777215]), ("ünïcode", [0.25] * 7), ("empty", [])):
        added = size({**base, name: items}) - size(base)
        assert project_json_bytes(name, json_array([repr(v) for v in items])) == added, name
