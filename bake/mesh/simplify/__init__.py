"""The simplify stage (``[mesh.simplify]``): reduce the triangles to a budget and measure what it
cost in shape. docs/simplify.md has the method and its numbers; stage.py's docstring says what the
stage does, step by step.

The API, documented here once (nothing is imported into this package: import the module):

* ``stage.stage(scene, cfg) -> (scene, record)``: the pipeline's entry point
  (``"bake.mesh.simplify.stage:stage"`` in bake/stages.py); ``stage.simplify_mesh`` is the same
  without turning a MemoryError into a StageError; ``stage.resolve_target(n, cfg)`` the target
  a config asks for; ``library.METHODS`` the methods.
* ``report.section(entry)``: the stage's section of report.html, from its entry in report.json
  (``"bake.mesh.simplify.report:section"``).
* ``measure.hausdorff``, ``measure.certify``, ``error.SurfaceIndex``, ``error.flip_check``: the
  measure and the distances, also used on their own by the tests and benchmarks.

Which module does what, in the order a run goes through them:

===============  ==================================================================================
``stage.py``     the entry point and the order of the phases: the job (target, method, input), the
                 shared context, the count found, the rounds, the proven bound, the record
``inputs.py``    the input as the libraries take it: one layer of the scene's triangles, its
                 regions and parts, the wedges handed to meshoptimizer
``state.py``     what the phases hand each other: ``Ctx`` (what every attempt shares, built once
                 by ``context``) and ``Out`` (a result after the library and its repairs)
``library.py``   one run of meshoptimizer, fast-simplification or MeshLab (``Raw``)
``ladder.py``    meeting the count with the library: the layer target corrected, and what is let
                 go, in order, where the library stops short (``RELAXATIONS``)
``attempt.py``   one attempt at a count: the library, the repairs after it, the lock-and-retry
                 rounds, the fit and its check, the measure (``whole``)
``defects.py``   the defect accounting: flipped triangles, new folds, new non-manifold edges, how
                 many (``count``, ``flaws``), the vertices to lock under them, their record
``search.py``    finding the count: a triangle target and the back-off from a refused result, or
                 the smallest count within ``max_error``
``rounds.py``    where the error peaks: the refine rounds, the peak rounds, the proven bound
``outcome.py``   the result handed on: attributes, backs, checks, warnings, scene and record
``report.py``    the stage's section of report.html
``error.py``     closest-triangle queries, exact distances, flip checks, topology counts
``measure.py``   the Hausdorff measure: the grids, the refinement, the proven bound (``certify``)
``repair.py``    local repairs: border locks, edge turns, the Chebyshev polish, flip repairs, folds
``fit.py``       the least-squares refit of the free vertices
``parts.py``     messy input: the two-sided layer, parts, the per-part report
``meshopt.py``   meshoptimizer's C API through ctypes
===============  ==================================================================================

The phases call each other through their modules (``defects.count(out)``, ``attempt.whole(ctx,
n)``, ``meshopt.simplify(...)``), so a test that swaps one swaps it for the whole stage.
"""
