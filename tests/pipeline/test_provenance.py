"""mcbench.pipeline.provenance: the run's manifest. The truths are independent of the module: the
digest is recomputed with hashlib over json.dumps(sort_keys=True), the git state is made by git
in a temporary repository and read back with git itself, the CPU text is written by hand in
/proc/cpuinfo's layout."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess

import pytest

from mcbench.io.tables import read_json
from mcbench.pipeline.config import read_config_file
from mcbench.pipeline.provenance import (ABSENT, DISTRIBUTIONS, UNKNOWN, collect_provenance, cpu_info, git_state,
                                         mcbench_version, package_versions, write_manifest)
from tests.conftest import REPO, SMOKE_CONFIG

CPU_KEYS = {"avx2", "avx512f", "family", "logical_cores", "model", "model_number", "vendor"}
VERSION_KEYS = {"mitsuba", "drjit", "oidn", "torch", "numpy", "scipy", "flip_evaluator", "snakemake", "python", "mcbench"}

# /proc/cpuinfo's layout: one block per logical processor, "key\t: value", blank line between
CPUINFO = """processor\t: 0
vendor_id\t: GenuineIntel
cpu family\t: 6
model\t\t: 143
model name\t: Intel(R) Xeon(R) Platinum 8480+
flags\t\t: fpu sse2 avx avx2 fma avx512f avx512dq
bugs\t\t: spectre_v1

processor\t: 1
vendor_id\t: GenuineIntel
cpu family\t: 6
model\t\t: 143
model name\t: Intel(R) Xeon(R) Platinum 8480+
flags\t\t: fpu sse2 avx avx2 fma avx512f avx512dq
"""


def _git(repo, *args):
    env = {**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@t"}
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True, text=True,
                          env=env).stdout.strip()


def _digest(config: dict) -> str:
    """The canonical digest written from its definition: SHA-256 of the JSON with sorted keys."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@pytest.fixture(scope="module")
def smoke_config() -> dict:
    return read_config_file(SMOKE_CONFIG)


def test_the_manifest_holds_every_key_in_sorted_order(smoke_config):
    manifest = collect_provenance(repo_dir=REPO, config=smoke_config)
    assert list(manifest) == sorted(manifest) == ["config_digest", "cpu", "git", "manifest_version", "platform",
                                                  "versions"]
    assert set(manifest["cpu"]) == CPU_KEYS and list(manifest["cpu"]) == sorted(CPU_KEYS)
    assert set(manifest["versions"]) == VERSION_KEYS and list(manifest["versions"]) == sorted(VERSION_KEYS)
    assert set(manifest["git"]) == {"commit", "clean"}
    assert manifest["cpu"]["logical_cores"] == os.cpu_count()
    # the installed versions, as pip reports them (numpy: its own __version__)
    import numpy

    assert manifest["versions"]["numpy"] == numpy.__version__
    assert manifest["config_digest"] == _digest(smoke_config)
    json.dumps(manifest, allow_nan=False)      # a JSON record as it is


def test_the_config_digest_follows_values_not_key_order(smoke_config):
    base = collect_provenance(repo_dir=REPO, config=smoke_config)["config_digest"]
    reordered = dict(reversed(list(smoke_config.items())))
    reordered["study"] = dict(reversed(list(smoke_config["study"].items())))
    assert list(reordered) != list(smoke_config)
    assert collect_provenance(repo_dir=REPO, config=reordered)["config_digest"] == base
    changed = {**smoke_config, "study": {**smoke_config["study"], "seed": smoke_config["study"]["seed"] + 1}}
    assert collect_provenance(repo_dir=REPO, config=changed)["config_digest"] != base
    assert collect_provenance(repo_dir=REPO, config=changed)["config_digest"] == _digest(changed)


