"""Hostile configurations by the thousand (Hypothesis): valid configs generated from the schema
plan every configured candidate, metric and case; mutated ones (wrong types, out-of-range
numbers, unknown names, duplicates, cycles among combiners, empty lists, huge values, odd strings
and unicode, YAML oddities through ``yaml.safe_load``) either plan or stop before any job with a
:class:`mcbench.BenchError` that names the offending key -- never a bare KeyError, TypeError or
AttributeError -- and say so when the key holds a schema default the config never wrote.

The planner is :func:`mcbench.pipeline.plan.plan_study`, the function ``workflow/rules/common.smk``
itself calls when the DAG is parsed, so no Snakemake run is needed per example (a few real
``snakemake -n`` runs on generated configs are in the fuzz tier, `python -m pytest -q -m fuzz`). Every example is reproducible:
Hypothesis prints the failing config and a ``@reproduce_failure`` blob (``print_blob``), and the
runs are derandomized (the same examples every run).

Strategies: :func:`valid_configs` draws any subset of the schema's keys (scenes from scenes/, spp
levels with a render seed code, denoisers as names or variants with params drawn from each
method's annotations, combiners over earlier entries, the pool or a slice of study.ensembles
9-39, metrics, references above every spp, oracle, progressive curve, training) and keeps what
it leaves to the defaults consistent with what it sets; :func:`mutated_configs` applies one to
three of :data:`MUTATIONS` to one; :func:`yaml_texts` dumps one to YAML and swaps a scalar, a key
or the whole document for a YAML oddity (``yes``, ``no``, ``null``, ``1e3``, ``0x10``, ``.nan``,
dates, tags, anchors, ...).

Below the properties: each defect found (by the generator, or on the way to it) as its minimal
example.
"""

from __future__ import annotations

import contextlib
import copy
import inspect
import itertools
import re
import signal
import subprocess
import sys
import typing
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, event, given, note, settings, strategies as st

import methods
from mcbench import NOISY_LABEL, BenchError
from mcbench.analysis.comparison_tables import comparison_role
from mcbench.pipeline.registry import available_metrics
from mcbench.analysis.pool import ENSEMBLE_IDS, pool_methods
from mcbench.io.weights import is_learned_method
from mcbench.pipeline.config import (ConfigError, config_digest, key_path, load_schema, parse_config_text,
                                     resolve_config, schema_defaults)
from mcbench.pipeline.plan import plan_study
from mcbench.pipeline.registry import available_scenes

REPO = Path(__file__).resolve().parents[2]
SOURCE = "generated.yaml"
SCHEMA = load_schema()
DEFAULTS = schema_defaults()
TOP_KEYS = set(SCHEMA["properties"])
SCENES = available_scenes()


# --------------------------------------------------------------------------- the method catalogue

def _catalogue() -> dict[str, dict]:
    out = {}
    for name in methods.available_methods():
        module = methods.load_method(name)
        spec = methods.method_spec(module)
        hints = typing.get_type_hints(spec.run)
        out[name] = {"kind": spec.kind, "label": spec.label, "inputs": spec.inputs,
                     "learned": is_learned_method(module),
                     "params": {key: (hints.get(key), p.default) for key, p in methods.method_parameters(module).items()}}
    return out


CATALOGUE = _catalogue()
#: methods that cannot run without a param no default gives (an external program's command,
#: precomputed results' folder, whose files are checked when the DAG is parsed): their own tests
#: (tests/methods/test_external.py, test_precomputed.py) cover their configs, not generated ones
NEEDS_OUTSIDE_PARAMS = sorted(n for n, c in CATALOGUE.items()
                              if any(default is inspect.Parameter.empty for _, default in c["params"].values()))
DENOISERS = sorted(n for n, c in CATALOGUE.items() if c["kind"] == "denoiser" and n not in NEEDS_OUTSIDE_PARAMS)
COMBINERS = sorted(n for n, c in CATALOGUE.items() if c["kind"] == "combiner")
POOL_NAMES = {name for denoisers, combiners in [pool_methods()] for name in denoisers + [c["name"] for c in combiners]}
# even spp with a render seed code (mcbench.render.seeds.spp_code)
SPP_VALUES = st.one_of(st.integers(1, 1024).map(lambda k: 2 * k), st.integers(2, 8).map(lambda k: 2048 * k))
NAME_TAIL = st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789_", max_size=6)
LABEL_TEXT = st.text(st.characters(codec="utf-8", exclude_categories=("Cc", "Cs")), min_size=0, max_size=12)


def _param_strategy(hint, default):
    """Values ``check_params`` accepts for a parameter (numbers near the default)."""
    if typing.get_origin(hint) is typing.Literal:
        return st.sampled_from(typing.get_args(hint))
    if hint is bool:
        return st.booleans()
    if hint is int:
        return st.integers(max(0, default - 2), default + 3)
    if hint is float:
        return st.sampled_from([default, default * 0.5, default * 2.0, float(int(default) + 1)])
    return st.just(default)


def params_strategy(module: str):
    spec = CATALOGUE[module]["params"]
    return st.fixed_dictionaries({}, optional={key: _param_strategy(h, d) for key, (h, d) in spec.items()})


def _default_label(module: str, inputs: list, params: dict) -> str:
    details = (["+".join(inputs)] if inputs else []) + (
        [", ".join(f"{k}={v}" for k, v in params.items())] if params else [])
    label = CATALOGUE[module]["label"]
    return f"{label} ({'; '.join(details)})" if details else label


# --------------------------------------------------------------------------- valid configs

def _pool_entries(pool: bool, ids):
    if not pool:
        return [], []
    denoisers, combiners = pool_methods(ids)
    return denoisers, combiners


def _labelled(draw, entry: dict, default_label: str, labels: set) -> str:
    """The entry's label: its default, or (drawn, or needed to stay unique) one of its own, set in ``entry``."""
    if draw(st.booleans()) or default_label in labels:
        entry["label"] = f"{entry['name']} {draw(LABEL_TEXT)}".strip()
        return entry["label"]
    return default_label


