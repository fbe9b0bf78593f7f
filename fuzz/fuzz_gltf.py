#!/usr/bin/env python3
"""atheris harness for the gltf reader: `python fuzz/fuzz_gltf.py fuzz/corpus/gltf [libFuzzer options]`
(`make fuzz` runs it with a time limit). See fuzz/fuzz_targets.py for what an input is."""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import harness  # noqa: E402

if __name__ == "__main__":
    harness.main("gltf")