def test_git_state_tells_a_clean_tree_from_a_changed_one(tmp_path):
    repo = tmp_path / "checkout"
    repo.mkdir()
    _git(repo, "init", "-q")
    (repo / "a.txt").write_text("one\n")
    _git(repo, "add", "a.txt")
    _git(repo, "commit", "-q", "-m", "first")
    head = _git(repo, "rev-parse", "HEAD")
    assert git_state(repo) == {"commit": head, "clean": True}
    (repo / "a.txt").write_text("two\n")                      # a tracked file changed
    assert git_state(repo) == {"commit": head, "clean": False}
    _git(repo, "commit", "-q", "-am", "second")
    assert git_state(repo) == {"commit": _git(repo, "rev-parse", "HEAD"), "clean": True}
    (repo / "new.txt").write_text("untracked\n")              # an untracked file is a change
    assert git_state(repo)["clean"] is False
    (repo / ".gitignore").write_text("new.txt\n.gitignore\n")  # an ignored one is not
    assert git_state(repo)["clean"] is True


def test_no_git_gives_unknown(tmp_path, monkeypatch):
    # a folder outside any repository (GIT_CEILING_DIRECTORIES: git may not look above it)
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    plain = tmp_path / "plain"
    plain.mkdir()
    assert git_state(plain) == {"commit": UNKNOWN, "clean": UNKNOWN}
    assert git_state(tmp_path / "missing") == {"commit": UNKNOWN, "clean": UNKNOWN}
    # an empty repository: no commit yet
    _git(plain, "init", "-q")
    assert git_state(plain) == {"commit": UNKNOWN, "clean": UNKNOWN}
    # no git program at all
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    assert git_state(REPO) == {"commit": UNKNOWN, "clean": UNKNOWN}


def test_missing_packages_are_absent():
    versions = package_versions({"numpy": "numpy", "ghost": "no-such-distribution-for-mcbench-tests"})
    assert versions["ghost"] == ABSENT
    import numpy
    import platform

    assert versions == {"ghost": ABSENT, "numpy": numpy.__version__, "python": platform.python_version()}
    assert set(DISTRIBUTIONS) | {"python"} == VERSION_KEYS - {"mcbench"}
    assert DISTRIBUTIONS["oidn"] == "pyoidn"         # the binding methods/oidn.py imports


def test_cpu_info_reads_the_first_processor_and_the_exact_flags():
    cpu = cpu_info(CPUINFO, cores=112)
    assert cpu == {"avx2": True, "avx512f": True, "family": "6", "logical_cores": 112,
                   "model": "Intel(R) Xeon(R) Platinum 8480+", "model_number": "143", "vendor": "GenuineIntel"}
    # AVX-512 extensions without the foundation, and avx without avx2: whole flags, not substrings
    other = CPUINFO.replace("avx2 fma avx512f avx512dq", "fma avx512fp16 avx512_bf16")
    cpu = cpu_info(other, cores=2)
    assert cpu["avx2"] is False and cpu["avx512f"] is False


def test_cpu_info_without_proc_cpuinfo_is_unknown():
    cpu = cpu_info("", cores=4)
    assert {k: cpu[k] for k in ("avx2", "avx512f", "family", "model_number", "vendor")} == dict.fromkeys(
        ("avx2", "avx512f", "family", "model_number", "vendor"), UNKNOWN)
    assert cpu["logical_cores"] == 4 and isinstance(cpu["model"], str) and cpu["model"]


def test_mcbench_version_is_the_checkouts(tmp_path):
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "mcbench"\nversion = "9.8.7"\n')
    assert mcbench_version(tmp_path) == "9.8.7"
    import tomllib

    with open(REPO / "pyproject.toml", "rb") as handle:
        assert mcbench_version(REPO) == tomllib.load(handle)["project"]["version"]


