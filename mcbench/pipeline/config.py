"""The study's configuration: one schema that holds every default, one way to read a config.

``workflow/schemas/config.schema.yaml`` is the single place where a key's default lives (the
default study of ``config.yaml`` is exactly the schema's defaults, which a test checks). A
config file is the *whole* configuration: :func:`resolve_config` fills what it leaves out from
the schema, never from another file, so the same file gives the same study from any folder.

Checks beyond JSON Schema, done here so that every consumer (the Snakefile, the steps, the
tests) gets them:

* an ``integer`` must be a YAML integer: ``4.0`` is refused (JSON Schema counts it as an
  integer; a render at "4.0 spp" would be named ``spp4.0``);
* errors name the config key as a path, e.g. ``combiners[3].params.solvr`` or ``spp[0]``.
"""

from __future__ import annotations

import copy
from functools import lru_cache
from pathlib import Path

import yaml

from mcbench import BenchError

__all__ = ["SCHEMA_PATH", "ConfigError", "load_schema", "schema_defaults", "resolve_config",
           "read_config_file", "key_path", "config_digest"]

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "workflow" / "schemas" / "config.schema.yaml"


class ConfigError(BenchError):
    """A configuration value the schema or a method refuses; the message names its key."""


@lru_cache(maxsize=None)
def _schema_cached(path: str) -> dict:
    with open(path) as handle:
        return yaml.safe_load(handle)


def load_schema(path: str | Path = SCHEMA_PATH) -> dict:
    """The config schema as a dict (a deep copy: callers may modify it)."""
    return copy.deepcopy(_schema_cached(str(path)))


def _resolve_ref(schema: dict, root: dict) -> dict:
    while "$ref" in schema:
        ref = schema["$ref"]
        if not ref.startswith("#/"):
            raise ValueError(f"unsupported $ref {ref!r} in the config schema")
        node = root
        for part in ref[2:].split("/"):
            node = node[part]
        schema = node
    return schema


def _fill_defaults(value, schema: dict, root: dict):
    """``value`` with every missing property that has a schema default filled in, recursively
    through objects (a default object is itself filled). Arrays and scalars are left as given."""
    schema = _resolve_ref(schema, root)
    if not isinstance(value, dict) or schema.get("type") != "object":
        return value
    out = dict(value)
    for name, sub in schema.get("properties", {}).items():
        sub_resolved = _resolve_ref(sub, root)
        if name not in out and "default" in sub_resolved:
            out[name] = copy.deepcopy(sub_resolved["default"])
        if name in out:
            out[name] = _fill_defaults(out[name], sub_resolved, root)
    return out


def schema_defaults(path: str | Path = SCHEMA_PATH) -> dict:
    """The configuration a config file that sets nothing gets: every default of the schema."""
    schema = load_schema(path)
    return _fill_defaults({}, schema, schema)


def key_path(parts) -> str:
    """``["combiners", 3, "params", "solvr"]`` -> ``"combiners[3].params.solvr"``."""
    text = ""
    for part in parts:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "<config>"


def _validator(schema: dict):
    import jsonschema

    base = jsonschema.Draft202012Validator
    strict_integer = base.TYPE_CHECKER.redefine(
        "integer", lambda checker, value: isinstance(value, int) and not isinstance(value, bool))
    return jsonschema.validators.extend(base, type_checker=strict_integer)(schema)


def resolve_config(config: dict | None, *, source: str = "config",
                   schema_path: str | Path = SCHEMA_PATH) -> dict:
    """Validate ``config`` against the schema and return it with every default filled in.

    ``source`` (a file name) prefixes the error message. The first error is reported with the
    key path where it is, e.g. ``config.yaml: spp[0]: 4.0 is not of type 'integer'``.
    """
    if config is None:
        config = {}
    if not isinstance(config, dict):
        raise ConfigError(f"{source}: the configuration must be a mapping of keys, got {type(config).__name__}")
    schema = load_schema(schema_path)
    resolved = _fill_defaults(copy.deepcopy(config), schema, schema)
    errors = sorted(_validator(schema).iter_errors(resolved), key=lambda e: (len(e.absolute_path), str(e.path)))
    if errors:
        error = errors[0]
        raise ConfigError(f"{source}: {key_path(error.absolute_path)}: {error.message}")
    return resolved


def config_digest(config: dict) -> str:
    """First 16 hex digits of the SHA-256 of a resolved config (canonical JSON): two runs with
    the same digest plan the same study, whatever folder they were started from."""
    import hashlib
    import json

    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def read_config_file(path: str | Path) -> dict:
    """Read and resolve one config file (YAML); errors name the file."""
    path = Path(path)
    try:
        with open(path) as handle:
            raw = yaml.safe_load(handle)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from exc
    return resolve_config(raw, source=str(path))