@st.composite
def valid_configs(draw, *, max_scenes: int = 4, max_spp: int = 4, max_denoisers: int = 5, max_combiners: int = 6,
                  small: bool = False):
    """A config the schema and the planner accept, drawing any subset of the schema's keys; the
    keys it leaves out take their defaults, and the draw keeps the defaults consistent with what
    it sets (e.g. the default combiners only with denoisers that hold their inputs)."""
    config: dict = {}
    # -- study and its pool
    study = draw(st.fixed_dictionaries({}, optional={
        "pool": st.booleans(),
        "ensembles": st.one_of(st.none(), st.lists(st.sampled_from(ENSEMBLE_IDS), min_size=1, max_size=4, unique=True)),
        "bootstrap": st.integers(100, 5000), "seed": st.integers(0, 2 ** 40)}))
    if study or draw(st.booleans()):
        config["study"] = study
    pool = study.get("pool", True)
    pool_denoisers, pool_combiners = _pool_entries(pool, study.get("ensembles"))
    pool_sets = {frozenset(c["inputs"]) for c in pool_combiners if c["method"] == "ensemble"}
    labels = {NOISY_LABEL} | {CATALOGUE[d]["label"] for d in pool_denoisers} | {c["label"] for c in pool_combiners}
    names = list(pool_denoisers)
    modules = {*pool_denoisers, *(c["method"] for c in pool_combiners)}

    # -- denoisers
    if draw(st.booleans()):
        denoisers = []
        for index in range(draw(st.integers(1, max_denoisers))):
            module = draw(st.sampled_from(DENOISERS))
            if draw(st.booleans()):
                if module in pool_denoisers:     # a pool base named again: the pool's entry stands
                    denoisers.append(module)
                    continue
                if module in names:
                    continue
                label = CATALOGUE[module]["label"]
                if label in labels:
                    continue
                denoisers.append(module)
                names.append(module)
                labels.add(label)
            else:
                name = f"d{index}_{module}{draw(NAME_TAIL)}"
                params = draw(params_strategy(module))
                entry = {"name": name, "method": module, **({"params": params} if params or draw(st.booleans()) else {})}
                label = _labelled(draw, entry, _default_label(module, [], params), labels)
                denoisers.append(entry)
                names.append(name)
                labels.add(label)
            modules.add(module)
        if not denoisers:
            denoisers = ["jbf"] if "jbf" not in names else ["oidn"] if "oidn" not in names else [{"name": "d_x", "method": "jbf", "label": "d_x"}]
            names.append(denoisers[0] if isinstance(denoisers[0], str) else denoisers[0]["name"])
            modules.add("jbf" if denoisers[0] != "oidn" else "oidn")
        config["denoisers"] = denoisers
    else:
        for name in DEFAULTS["denoisers"]:
            if name not in names:
                names.append(name)
            labels.add(CATALOGUE[name]["label"])
            modules.add(name)
    names += [c["name"] for c in pool_combiners]

    # -- combiners: the defaults when their inputs are all there, else (or when drawn) our own
    default_combiners = DEFAULTS["combiners"]
    default_inputs = {i for c in default_combiners for i in c["inputs"]} - {c["name"] for c in default_combiners}
    progressive = False
    if default_inputs <= set(names) and draw(st.booleans()):
        modules |= {c["method"] for c in default_combiners}
        progressive = True
    else:
        combiners, roles = [], set()
        for index in range(draw(st.integers(0, max_combiners))):
            module = draw(st.sampled_from(COMBINERS))
            count = CATALOGUE[module]["inputs"] or draw(st.integers(1, min(4, len(names))))
            inputs = draw(st.lists(st.sampled_from(names), min_size=count, max_size=count, unique=True))
            params = draw(params_strategy(module))
            if module == "ensemble" and not params and frozenset(inputs) in pool_sets:
                continue
            role = comparison_role({"module": module, "inputs": inputs, "params": params,
                                    "comparison_role": methods.method_spec(methods.load_method(module)).comparison_role})
            if role is not None:
                if (frozenset(inputs), role) in roles:
                    continue
                roles.add((frozenset(inputs), role))
            name = f"c{index}_{module[:4]}{draw(NAME_TAIL)}"
            entry = {"name": name, "method": module, "inputs": inputs, **({"params": params} if params else {})}
            label = _labelled(draw, entry, _default_label(module, inputs, params), labels)
            labels.add(label)
            combiners.append(entry)
            names.append(name)
            modules.add(module)
            progressive |= module == "progressive"
        config["combiners"] = combiners

    # -- scenes, spp, metrics, resolution
    if draw(st.booleans()):
        config["scenes"] = draw(st.lists(st.sampled_from(SCENES), min_size=1, max_size=max_scenes, unique=True))
    scenes = config.get("scenes", DEFAULTS["scenes"])
    if draw(st.booleans()):
        config["spp"] = draw(st.lists(SPP_VALUES if not small else st.sampled_from([2, 4, 8, 16]),
                                      min_size=1, max_size=max_spp, unique=True))
    if draw(st.booleans()):
        config["metrics"] = draw(st.permutations(available_metrics()).flatmap(
            lambda order: st.integers(1, len(order)).map(lambda n: list(order[:n]))))
    if draw(st.booleans()):
        config["resolution"] = draw(st.one_of(st.none(), st.lists(st.integers(11, 96 if small else 700), min_size=2, max_size=2)))

    # -- the oracle and the progressive curve
    oracle = draw(st.fixed_dictionaries({}, optional={
        "scene": st.one_of(st.none(), st.sampled_from(scenes)),
        "denoisers": st.lists(st.sampled_from(DENOISERS), min_size=2, max_size=10, unique=True),
        "repetitions": st.integers(2, 1023), "spp": st.integers(1, 64).map(lambda k: 2 * k),
        "downscale": st.integers(1, 5)}))
    if oracle or draw(st.booleans()):
        config["oracle"] = oracle
    curve = draw(st.fixed_dictionaries({}, optional={
        "scene": st.one_of(st.none(), st.sampled_from(scenes)),
        "spp": st.lists(st.integers(1, 4096).map(lambda k: 2 * k), min_size=2, max_size=6, unique=True),
        "base": st.sampled_from(DENOISERS),
        "divergence": st.sampled_from(("none", *methods.single_image_methods())),
        "downscale": st.integers(1, 4)}))
    if curve or draw(st.booleans()):
        config["progressive_curve"] = curve

    # -- references: more samples than every image they score, split into even chunks
    spps = config.get("spp", DEFAULTS["spp"])
    need = max(spps) + 1
    need = max(need, oracle.get("spp", DEFAULTS["oracle"]["spp"]) + 1)
    if progressive:
        need = max(need, max(curve.get("spp", DEFAULTS["progressive_curve"]["spp"])) + 1)
    reference: dict = {}
    chunks = draw(st.one_of(st.sampled_from([1, 2, 4, 8, 16, 64, 256]), st.integers(1, 256)))
    default_spp = DEFAULTS["reference"]["spp"]

    def reference_spp(extra):
        per_chunk = -(-need // chunks)
        per_chunk += per_chunk % 2
        return chunks * (per_chunk + 2 * extra)

    splits_default = default_spp % chunks == 0 and (default_spp // chunks) % 2 == 0
    if default_spp >= need and splits_default and draw(st.booleans()):
        if chunks != DEFAULTS["reference"]["chunks"] or draw(st.booleans()):
            reference["chunks"] = chunks
    else:
        reference["chunks"] = chunks
        reference["spp"] = reference_spp(draw(st.integers(0, 64)))
    if draw(st.booleans()):
        named = draw(st.lists(st.sampled_from(SCENES), max_size=3, unique=True))
        reference["scene_spp"] = {scene: reference_spp(draw(st.integers(0, 512))) for scene in named}
    if reference or draw(st.booleans()):
        config["reference"] = reference

    # -- training: seeds within their ranges, crops that fit, a learned combiner's subset
    learned_combiner = any(CATALOGUE[m]["learned"] and CATALOGUE[m]["kind"] == "combiner" for m in modules)
    training: dict = {}
    if draw(st.booleans()):
        t = DEFAULTS["training"]
        count = draw(st.integers(1, 300))
        first = draw(st.integers(0, 32768 - count))
        fibre = draw(st.integers(0, 64))
        side = draw(st.integers(16, 256))
        crop = draw(st.integers(8, side))
        cells = (side // crop) ** 2
        crops = draw(st.integers(1, min(cells, 8)))
        chosen = {"first_seed": first, "count": count, "fibre_count": fibre, "resolution": [side, side], "crop": crop,
                  "crops": crops, "spp": draw(st.lists(st.sampled_from([2 ** k for k in range(1, 16)]), min_size=1,
                                                       max_size=5, unique=True)),
                  "target_spp": draw(st.integers(2, 2 ** 20)),
                  "combiners": {"count": draw(st.integers(1, count)), "fibre_count": draw(st.integers(0, fibre)),
                                "crops": draw(st.integers(1, crops))}}
        for key, value in chosen.items():
            if draw(st.booleans()):
                training[key] = value
        # what is left out must agree with what is set (and the defaults with each other)
        merged = {**t, **training, "combiners": {**t["combiners"], **training.get("combiners", {})}}
        if merged["first_seed"] + merged["count"] > 32768 or merged["crop"] > min(merged["resolution"]) or \
                max(merged["crops"], merged["combiners"]["crops"]) > (merged["resolution"][0] // merged["crop"]) * (
                    merged["resolution"][1] // merged["crop"]) or (learned_combiner and any(
                    merged["combiners"][k] > merged[k] for k in ("count", "fibre_count", "crops"))):
            training = chosen
        networks = sorted(m for m in modules if CATALOGUE[m]["learned"])
        if networks and draw(st.booleans()):
            training["networks"] = {name: draw(st.fixed_dictionaries({}, optional={
                "steps": st.integers(1, 10 ** 6), "batch_size": st.integers(1, 64), "patch": st.integers(4, 128),
                "learning_rate": st.floats(1e-6, 1.0), "final_lr_fraction": st.floats(0, 1),
                "loss": st.sampled_from(["l1_log", "smape", "l1_log_gradient", "relmse"]), "seed": st.integers(0, 99)}))
                for name in draw(st.lists(st.sampled_from(networks), max_size=2, unique=True))}
    if training or draw(st.booleans()):
        config["training"] = training

    # -- the rest
    config.update(draw(st.fixed_dictionaries({}, optional={
        "variant": st.sampled_from(SCHEMA["properties"]["variant"]["enum"]), "seed": st.integers(0, 6),
        "render_threads": st.integers(1, 64), "weights_dir": st.none(),
        "gpus": st.integers(0, 8), "gpu_model": st.sampled_from(["", "a100", "h100", "rtx_4090"])})))
    # the curve's and the oracle's scenes default to the first scene; a progressive entry needs its
    # curve scene among the scenes (drawn from them above)
    return config


# --------------------------------------------------------------------------- the properties

_LEADING_KEY = re.compile(r"^(?:config key '(?P<quoted>[^']+)'|(?P<plain><config>|[A-Za-z_][A-Za-z0-9_]*"
                          r"(?:\[\d+\]|\['[^']*'\]|\.[^\s:.\[\]()']+)*))")


def _parts(key: str) -> list:
    return [int(i) if i else (q if q or not n else n) for i, q, n in
            re.findall(r"\[(\d+)\]|\['([^']*)'\]|\.?([^.\[\]]+)", key)]


def leading_key(message: str) -> list:
    """The key path an error message starts with (after the source)."""
    assert message.startswith(f"{SOURCE}: "), message
    match = _LEADING_KEY.match(message[len(SOURCE) + 2:])
    assert match, f"the message names no config key first: {message}"
    key = match.group("quoted") or match.group("plain")
    return [] if key == "<config>" else _parts(key)


def _written_prefix_missing(parts: list, written) -> bool:
    """Whether the config as written lacks the key (or a key above it)."""
    node = written
    for part in parts:
        if isinstance(node, dict):
            if part not in node:
                return True
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            node = node[part]
        else:
            return False
    return False


def _related(a: list, b: list) -> bool:
    n = min(len(a), len(b))
    return n > 0 and a[:n] == b[:n]


# Parsing a config takes milliseconds; a config that makes it loop (a huge downscale did) fails
# the example instead of hanging the suite.
PARSE_SECONDS = 60


@contextlib.contextmanager
def _time_limit(seconds: int):
    def stop(signum, frame):
        signal.alarm(1)      # again in a second if this one lands where it is swallowed (a gc callback)
        raise AssertionError(f"resolving and planning the config took over {seconds} s")

    previous = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def check(config, *, near: list | None = None) -> str:
    """Resolve and plan ``config``: either the plan holds every configured candidate, metric and
    case, or a BenchError names a key (``near``: the mutated key, which a schema error must be
    at or above/below) and, for a key the config never wrote, says it is a default."""
    written = copy.deepcopy(config)
    try:
        with _time_limit(PARSE_SECONDS):
            resolved = resolve_config(copy.deepcopy(config), source=SOURCE)
            digest = config_digest(resolved)
            plan = plan_study(resolved, written=written if isinstance(written, dict) else None, source=SOURCE)
    except BenchError as error:
        message = str(error)
        note(f"refused: {message}")
        parts = leading_key(message)
        assert not parts or parts[0] in TOP_KEYS, message
        if isinstance(error, ConfigError) and near is not None and parts and "is not a string" not in message:
            assert _related(parts, near) or key_path(near) in message, (key_path(near), message)
        if parts and isinstance(written, dict) and _written_prefix_missing(parts, written):
            assert "schema's default" in message and "to override it" in message, message
        event(f"refused at {parts[0] if parts else '<config>'}")
        return "refused"
    assert len(digest) == 16
    check_plan(resolved, plan)
    event("planned")
    return "planned"


def check_plan(config: dict, plan) -> None:
    """Every configured candidate, metric and case is in the plan; ranked and extras split it."""
    own = [d if isinstance(d, str) else d["name"] for d in config["denoisers"]] + [c["name"] for c in config["combiners"]]
    if config["study"]["pool"]:
        denoisers, combiners = pool_methods(config["study"]["ensembles"])
        pool = denoisers + [c["name"] for c in combiners]
        assert set(pool) <= set(plan.methods)
        # the slice, and every other pool candidate the config runs (a base among its denoisers)
        assert set(pool) <= set(list(plan.ranking.ranked)) <= POOL_NAMES
    else:
        assert list(plan.ranking.ranked), "no candidate to rank"
    assert set(own) <= set(plan.methods)
    assert list(plan.ranking.candidates) == list(plan.methods)
    assert sorted(list(plan.ranking.ranked) + list(plan.ranking.extras)) == sorted(list(plan.ranking.candidates))
    assert not set(list(plan.ranking.ranked)) & set(list(plan.ranking.extras))
    assert list(plan.ranking.metrics) == config["metrics"]
    assert sorted(plan.cases.pairs) == sorted(itertools.product(config["scenes"], config["spp"]))
    assert list(plan.cases.spps) == sorted(config["spp"])
    assert set(dict(plan.cases.reference_spp)) == set(config["scenes"])
    assert all(spp > max(config["spp"]) for spp in dict(plan.cases.reference_spp).values())
    assert plan.side.oracle_scene in config["scenes"]
    # what the plan accepts, the jobs can run: the decisions of mcbench.pipeline.plan
    assert config["study"]["ensembles"] is None or set(config["study"]["ensembles"]) <= set(ENSEMBLE_IDS)
    assert all(s <= 2048 or s % 2048 == 0 and s <= 2048 * 1024 for s in config["spp"])
    for spec in plan.methods.values():
        assert len(spec.inputs) == len(set(spec.inputs))
        expected = CATALOGUE[spec.module]["inputs"]
        assert expected is None or len(spec.inputs) == expected, spec
    training = config["training"]
    assert training["first_seed"] + training["count"] <= 32768
    assert all(s & (s - 1) == 0 and s <= 32768 for s in training["spp"])
    assert training["crop"] <= min(training["resolution"])
    labels = list(plan.ranking.labels.values())
    assert len(labels) == len(set(labels))
    for name, spec in plan.methods.items():
        position = list(plan.ranking.candidates).index(name)
        assert all(list(plan.ranking.candidates).index(i) < position for i in spec.inputs)


COMMON = dict(deadline=None, derandomize=True, database=None, print_blob=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])


# --------------------------------------------------------------------------- mutations

ODD_STRINGS = ["", " ", "é", "名前", "a b", "a\nb", "tab\t", "\x00", "x" * 300, "-", "../..", "noisy", "NOISY",
               "Noisy input", "1abc", "oidn", "ens27", "nfor_dc", "\u202eevil", "😀", "yes", "null", "0x10"]
WRONG_VALUES = [None, True, False, 0, -1, 1.5, 4.0, 2 ** 31, 2 ** 63, 10 ** 30, "4", "", [], {}, [None], [[]],
                {"": 1}, {"a": None}, float("nan"), float("inf"), -float("inf")]
HUGE = [2 ** 31, 2 ** 32 + 2, 2 ** 62, 2 ** 63, 10 ** 30, 2 ** 40, 2 ** 21 + 2048, 2050, 4098]
YAML_SCALARS = ["yes", "no", "on", "off", "y", "n", "True", "NULL", "null", "~", "1e3", "1.0e3", "0x10", "0o17", "017",
                "0b101", "1_000", "+4", "-4", ".inf", "-.inf", ".nan", "4.", '"4"', "'yes'", "2001-12-14",
                "2001-12-14t21:59:43.10-05:00", "1:30", "12:30:00", "!!binary aGVsbG8=", "!!str 4", "!!float 4",
                '!!int "4"', "[]", "{}", "[4, 4]", "&anchor 4", "*undefined", '"\\0"', '"\\u00e9"', "ünï", '""',
                "''", "!!set {a, b}", "!!python/object/apply:os.getcwd []", "!!omap [a: 1]", "{a: 1, a: 2}", "|\n  x"]
YAML_KEYS = ["yes", "no", "1", "4", "null", "~", "1.5", "0x10", "2001-12-14", '"4"', "on", "[a, b]", "? x"]
YAML_DOCUMENTS = ["", "---", "~", "[]", "42", "- a\n- b", "just text", "{", "a: [", "\t- x", "%YAML 1.1\n---\na: 1"]


def _paths(value, path=()):
    """Every (path, value) below the config."""
    yield list(path), value
    if isinstance(value, dict):
        for key, sub in value.items():
            yield from _paths(sub, path + (key,))
    elif isinstance(value, list):
        for index, sub in enumerate(value):
            yield from _paths(sub, path + (index,))


def _get(config, path):
    for part in path:
        config = config[part]
    return config


def _set(config, path, value):
    _get(config, path[:-1])[path[-1]] = value


def _with_defaults(config: dict) -> dict:
    """The config with the defaults of the keys it leaves out written in (so that a mutation can
    reach them too; e.g. mutating the default combiners)."""
    out = copy.deepcopy(DEFAULTS)
    for key, value in config.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = {**out[key], **copy.deepcopy(value)}
        else:
            out[key] = copy.deepcopy(value)
    return out


MUTATIONS = ["wrong_type", "out_of_range", "unknown_name", "duplicate", "cycle", "empty_list", "huge", "odd_string",
             "unknown_key", "drop_key", "drop_entry", "ensembles", "reference_low", "non_finite"]


@st.composite
def mutated_configs(draw):
    """A valid config with one to three mutations; returns ``(config, near)`` with ``near`` the
    key a schema error must be related to (the single mutation's key), or None."""
    config = draw(valid_configs())
    if draw(st.booleans()):
        config = _with_defaults(config) if draw(st.booleans()) else config
    near = None
    count = draw(st.integers(1, 3))
    for _ in range(count):
        kind = draw(st.sampled_from(MUTATIONS))
        note(f"mutation: {kind}")
        paths = [p for p, _ in _paths(config) if p]
        leaves = [p for p in paths if not isinstance(_get(config, p), (dict, list))]
        lists = [p for p in paths if isinstance(_get(config, p), list)]
        path = None
        if kind in ("wrong_type", "non_finite", "odd_string", "huge") and leaves:
            path = draw(st.sampled_from(leaves))
            value = {"wrong_type": st.sampled_from(WRONG_VALUES), "non_finite": st.sampled_from(
                [float("nan"), float("inf"), -float("inf")]), "odd_string": st.sampled_from(ODD_STRINGS),
                "huge": st.sampled_from(HUGE)}[kind]
            _set(config, path, copy.deepcopy(draw(value)))      # never the shared list or dict itself
        elif kind == "out_of_range":
            numbers = [p for p in leaves if isinstance(_get(config, p), int) and not isinstance(_get(config, p), bool)]
            if numbers:
                path = draw(st.sampled_from(numbers))
                _set(config, path, draw(st.sampled_from([-1, 0, 1, 3, 5, 7, 10 ** 6, -(2 ** 40)])))
        elif kind == "unknown_name":
            named = [p for p in leaves if isinstance(_get(config, p), str)
                     and (p[0] in ("scenes", "denoisers", "oracle", "metrics") or p[-1] in ("method", "base", "scene")
                          or "inputs" in p)]
            if named:
                path = draw(st.sampled_from(named))
                _set(config, path, draw(st.sampled_from(["no_such_thing", "Oidn", "cornell_box2", "ensemble",
                                                         "progressive", "jbf", "kpcn_dc", "ens40"])))
        elif kind == "duplicate" and lists:
            path = draw(st.sampled_from(lists))
            items = _get(config, path)
            if items:
                items.insert(draw(st.integers(0, len(items))), copy.deepcopy(draw(st.sampled_from(items))))
        elif kind == "cycle" and config.get("combiners"):
            combiners = config["combiners"]
            index = draw(st.integers(0, len(combiners) - 1))
            target = draw(st.integers(index, len(combiners) - 1))
            if isinstance(combiners[index], dict) and isinstance(combiners[target], dict) and \
                    isinstance(combiners[index].get("inputs"), list):
                combiners[index]["inputs"].append(combiners[target].get("name"))
                path = ["combiners", index, "inputs"]
            if len(combiners) > 1 and draw(st.booleans()):
                i, j = draw(st.lists(st.integers(0, len(combiners) - 1), min_size=2, max_size=2, unique=True))
                combiners[i], combiners[j] = combiners[j], combiners[i]
                path = None
        elif kind == "empty_list" and lists:
            path = draw(st.sampled_from(lists))
            _set(config, path, [])
        elif kind == "unknown_key":
            objects = [p for p in [[]] + paths if isinstance(_get(config, p), dict)]
            path = draw(st.sampled_from(objects))
            key = draw(st.sampled_from(["sceness", "spp ", "Name", "inptus", "parms", "ünknown", "", "1", "null"]))
            _get(config, path)[key] = draw(st.sampled_from([1, "x", None, [], {}]))
            path = path + [key] if path else None
        elif kind == "drop_key":
            keyed = [p for p in paths if isinstance(p[-1], str)]
            if keyed:
                path = draw(st.sampled_from(keyed))
                del _get(config, path[:-1])[path[-1]]
                path = None
        elif kind == "drop_entry":
            filled = [p for p in lists if _get(config, p)]
            if filled:
                items = _get(config, draw(st.sampled_from(filled)))
                del items[draw(st.integers(0, len(items) - 1))]
        elif kind == "ensembles":
            value = draw(st.one_of(st.lists(st.integers(-2, 42), min_size=0, max_size=4),
                                   st.sampled_from([[8], [1, 9], [9, 9], [0], [40], "10", 10, [10.0], [True]])))
            config.setdefault("study", {})
            if isinstance(config["study"], dict):
                config["study"]["ensembles"] = value
                path = ["study", "ensembles"]
        elif kind == "reference_low":
            config.setdefault("reference", {})
            if isinstance(config["reference"], dict):
                spps = config.get("spp", DEFAULTS["spp"])
                top = max([s for s in spps if isinstance(s, int)] or [4])
                config["reference"]["spp"] = draw(st.sampled_from([top, top // 2, 2, top - 2]))
        near = path if count == 1 else None
    return config, near


@st.composite
def yaml_texts(draw):
    """A valid config dumped to YAML with a scalar, a key or the whole document replaced by a
    YAML oddity, for ``yaml.safe_load`` (as Snakemake reads a config file)."""
    config = draw(valid_configs())
    choice = draw(st.sampled_from(["scalar", "key", "document"]))
    if choice == "document":
        return draw(st.sampled_from(YAML_DOCUMENTS))
    paths = [p for p, v in _paths(config) if p and not isinstance(v, (dict, list))]
    objects = [p for p, v in _paths(config) if isinstance(v, dict)]
    if choice == "scalar" and paths:
        path = draw(st.sampled_from(paths))
        _set(config, path, "__ODD_VALUE__")
        token = draw(st.sampled_from(YAML_SCALARS))
    else:
        path = draw(st.sampled_from(objects))
        _get(config, path)["__ODD_KEY__"] = 1
        token = draw(st.sampled_from(YAML_KEYS))
    text = yaml.safe_dump(config, allow_unicode=True, sort_keys=False)
    return text.replace("__ODD_VALUE__", token).replace("__ODD_KEY__", token)


def _check_text(text: str) -> str:
    note(f"yaml text:\n{text}")
    try:
        config = parse_config_text(text, source=SOURCE)
    except ConfigError as error:
        assert str(error).startswith(f"{SOURCE}: not valid YAML"), error
        event("not YAML")
        return "refused"
    if config is None:      # an empty document: the schema's defaults
        config = {}
    if not isinstance(config, dict):
        with pytest.raises(ConfigError, match=r"must be a mapping|^" + re.escape(SOURCE)):
            resolve_config(config, source=SOURCE)
        event("not a mapping")
        return "refused"
    return check(config)


# --------------------------------------------------------------------------- the tests

@settings(max_examples=200, **COMMON)
@given(valid_configs())
def test_generated_valid_configs_plan_every_candidate_metric_and_case(config):
    assert check(config) == "planned"


@settings(max_examples=300, **COMMON)
@given(mutated_configs())
def test_mutated_configs_plan_or_stop_naming_the_key(case):
    config, near = case
    check(config, near=near)


@settings(max_examples=150, **COMMON)
@given(yaml_texts())
def test_yaml_oddities_plan_or_stop_naming_the_key(text):
    _check_text(text)


@pytest.mark.fuzz
@settings(max_examples=1000, **COMMON)
@given(valid_configs())
def test_many_generated_valid_configs_plan(config):
    assert check(config) == "planned"


@pytest.mark.fuzz
@settings(max_examples=2000, **COMMON)
@given(mutated_configs())
def test_many_mutated_configs_plan_or_stop_naming_the_key(case):
    config, near = case
    check(config, near=near)


@pytest.mark.fuzz
@settings(max_examples=1000, **COMMON)
@given(yaml_texts())
def test_many_yaml_oddities_plan_or_stop_naming_the_key(text):
    _check_text(text)


# --------------------------------------------------------------------------- real dry runs

def _dry_run(workdir: Path, config: dict, *args: str) -> subprocess.CompletedProcess:
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config, allow_unicode=True))
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
               "--configfile", str(workdir / "config.yaml"), "--cores", "2", "-n", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=600, check=False)


@pytest.mark.fuzz
@settings(max_examples=4, **COMMON)
@given(valid_configs(max_scenes=2, max_spp=2, max_denoisers=3, max_combiners=3, small=True))
def test_snakemake_dry_run_of_generated_configs_plans_what_the_planner_says(tmp_path_factory, config):
    """``snakemake -n`` on a generated config plans a job for every case of every candidate and
    every metric table, the same as :func:`plan_study` (the function its parse calls)."""
    resolved = resolve_config(copy.deepcopy(config), source=SOURCE)
    plan = plan_study(resolved, written=config, source=SOURCE)
    result = _dry_run(tmp_path_factory.mktemp("generated"), config)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-4000:]
    cases = plan.cases.pairs
    for scene, spp in cases:
        assert f"results/cases/{scene}/spp{spp}.json" in text, (scene, spp)
    counts = dict(re.findall(r"^(\w+)\s+(\d+)$", text, flags=re.MULTILINE))
    assert int(counts["render_noisy"]) == len(cases) and int(counts["run_case"]) == len(cases)
    assert int(counts["ranking_table"]) == len(list(plan.ranking.metrics)) == int(counts["extras_table"])
    # a reference is merged from chunks where this run renders it, copied where the store holds it
    assert int(counts.get("merge_reference", 0)) == len(plan.cases.rendered_references)
    assert int(counts.get("stored_reference", 0)) == len(plan.cases.stored_references)
    # one job per case (its methods, evaluations and tables), whatever exists
    assert ("study_tables" in counts) == plan.ranking.pool_study
    assert ("progressive_tables" in counts) == bool(plan.side.progressive)


