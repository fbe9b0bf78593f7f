"""The bunny's targets hold for any vertex and face order (issue 19).

The corpus bunny goes to 1% and to 10% of its triangles with the default stage, for the file as
given, with ``transform.frame = "right"`` (z mirrored: a different order of everything the
library sees) and for five OBJ files with the face lines shuffled (seeded). Each result is
measured independently (tests/mesh/simplify_reference.py: MeshLab's Hausdorff filter, refined
around its worst samples, no bake code) and must stay within 1.0% of the bounding-box diagonal
at 1% and 0.20% at 10%. meshoptimizer alone ranges from 1.14% to 1.82% at 1% over such orders,
and the stage before this fix from 0.96% to 1.18%: the stage has to make the result robust, not
lucky.
"""

from __future__ import annotations

import pytest

from bake import pipeline
from bake.config import SimplifyConfig
from bake.mesh.simplify import stage as S

from conftest import corpus_path
from simplify_reference import hausdorff_reference, shuffled_obj


def variants(tmp_path):
    src = corpus_path("stanford_bunny_res1_obj", "stanford-bunny.obj")
    yield "as given", src, None
    yield "frame right", src, ["transform.frame=right"]
    for seed in range(1, 6):
        yield f"faces shuffled ({seed})", shuffled_obj(src, tmp_path / f"bunny-{seed}.obj", seed), None


@pytest.mark.corpus
@pytest.mark.slow
@pytest.mark.parametrize("ratio,limit", [(0.01, 0.010), (0.1, 0.0020)])
def test_bunny_targets_hold_for_any_order(tmp_path, ratio, limit):
    results = []
    for name, path, overrides in variants(tmp_path):
        sc = pipeline.run(pipeline.load_config_for(path, overrides), until="clean").scene
        out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=ratio))
        assert abs(out.n_triangles - round(ratio * sc.n_triangles)) <= 0.01 * ratio * sc.n_triangles + 1
        ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=100_000,
                                  rounds=5)
        results.append((name, ref.max / sc.scale(), rec.accuracy["hausdorff_max"], rec.accuracy["folds"]))
    bad = [r for r in results if r[1] > limit or r[2] > limit or r[3] > 0]
    assert not bad, f"measured (independent, reported, folds) above {limit:.2%}: {bad}; all: {results}"
