"""The config: TOML -> typed sections.

- ``schema.py``: every section as a dataclass with its defaults and its own range check
  (``check``); the sections stages bring themselves (``use_stage_sections``, set by the registry).
- ``loader.py``: reading a TOML file and ``--set`` overrides into the schema, type checks, then
  every section's check and the stages' (``load``, ``apply_override``, ``validate``).
- ``keys.py``: keys by dotted name (``all_keys``, ``get_key``, ``key_defaults`` for ``bake keys``,
  ``to_dict`` for the report) and the "did you mean" of an unknown key.
- ``origins.py``: where a value came from (the config's line, or the ``--set``) for messages.

What the rest of bake uses is imported here.
"""

from ..errors import ConfigError
from .keys import FILE_RELATIVE_KEYS, PATH_KEYS, all_keys, get_key, key_defaults, numeric_keys, to_dict
from .loader import apply_override, load, parse_value, validate
from .origins import error_at, origin
from .schema import (RESERVED_OUTPUT_NAMES, AOConfig, BouncesConfig, BSPConfig, BVHConfig, CacheConfig, CleanConfig,
                     Config, ExportConfig, HiddenBox, HiddenConfig, ImportConfig, ImportJob, InputConfig, LightConfig, LightingConfig,
                     LightmapConfig, ListNames, MeshConfig, ReportConfig, ShadowsConfig, SimplifyConfig, SkyConfig,
                     TexturesConfig, TransformConfig, TriangulateConfig, stage_sections, use_stage_sections)

__all__ = ["ConfigError", "FILE_RELATIVE_KEYS", "PATH_KEYS", "all_keys", "get_key", "key_defaults", "numeric_keys", "to_dict",
           "apply_override", "load", "parse_value", "validate", "error_at", "origin", "RESERVED_OUTPUT_NAMES",
           "AOConfig", "BouncesConfig", "BSPConfig", "BVHConfig", "CacheConfig", "CleanConfig", "Config",
           "ExportConfig", "HiddenBox", "HiddenConfig", "ImportConfig", "ImportJob", "InputConfig", "LightConfig", "LightingConfig",
           "LightmapConfig", "ListNames", "MeshConfig", "ReportConfig", "ShadowsConfig", "SimplifyConfig",
           "SkyConfig", "TexturesConfig", "TransformConfig", "TriangulateConfig", "stage_sections",
           "use_stage_sections"]