# --------------------------------------------------------------------------- the defects, one by one
# Each config below is the minimal example of a defect class (found by the generator, or on the
# way to it): planned without its check, each would fail in a job, stop with a bare traceback,
# hang, or name the wrong key.

def _refusal(config) -> str:
    """The message of the BenchError that resolving and planning ``config`` stops with."""
    with pytest.raises(BenchError) as error, _time_limit(PARSE_SECONDS):
        resolved = resolve_config(copy.deepcopy(config), source=SOURCE)
        config_digest(resolved)
        plan_study(resolved, written=config, source=SOURCE)
    return str(error.value)


def _plans(config) -> dict:
    resolved = resolve_config(copy.deepcopy(config), source=SOURCE)
    return plan_study(resolved, written=config, source=SOURCE)


OWN = {"study": {"pool": False}, "combiners": []}     # no pool, no default combiners


@pytest.mark.parametrize("config, start", [
    # 8 is a base (RDFC), not an ensemble: ensembles are #9-#39 (it planned a one-candidate "pool")
    ({"study": {"ensembles": [8]}}, "study.ensembles[0]: 8 is base #8 (rdfc), not an ensemble"),
    ({"study": {"ensembles": [10, 1]}}, "study.ensembles[1]: 1 is base #1 (kpcn), not an ensemble"),
    ({"study": {"ensembles": [0]}}, "study.ensembles[0]: 0 is not an ensemble"),
    # a reference with fewer samples than the renders it scores (or as many: its own noise is as
    # large as the error it measures) -- decided: the reference must have more
    ({"spp": [4, 64], "reference": {"spp": 16, "chunks": 1}}, "reference.spp: the reference of 'cornell_box' has 16 spp"),
    ({"spp": [4, 64], "reference": {"spp": 64, "chunks": 1}}, "reference.spp: the reference of 'cornell_box' has 64 spp"),
    ({"scenes": ["furball"], "spp": [4, 64], "reference": {"scene_spp": {"furball": 32}}},
     "reference.scene_spp.furball: the reference of 'furball' has 32 spp"),
    ({"spp": [4], "reference": {"spp": 8, "chunks": 1}, "oracle": {"spp": 64}, **OWN, "denoisers": ["oidn"]},
     "oracle.spp: 64 spp is not below"),
    ({"spp": [4], "reference": {"spp": 1024, "chunks": 1}, "progressive_curve": {"spp": [4, 8192]}, "study": {"pool": False},
      "denoisers": ["oidn"], "combiners": [{"name": "pd", "method": "progressive", "inputs": ["oidn"]}]},
     "progressive_curve.spp[1]: 8192 spp is not below the 4096 spp"),
    # spp without a render seed code: planned, then every render job of that spp failed
    ({"spp": [2050], "reference": {"spp": 65536}}, "spp[0]: 2050 spp has no render seed code"),
    ({"spp": [2 ** 40], "reference": {"spp": 2 ** 42}}, "spp[0]: 1099511627776 spp has no render seed code"),
    # a combiner of exactly one input given two (progressive, deep_combiner): failed in its job
    ({**OWN, "denoisers": ["oidn", "jbf"], "combiners": [{"name": "pd", "method": "progressive", "inputs": ["oidn", "jbf"]}]},
     "combiners[0].inputs: progressive combines exactly 1 input(s), got 2"),
    # the same input twice
    ({**OWN, "denoisers": ["oidn", "jbf"], "combiners": [{"name": "e", "method": "ensemble", "inputs": ["oidn", "oidn"]}]},
     "combiners[0].inputs[1]: 'oidn' is already inputs[0]"),
    # two methods in one comparison role: planned, then the comparison tables failed after the run
    ({**OWN, "denoisers": ["oidn", "jbf"], "combiners": [
        {"name": "a", "method": "one_hot", "inputs": ["oidn", "jbf"], "params": {"prefilter": "sbf"}},
        {"name": "b", "method": "one_hot", "inputs": ["jbf", "oidn"], "params": {"prefilter": "sbf"}}]},
     "combiners[1]: methods 'a' and 'b' are both the one-hot sbf"),
    # a config line named like a pool candidate: the error named the pool's entry, not the line
    ({"denoisers": [{"name": "nfor_dc", "method": "oidn"}], "combiners": []},
     "denoisers[0].name: 'nfor_dc' is the name of candidate #2 of the pool"),
    ({"denoisers": [{"name": "x", "method": "oidn", "label": "#27 KPCN+NFOR+OIDN+RDFC"}], "combiners": []},
     "denoisers[0].label: '#27 KPCN+NFOR+OIDN+RDFC' is also the label of 'ens27'"),
    # an unknown curve scene without a progressive entry: the error named `scenes`
    ({**OWN, "denoisers": ["oidn"], "progressive_curve": {"scene": "no_such_scene"}},
     "config key 'progressive_curve.scene': unknown scene 'no_such_scene'"),
    # a huge downscale made the parse loop (usable_downscale counts down from it)
    ({"oracle": {"downscale": 2 ** 40}}, "oracle.downscale: 1099511627776 is greater than the maximum of 372"),
    ({"progressive_curve": {"downscale": 10 ** 9}}, "progressive_curve.downscale: 1000000000 is greater than"),
    # mapping keys that are not strings (YAML's 1, yes, null): a mix of them crashed the digest
    ({**OWN, "denoisers": [{"name": "j", "method": "jbf", "params": {1: 2, "radius": 3}}]},
     "denoisers[0].params: key 1 is not a string"),
    ({"reference": {"scene_spp": {True: 65536}}}, "reference.scene_spp: key True is not a string"),
    ({None: 1}, "<config>: key None is not a string"),
    # NaN and infinity pass JSON Schema's bounds
    ({"training": {"networks": {"kpcn": {"learning_rate": float("nan")}}}},
     "training.networks.kpcn.learning_rate: nan is not a finite number"),
    ({"training": {"networks": {"kpcn": {"final_lr_fraction": float("inf")}}}},
     "training.networks.kpcn.final_lr_fraction: inf is not a finite number"),
    # control characters: a label's line break split table rows, a NUL in weights_dir raised ValueError
    ({**OWN, "denoisers": [{"name": "j", "method": "jbf", "label": "two\nlines"}]},
     "denoisers[0].label: 'two\\nlines' holds a control character"),
    ({"weights_dir": "w\x00"}, "weights_dir: 'w\\x00' holds a control character"),
    # training values only the training jobs refused
    ({"training": {"spp": [6]}}, "training.spp[0]: 6 is not a power of two"),
    ({"training": {"spp": [4, 4]}}, "training.spp: [4, 4] has non-unique elements"),
    ({"training": {"crop": 200}}, "training.crop: a 200x200 crop does not fit training.resolution 128x128"),
    ({"training": {"crop": 64, "crops": 5}}, "training.crops: 5 disjoint 64x64 crops do not fit"),
    ({"training": {"first_seed": 32700}}, "training.count: training.first_seed 32700 + training.count 128"),
    # a oneOf error reported at the branch that fits the value
    ({"resolution": [8, 64]}, "resolution[0]: 8 is less than the minimum of 11"),
    ({"denoisers": [5]}, "denoisers[0]: 5 is not of type 'string' or 'object'"),
    ({"study": {"ensembles": "10"}}, "study.ensembles: '10' is not of type 'null' or 'array'"),
])
def test_defect_stops_before_any_job_naming_the_key(config, start):
    message = _refusal(config)
    assert message.startswith(f"{SOURCE}: {start}"), message