def test_write_manifest_writes_json_and_markdown(tmp_path, smoke_config):
    json_path, md_path = tmp_path / "results/manifest.json", tmp_path / "results/manifest.md"
    manifest = write_manifest(str(json_path), str(md_path), repo_dir=REPO, config=smoke_config)
    assert read_json(json_path) == manifest                  # checksum side file written with it
    text = json_path.read_text()
    assert text == json.dumps(manifest, indent=2, sort_keys=True) + "\n"
    md = md_path.read_text()
    assert md.startswith("# Provenance of this run\n")
    assert f"`{manifest['git']['commit']}`" in md and f"`{manifest['config_digest']}`" in md
    assert [p.name for p in json_path.parent.iterdir() if p.name.endswith(".tmp")] == []


def test_the_study_step_ends_summary_md_with_the_manifests_block(tmp_path, smoke_config):
    """mcbench.pipeline.pool_study.write_study (rule study_tables) reads results/manifest.json and puts
    its short block last in summary.md; the other study files are the same as without it."""
    import numpy as np

    from mcbench.analysis.study.markdown import PROVENANCE_HEADING
    from mcbench.io.tables import write_csv
    from mcbench.pipeline.pool_study import write_study
    from tests.analysis.study.synthetic import tidy

    rng = np.random.default_rng(3)
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "noisy"]
    write_csv(tmp_path / "metrics.csv", tidy([(f"s{s}", spp, n, "relmse", float(rng.uniform(0.1, 1.0)))
                                              for s in range(3) for spp in (4, 64) for n in names]))
    manifest = write_manifest(str(tmp_path / "manifest.json"), str(tmp_path / "manifest.md"), repo_dir=REPO,
                              config=smoke_config)
    options = dict(metrics=["relmse"], labels={}, entries=names, n_resamples=200, seed=1)
    write_study(str(tmp_path / "metrics.csv"), str(tmp_path / "with"), manifest_json=str(tmp_path / "manifest.json"),
                **options)
    write_study(str(tmp_path / "metrics.csv"), str(tmp_path / "without"), **options)
    summary = (tmp_path / "with/summary.md").read_text()
    head, block = summary.split(f"\n{PROVENANCE_HEADING}\n\n")
    assert head == (tmp_path / "without/summary.md").read_text()
    assert block.startswith(f"- Commit: `{manifest['git']['commit']}`")
    assert f"- Config digest: `{manifest['config_digest']}`" in block
    for path in (tmp_path / "without").iterdir():
        if "summary.md" not in path.name:           # and its checksum side file
            assert (tmp_path / "with" / path.name).read_bytes() == path.read_bytes(), path.name


def test_the_manifest_says_where_each_reference_came_from(tmp_path, smoke_config):
    """From each reference's header: a copy of the store's (record, SHA-256, spp), one this run
    merged from its chunks, one imported from a folder; in manifest.json and manifest.md."""
    import numpy as np

    from mcbench.io.exr import write_layers

    layers = {"color": np.ones((4, 4, 3), np.float32)}
    write_layers(tmp_path / "a.exr", layers, metadata={"stored_reference": "a.json", "stored_sha256": "f" * 64,
                                                         "spp": "65536"})
    write_layers(tmp_path / "b.exr", layers, metadata={"spp": "1024", "chunks": "2"})
    write_layers(tmp_path / "c.exr", layers, metadata={"imported_from": "/data/kitchen"})
    manifest = write_manifest(str(tmp_path / "manifest.json"), str(tmp_path / "manifest.md"), repo_dir=REPO,
                              config=smoke_config, references=[tmp_path / n for n in ("c.exr", "a.exr", "b.exr")])
    assert manifest["references"] == {
        "a": {"source": "store", "record": "a.json", "sha256": "f" * 64, "spp": "65536"},
        "b": {"source": "render", "spp": "1024", "chunks": "2"},
        "c": {"source": "folder", "from": "/data/kitchen"}}
    assert read_json(tmp_path / "manifest.json") == manifest
    md = (tmp_path / "manifest.md").read_text()
    assert "- a: the store's `a.json`" in md and "- b: rendered by this run (1024 spp in 2 chunks)" in md
    assert "references" not in write_manifest(str(tmp_path / "m2.json"), str(tmp_path / "m2.md"), repo_dir=REPO,
                                              config=smoke_config)
