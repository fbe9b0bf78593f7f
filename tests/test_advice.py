"""Surprises that used to stay silent (issue 18, item 6): each is now a warning in the stage's
record and on the terminal, and the warning goes away when the config does what it says."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bake import cli

sys.path.insert(0, str(Path(__file__).parent / "reliability"))
from rel_util import write_obj  # noqa: E402
from test_rel_memory import sphere  # noqa: E402


def bake(capsys, target, out, *sets):
    argv = ["run", str(target), "--out", str(out)]
    for s in sets:
        argv += ["--set", s]
    code = cli.main(argv)
    cap = capsys.readouterr()
    assert code == 0, cap.err
    rep = json.loads((Path(out) / "report.json").read_text())
    return rep, cap.out


def warnings_of(rep, stage):
    return next(s for s in rep["stages"] if s["name"] == stage)["warnings"]


def test_a_texture_that_is_not_used_is_said_with_how_to_use_it(tmp_path, capsys):
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
                                    "vt 0 1\nusemtl wood\nf 1/1 2/2 3/3 4/4\n")
    (tmp_path / "m.mtl").write_text("newmtl wood\nKd 1 1 1\nmap_Kd wood.png\n")
    Image.fromarray(np.full((4, 4, 3), (120, 80, 40), np.uint8)).save(tmp_path / "wood.png")
    rep, out = bake(capsys, tmp_path / "m.obj", tmp_path / "o", "textures.enabled=false")
    w = " ".join(warnings_of(rep, "import"))
    assert "texture ('wood') that is not used" in w and "textures.enabled = true" in w and "white" in w, w
    assert "textures.enabled = true" in out  # on the terminal too
    for on in ("textures.enabled=true", "textures.enabled=auto"):  # (auto: the default)
        rep, _ = bake(capsys, tmp_path / "m.obj", tmp_path / "o2", on)
        assert not [x for x in warnings_of(rep, "import") if "not used" in x]


def test_bsp_splits_past_the_simplify_budget_are_said(tmp_path, capsys):
    p, f = sphere(3)
    write_obj(tmp_path / "two.obj", np.vstack([p, p * 0.8 + [0.9, 0.1, 0.2]]), np.vstack([f, f + len(p)]))
    rep, _ = bake(capsys, tmp_path / "two.obj", tmp_path / "o", "mesh.simplify.enabled=true",
                  "mesh.simplify.target_triangles=500", "bsp.enabled=true", "report.html=false")
    n = rep["scene"]["triangles"]
    assert n > 1.25 * 500  # the intersecting spheres split: the premise of the warning
    w = " ".join(warnings_of(rep, "bsp"))
    assert f"to {n:,}" in w and "500 asked by mesh.simplify.target_triangles" in w, w
    # within the budget's margin: nothing said
    rep, _ = bake(capsys, tmp_path / "two.obj", tmp_path / "o2", "mesh.simplify.enabled=true",
                  f"mesh.simplify.target_triangles={n}", "bsp.enabled=true", "report.html=false")
    budget = [x for x in warnings_of(rep, "bsp") if "asked by" in x]
    assert not budget or rep["scene"]["triangles"] > 1.25 * n
    # the spheres pass through each other: that is said too, whatever the budget
    assert any("pass through each other" in x for x in warnings_of(rep, "bsp"))


def test_bsp_of_a_large_mesh_without_simplify_hints_to_simplify_first(tmp_path, capsys):
    n = 103
    x, z = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    pos = np.stack([x.ravel(), 0 * x.ravel(), z.ravel()], 1)
    i = np.arange(n * n).reshape(n, n)
    write_obj(tmp_path / "g.obj", pos, np.stack([i[:-1, :-1], i[1:, :-1], i[1:, 1:], i[:-1, 1:]], -1).reshape(-1, 4))
    rep, out = bake(capsys, tmp_path / "g.obj", tmp_path / "o", "bsp.enabled=true", "report.html=false")
    w = " ".join(warnings_of(rep, "bsp"))
    assert "BSP of 20,808 triangles" in w and "mesh.simplify.enabled = true" in w, w


@pytest.mark.parametrize("kind", ["spot", "point"])
def test_a_point_or_spot_light_without_a_position_is_said(tmp_path, capsys, kind):
    p, f = sphere(2)
    write_obj(tmp_path / "ball.obj", p, f)
    cfg = tmp_path / "bake.toml"
    light = f'[[lighting.lights]]\nkind = "{kind}"\ndirection = [0, -1, 0]\nouter_cone = 60\n'
    cfg.write_text('[input]\npath = "ball.obj"\n[lighting]\nenabled = true\n' + light)
    rep, _ = bake(capsys, cfg, tmp_path / "o", "report.html=false")
    w = " ".join(warnings_of(rep, "lighting"))
    assert f"lighting.lights[0] ({kind}) has no position" in w and "lights nothing" in w, w
    cfg.write_text('[input]\npath = "ball.obj"\n[lighting]\nenabled = true\n' + light + "position = [0, 3, 0]\n")
    rep, _ = bake(capsys, cfg, tmp_path / "o2", "report.html=false")
    assert not [x for x in warnings_of(rep, "lighting") if "lights[0]" in x], warnings_of(rep, "lighting")