@pytest.mark.parametrize("config, key, default", [
    # the default combiners name denoisers the config's own list dropped
    ({"denoisers": ["oidn"]}, "combiners", "the schema's default (40 entries)"),
    ({"study": {"pool": False}, "denoisers": ["oidn", "jbf"]}, "combiners", "the schema's default (40 entries)"),
    # the default reference under the config's spp
    ({"spp": [4, 32768]}, "reference.spp", "the schema's default 16384"),
    # the config's reference.spp, the default chunks
    ({"reference": {"spp": 1002}}, "reference.chunks", "the schema's default 4"),
    # the config's reference under the default spp levels
    ({"reference": {"spp": 1000}}, "spp", "the schema's default (9 entries)"),
    # a smaller training set than the learned combiners' default subset (the pool has DC variants)
    ({"training": {"count": 24}}, "training.combiners.count", "the schema's default 48"),
    # the default curve levels above the config's reference (the default combiners hold PD entries)
    ({"spp": [4], "reference": {"spp": 1024}}, "progressive_curve.spp", "the schema's default (12 entries)"),
    # a pool candidate's clash: the pool is on by default
    ({"combiners": [{"name": "mine", "method": "ensemble", "inputs": ["kpcn", "nfor"]}]}, None, None),
])
def test_an_error_about_a_default_says_so_and_how_to_override_it(config, key, default):
    message = _refusal(config)
    if key is None:
        assert "study.pool" in message, message
        return
    assert f"[{key} is not set in {SOURCE}: it is {default} from workflow/schemas/config.schema.yaml; " \
           f"set {key} in the config to override it]" in message, message


