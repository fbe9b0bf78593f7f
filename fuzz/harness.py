"""The atheris (libFuzzer) loop shared by ``fuzz_obj.py``, ``fuzz_gltf.py`` and ``fuzz_sb3.py``.

A finding is any exception other than :class:`bake.errors.BakeError` (an ``AssertionError``
from the checks in ``fuzz_targets`` included; known, reported bugs listed in
``fuzz_targets.KNOWN_BUGS`` are stepped over unless ``BAKE_FUZZ_STRICT=1``): libFuzzer writes the input to
``crash-<sha1>`` under ``-artifact_prefix`` and stops. Inputs that reach new code are added to
the first corpus folder given. ``make fuzz`` drives this through ``fuzz/run.py``.
"""

from __future__ import annotations

import os
import sys
import warnings


def main(target: str) -> None:
    import atheris

    with atheris.instrument_imports(include=["bake"]):
        import bake.importers.obj  # noqa: F401
        import bake.importers.obj_lines  # noqa: F401
        import bake.importers.obj_parse  # noqa: F401
        import bake.importers.mtl  # noqa: F401
        import bake.importers.gltf  # noqa: F401
        import bake.importers.gltf_data  # noqa: F401
        import bake.scratch.sb3  # noqa: F401
        import bake.scene  # noqa: F401
    import fuzz_targets
    from bake.errors import BakeError

    fn = fuzz_targets.TARGETS[target]
    warnings.simplefilter("ignore")  # numpy/zipfile warnings are not findings

    ignore_known = os.environ.get("BAKE_FUZZ_STRICT", "") != "1"

    def one_input(data: bytes) -> None:
        try:
            fn(data)
        except BakeError as e:
            msg = str(e)
            if not msg or "\n" in msg:
                raise AssertionError(f"error message is not one line: {msg!r}") from None
        except Exception as e:
            if not (ignore_known and fuzz_targets.is_known(target, e)):
                raise

    atheris.Setup(sys.argv, one_input)
    atheris.Fuzz()
