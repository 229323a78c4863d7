"""The study's configuration: one schema that holds every default, one way to read a config.

``workflow/schemas/config.schema.yaml`` is the single place where a key's default lives (the
default study of ``config.yaml`` is exactly the schema's defaults, which a test checks). A
config file is the *whole* configuration: :func:`resolve_config` fills what it leaves out from
the schema, never from another file, so the same file gives the same study from any folder.

Checks beyond JSON Schema, done here so that every consumer (the Snakefile, the steps, the
tests) gets them:

* an ``integer`` must be a YAML integer: ``4.0`` is refused (JSON Schema counts it as an
  integer; a render at "4.0 spp" would be named ``spp4.0``);
* every mapping key is a string: YAML reads an unquoted ``1``, ``yes``, ``no`` or ``null`` key as
  a number, a boolean or null (and a mix of those with strings cannot even be hashed into the
  config's digest);
* every number is finite: ``.nan`` and ``.inf`` pass JSON Schema's bounds (NaN compares false);
* labels, ``weights_dir`` and ``gpu_model`` are one line of text (the schema's :data:`ONE_LINE`
  pattern: a line break splits a table row, a NUL byte is no path);
* errors name the config key as a path, e.g. ``combiners[3].params.solvr`` or ``spp[0]``; an
  error inside a ``oneOf`` (a denoiser as a name or a mapping, ``resolution`` as null or a
  pair, ...) is reported at the branch that fits the value's type, e.g. ``resolution[0]``;
* ``study.ensembles`` takes ensemble IDs (9-39): a base ID (1-8) is refused naming the base
  (the bases come with the ensembles that take them, or all of them with ``ensembles: null``).

What needs more than the config itself (the method and scene registries, several keys at
once) is checked by :func:`mcbench.pipeline.plan.plan_study`.
"""

from __future__ import annotations

import re

import copy
import math
from functools import lru_cache
from pathlib import Path

import yaml

from mcbench import BenchError

__all__ = ["SCHEMA_PATH", "ConfigError", "load_schema", "schema_defaults", "resolve_config",
           "read_config_file", "parse_config_text", "key_path", "config_digest"]

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "workflow" / "schemas" / "config.schema.yaml"


#: The schema's pattern of one line of text (labels, weights_dir, gpu_model): no control character.
ONE_LINE = "^[^\\x00-\\x1f\\x7f]*$"


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
    """``["combiners", 3, "params", "solvr"]`` -> ``"combiners[3].params.solvr"``; a key that is
    not a plain name (a space, a dot, a quote, empty) in brackets as Python writes it, e.g.
    ``reference.scene_spp['spp ']``, so that no two keys read alike."""
    text = ""
    for part in parts:
        if isinstance(part, int):
            text += f"[{part}]"
        elif not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_-]*", str(part)):
            text += f"[{str(part)!r}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "<config>"


@lru_cache(maxsize=None)
def _cached_validator(path: str):
    return _validator(load_schema(path))


def _import_jsonschema():
    """``jsonschema``, imported without the optional IRI-syntax checker of its ``format``
    keyword. With JupyterLab installed (jupyter-events asks for ``jsonschema[format-nongpl]``),
    ``import jsonschema`` also imports ``rfc3987_syntax``, which builds a Lark grammar on import:
    about 2 s of CPU in every process that validates a config (each ``snakemake`` call, each
    worker). The config's validator asserts no formats (no ``FormatChecker``), so the checker is
    never used: a ``None`` in ``sys.modules`` makes that one import raise ``ImportError``, which
    jsonschema skips, and is removed again so that other code can still import the package."""
    import sys

    if "jsonschema" in sys.modules or "rfc3987_syntax" in sys.modules:
        import jsonschema

        return jsonschema
    sys.modules["rfc3987_syntax"] = None
    try:
        import jsonschema
    finally:
        del sys.modules["rfc3987_syntax"]
    return jsonschema


def _validator(schema: dict):
    jsonschema = _import_jsonschema()

    base = jsonschema.Draft202012Validator
    strict_integer = base.TYPE_CHECKER.redefine(
        "integer", lambda checker, value: isinstance(value, int) and not isinstance(value, bool))
    return jsonschema.validators.extend(base, type_checker=strict_integer)(schema)