def test_a_default_the_config_never_touches_gets_no_note():
    message = _refusal({"spp": [4, 64], "reference": {"spp": 16, "chunks": 1}})
    assert "schema's default" not in message


@pytest.mark.parametrize("text, expected", [
    ("spp: [1e3]\n", "spp[0]: '1e3' is not of type 'integer'"),          # YAML 1.1: a string, not 1000
    ("spp: [4.]\n", "spp[0]: 4.0 is not of type 'integer'"),
    ("scenes: [no]\n", "scenes[0]: False is not of type 'string'"),      # no: a boolean
    ("metrics: [null]\n", "metrics[0]: None is not of type 'string'"),
    ("yes: 1\n", "<config>: key True is not a string"),
    ("reference: {scene_spp: {1: 4096}}\n", "reference.scene_spp: key 1 is not a string"),
    ("study: {ensembles: [0x8]}\n", "study.ensembles[0]: 8 is base #8 (rdfc)"),
    ("spp: [.nan]\n", "spp[0]: nan is not a finite number"),
    ("gpu_model: !!binary aGVsbG8=\n", "gpu_model: b'hello' is not of type 'string'"),
    ("label_date: 2001-12-14\n", "<config>: Additional properties are not allowed"),
    ("spp: *nowhere\n", "not valid YAML"),
    ("oracle: !!python/object/apply:os.getcwd []\n", "not valid YAML"),
])
def test_yaml_oddities_stop_naming_the_key(text, expected):
    with pytest.raises(BenchError) as error:
        config = parse_config_text(text, source=SOURCE)
        plan_study(resolve_config(config, source=SOURCE), written=config, source=SOURCE)
    assert expected in str(error.value), str(error.value)


@pytest.mark.parametrize("text, check", [
    ("spp: [0x10, 040]\n", lambda p: list(p.cases.spps) == [16, 32]),   # YAML 1.1 hex, octal
    ("spp: [1_024]\n", lambda p: list(p.cases.spps) == [1024]),
    ("add_denoisers: [jbf]\ndenoisers: [oidn]\ncombiners: []\nstudy: {pool: no}\n", lambda p: list(p.methods) == ["oidn", "jbf"]),
    ("resolution: ~\n", lambda p: p.side.oracle_downscale == 2),
    ("study: {ensembles: [10, 15], pool: yes}\n", lambda p: "ens10" in p.ranking.ranked and "ens15" in p.ranking.ranked),
])
def test_yaml_oddities_that_mean_something_plan_it(text, check):
    config = parse_config_text(text, source=SOURCE)
    assert check(plan_study(resolve_config(config, source=SOURCE), written=config, source=SOURCE))


def test_the_schema_holds_the_checks_the_code_names():
    """One pattern of one line of text (``ONE_LINE``); downscale bounded (usable_downscale counts
    down from it); ensembles are #9-#39."""
    from mcbench.analysis.metrics import DSSIM_MIN_SIZE
    from mcbench.pipeline.config import ONE_LINE

    properties = SCHEMA["properties"]
    assert SCHEMA["$defs"]["line"]["pattern"] == properties["weights_dir"]["pattern"] == \
        properties["gpu_model"]["pattern"] == ONE_LINE
    resolution_max = properties["resolution"]["oneOf"][1]["items"]["maximum"]
    for key in ("oracle", "progressive_curve"):
        assert properties[key]["properties"]["downscale"]["maximum"] == resolution_max // DSSIM_MIN_SIZE
    items = properties["study"]["properties"]["ensembles"]["oneOf"][1]["items"]
    assert (items["minimum"], items["maximum"]) == (min(ENSEMBLE_IDS), max(ENSEMBLE_IDS))