def _check_keys_and_numbers(value, path: list, source: str) -> None:
    """ConfigError at the first mapping key that is not a string or number that is not finite."""
    if isinstance(value, dict):
        for key, sub in value.items():
            if not isinstance(key, str):
                where = key_path(path) if path else "<config>"
                raise ConfigError(f"{source}: {where}: key {key!r} is not a string (YAML reads an unquoted "
                                  f"{key!r} as {type(key).__name__}); quote it or use a name")
            _check_keys_and_numbers(sub, path + [key], source)
    elif isinstance(value, list):
        for index, sub in enumerate(value):
            _check_keys_and_numbers(sub, path + [index], source)
    elif isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{source}: {key_path(path)}: {value} is not a finite number")


def _branch_error(error):
    """The error to report for ``error``: inside a ``oneOf``/``anyOf``, the deepest error of the
    branch whose type fits the value (``resolution[0]: 8 is less than the minimum of 11``
    rather than ``resolution: [8, 8] is not valid under any of the given schemas``); when no
    branch's type fits, the error with the types named."""
    while error.context:
        depth = len(error.absolute_path)
        branches: dict = {}
        for sub in error.context:
            branches.setdefault(sub.relative_schema_path[0], []).append(sub)
        fitting = [subs for subs in branches.values()
                   if not any(e.validator == "type" and len(e.absolute_path) == depth for e in subs)]
        if not fitting:
            types = [e.validator_value for subs in branches.values() for e in subs
                     if e.validator == "type" and len(e.absolute_path) == depth]
            names = [t for value in types for t in (value if isinstance(value, list) else [value])]
            error.message = f"{error.instance!r} is not of type {' or '.join(repr(t) for t in dict.fromkeys(names))}"
            return error
        error = max(fitting[0], key=lambda e: len(e.absolute_path))
    return error


def _message(error) -> str:
    """The message of a schema error, with what a bare bound does not say."""
    path = list(error.absolute_path)
    if (path[:2] == ["study", "ensembles"] and len(path) == 3 and error.validator == "minimum"
            and isinstance(error.instance, int)):
        from mcbench.analysis.pool import BASES, ENSEMBLE_IDS

        what = (f"base #{error.instance} ({BASES[error.instance]}), not an ensemble" if error.instance in BASES
                else "not an ensemble")
        return (f"{error.instance} is {what}: study.ensembles takes ensemble IDs {ENSEMBLE_IDS[0]}-"
                f"{ENSEMBLE_IDS[-1]} and brings the bases they take (null: the whole pool, bases included)")
    if error.validator == "pattern" and error.validator_value == ONE_LINE:
        return f"{error.instance!r} holds a control character (a line break, tab or NUL); write one line of text"
    return error.message


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
    _check_keys_and_numbers(config, [], source)
    schema = load_schema(schema_path)
    resolved = _fill_defaults(copy.deepcopy(config), schema, schema)
    errors = sorted(_cached_validator(str(schema_path)).iter_errors(resolved),
                    key=lambda e: (len(e.absolute_path), str(e.path)))
    if errors:
        error = _branch_error(errors[0])
        raise ConfigError(f"{source}: {key_path(error.absolute_path)}: {_message(error)}")
    return _fold_additions(resolved)


def _fold_additions(resolved: dict) -> dict:
    """``add_denoisers`` and ``add_combiners`` appended to ``denoisers`` and ``combiners`` (each
    then empty): the resolved config holds one list of each, so a study written either way has
    one digest and one plan."""
    for key in ("denoisers", "combiners"):
        resolved[key] = list(resolved[key]) + list(resolved[f"add_{key}"])
        resolved[f"add_{key}"] = []
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
            text = handle.read()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    return resolve_config(parse_config_text(text, source=str(path)), source=str(path))


def parse_config_text(text: str, *, source: str = "config"):
    """The config a YAML text holds (``yaml.safe_load``, as Snakemake reads a config file), not
    yet resolved; invalid YAML is a :class:`ConfigError` naming ``source``."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML ({exc})") from exc