def test_a_reference_above_every_spp_plans():
    plan = _plans({"spp": [4, 64], "reference": {"spp": 128, "chunks": 1}, **OWN, "denoisers": ["oidn"],
                   "oracle": {"spp": 4}})
    assert dict(plan.cases.reference_spp) == {scene: 128 for scene in DEFAULTS["scenes"]}
    assert plan.cases.pairs[:2] == [("cornell_box", 4), ("cornell_box", 64)]


def test_the_plan_of_every_shipped_config_matches_what_the_snakefile_read_before():
    """The numbers the rules planned before the planner existed (``snakemake -n --quiet rules``,
    recorded per config): cases, candidates, ranked, extras."""
    expected = {"config.yaml": (72, 81, 39, 42), "workflow/configs/smoke.yaml": (6, 15, 6, 9),
                "workflow/configs/paper.yaml": (270, 44, 39, 5), "workflow/configs/deep_combiner.yaml": (72, 6, 6, 0),
                "workflow/configs/progressive.yaml": (72, 12, 12, 0)}
    for path, numbers in expected.items():
        config = yaml.safe_load((REPO / path).read_text())
        plan = plan_study(resolve_config(config, source=path), written=config, source=path)
        assert (len(plan.cases.pairs), len(list(plan.ranking.candidates)), len(list(plan.ranking.ranked)), len(list(plan.ranking.extras))) == numbers, path
