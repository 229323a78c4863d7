"""The work behind ``workflow/rules/provenance.smk``: the run's provenance manifest.

``results/manifest.json`` says what produced a run's tables: the checkout's git commit and
whether its tree was clean, the digest of the resolved config (the one the Snakefile logs,
:func:`mcbench.pipeline.config.config_digest`), the versions of the libraries the numbers
depend on, the CPU (model, vendor/family/model numbers, AVX2/AVX-512F) and its logical cores.
``results/manifest.md`` shows the same as a short Markdown list, and the study's ``summary.md``
repeats its key lines (:func:`mcbench.analysis.study.markdown.provenance_markdown`).

Every collector is a small function that never raises for a missing piece: a checkout without
git (or without a ``git`` program) gives ``"unknown"``, a package that is not installed gives
``"absent"``, a machine without ``/proc/cpuinfo`` gives ``"unknown"`` CPU fields. Versions are
read from the installed distributions' metadata (:mod:`importlib.metadata`), never by importing
the package: importing torch or Mitsuba would cost seconds and memory, and rule 5 of
docs/architecture.md keeps Mitsuba and Dr.Jit out of this layer. For the same reason Dr.Jit's
LLVM target (which needs drjit imported) is not recorded; the AVX flags say which vector width
its LLVM backend can use.

The rule is local (``localrule: True``): on a cluster the CPU and cores are those of the host
that ran the submitting Snakemake, not of the nodes that ran the methods (``timings.csv``'s
``machine`` column names each method run's host).

The keys are written in sorted order (:func:`mcbench.io.tables.write_json`), so two manifests of
the same run compare byte for byte.
"""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

from mcbench.io.tables import write_json, write_text
from mcbench.pipeline.config import config_digest

__all__ = ["UNKNOWN", "ABSENT", "DISTRIBUTIONS", "MANIFEST_VERSION", "git_state", "package_versions",
           "cpu_info", "mcbench_version", "collect_provenance", "manifest_markdown", "write_manifest"]

#: The value of a field that cannot be determined (no git, no /proc/cpuinfo).
UNKNOWN = "unknown"
#: The version of a package that is not installed.
ABSENT = "absent"
#: The record's layout; raised when a key changes meaning.
MANIFEST_VERSION = 1
#: The manifest's version keys -> the distribution names (``pip show`` names) they are read from;
#: ``oidn`` is ``pyoidn``, the binding methods/oidn.py calls.
DISTRIBUTIONS = {
    "mitsuba": "mitsuba",
    "drjit": "drjit",
    "oidn": "pyoidn",
    "torch": "torch",
    "numpy": "numpy",
    "scipy": "scipy",
    "flip_evaluator": "flip-evaluator",
    "snakemake": "snakemake",
}
_GIT_TIMEOUT_S = 30


def _git(repo_dir, *args: str) -> str | None:
    """stdout of ``git -C repo_dir args`` (stripped), or None when git is missing, fails
    (not a repository, a repository of another owner) or hangs. ``GIT_OPTIONAL_LOCKS=0``: a
    ``git status`` must not take the index lock while another git command runs in the checkout."""
    env = {**os.environ, "GIT_OPTIONAL_LOCKS": "0", "LC_ALL": "C"}
    try:
        done = subprocess.run(["git", "-C", str(repo_dir), *args], capture_output=True, text=True,
                              timeout=_GIT_TIMEOUT_S, env=env, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def git_state(repo_dir) -> dict:
    """``{"commit": <40 hex digits>, "clean": bool}`` of the checkout at ``repo_dir``: clean when
    ``git status --porcelain`` lists nothing (untracked files count as changes; ``results/`` and
    ``.snakemake/`` are ignored by the project's .gitignore). ``"unknown"`` for both when
    ``repo_dir`` is not in a git repository or git cannot run; for ``clean`` alone when the
    status cannot be read."""
    commit = _git(repo_dir, "rev-parse", "--verify", "HEAD")
    if not commit:
        return {"commit": UNKNOWN, "clean": UNKNOWN}
    status = _git(repo_dir, "status", "--porcelain")
    return {"commit": commit, "clean": UNKNOWN if status is None else status == ""}


def package_versions(distributions: dict[str, str] | None = None) -> dict[str, str]:
    """Installed version of each distribution of ``distributions`` (key -> distribution name;
    default :data:`DISTRIBUTIONS`) from its metadata, :data:`ABSENT` when it is not installed,
    plus ``python`` (``platform.python_version()``)."""
    versions = {}
    for key, name in (DISTRIBUTIONS if distributions is None else distributions).items():
        try:
            versions[key] = metadata.version(name)
        except (metadata.PackageNotFoundError, ValueError):
            versions[key] = ABSENT
    versions["python"] = platform.python_version()
    return dict(sorted(versions.items()))


def cpu_info(cpuinfo_text: str | None = None, *, cores: int | None = None) -> dict:
    """The CPU from the text of ``/proc/cpuinfo`` (read when None; :data:`UNKNOWN` fields where
    it is missing, e.g. off Linux, with ``platform.processor()`` as the model if it says
    anything): ``model`` ("model name"), ``vendor`` ("vendor_id"), ``family`` and
    ``model_number`` ("cpu family", "model"; decimal strings as the kernel prints them),
    ``avx2`` and ``avx512f`` (whether the first processor's "flags" hold them; :data:`UNKNOWN`
    without flags) and ``logical_cores`` (``cores``, default ``os.cpu_count()``)."""
    if cpuinfo_text is None:
        try:
            cpuinfo_text = Path("/proc/cpuinfo").read_text(errors="replace")
        except OSError:
            cpuinfo_text = ""
    first: dict[str, str] = {}
    for line in cpuinfo_text.splitlines():
        if not line.strip():
            if first:
                break           # the first processor's block only: the rest repeat it
            continue
        key, sep, value = line.partition(":")
        if sep:
            first.setdefault(key.strip(), value.strip())
    flags = set(first["flags"].split()) if "flags" in first else None
    model = first.get("model name") or platform.processor() or UNKNOWN
    count = os.cpu_count() if cores is None else cores
    return {
        "avx2": UNKNOWN if flags is None else "avx2" in flags,
        "avx512f": UNKNOWN if flags is None else "avx512f" in flags,
        "family": first.get("cpu family", UNKNOWN),
        "logical_cores": count if count else UNKNOWN,
        "model": model,
        "model_number": first.get("model", UNKNOWN),
        "vendor": first.get("vendor_id", UNKNOWN),
    }


def mcbench_version(repo_dir) -> str:
    """mcbench's version: ``project.version`` of ``repo_dir/pyproject.toml`` (the checkout that
    ran; the installed metadata may be another checkout's), else the installed distribution's,
    else :data:`ABSENT`."""
    import tomllib

    try:
        with open(Path(repo_dir) / "pyproject.toml", "rb") as handle:
            version = tomllib.load(handle).get("project", {}).get("version")
        if isinstance(version, str) and version:
            return version
    except (OSError, tomllib.TOMLDecodeError):
        pass
    try:
        return metadata.version("mcbench")
    except metadata.PackageNotFoundError:
        return ABSENT


def collect_provenance(*, repo_dir, config: dict) -> dict:
    """The provenance manifest of a run from the checkout ``repo_dir`` with the resolved config
    ``config`` (schema defaults applied, :func:`mcbench.pipeline.config.resolve_config`):

    * ``git``: :func:`git_state` (``commit``, ``clean``);
    * ``config_digest``: :func:`mcbench.pipeline.config.config_digest` -- the first 16 hex
      digits of the SHA-256 of the config as canonical JSON (sorted keys), the digest the
      Snakefile logs when it parses;
    * ``versions``: :func:`package_versions` with ``mcbench`` (:func:`mcbench_version`);
    * ``cpu``: :func:`cpu_info`; ``platform``: ``platform.platform()``;
    * ``manifest_version``: :data:`MANIFEST_VERSION`.

    Keys in sorted order at every level."""
    versions = package_versions()
    versions["mcbench"] = mcbench_version(repo_dir)
    record = {
        "config_digest": config_digest(config),
        "cpu": cpu_info(),
        "git": git_state(repo_dir),
        "manifest_version": MANIFEST_VERSION,
        "platform": platform.platform(),
        "versions": dict(sorted(versions.items())),
    }
    return dict(sorted(record.items()))


def reference_sources(reference_paths) -> dict:
    """Where each reference of a run came from, read from its header (``reference_paths``: the
    run's ``results/references/<scene>.exr``): ``{scene: {"source": "store", "record", "sha256",
    "spp"}}`` for a reference copied from the store (:func:`mcbench.pipeline.reference_sources.
    copy_stored_reference` writes those), ``{"source": "folder", "from"}`` for one imported from a
    folder of renders, else ``{"source": "render", "spp", "chunks"}`` (merged here from its chunks)."""
    from mcbench.io.exr import read_metadata

    sources = {}
    for path in sorted(Path(p) for p in reference_paths):
        header = read_metadata(str(path))
        if "stored_reference" in header:
            entry = {"source": "store", "record": header["stored_reference"], "sha256": header.get("stored_sha256", ""),
                     "spp": header.get("spp", "")}
        elif "imported_from" in header:
            entry = {"source": "folder", "from": header["imported_from"]}
        else:
            entry = {"source": "render", "spp": header.get("spp", ""), "chunks": header.get("chunks", "")}
        sources[path.stem] = entry
    return sources


def manifest_markdown(manifest: dict) -> str:
    """``manifest.md``: a heading and one line per field of ``manifest`` (:func:`collect_provenance`),
    the short block of the study's summary first."""
    from mcbench.analysis.study.markdown import provenance_markdown

    lines = ["# Provenance of this run", "", *provenance_markdown(manifest), "", "## Every library version", ""]
    lines += [f"- {name}: {version}" for name, version in sorted(manifest.get("versions", {}).items())]
    if manifest.get("references"):
        lines += ["", "## Where each reference came from", ""]
        for scene, entry in manifest["references"].items():
            detail = {"store": f"the store's `{entry.get('record')}` (SHA-256 `{str(entry.get('sha256'))[:16]}`…, "
                               f"{entry.get('spp')} spp), checked against this run's render",
                      "folder": f"the folder `{entry.get('from')}`",
                      "render": f"rendered by this run ({entry.get('spp')} spp in {entry.get('chunks')} chunks)"}
            lines.append(f"- {scene}: {detail.get(entry.get('source'), entry.get('source'))}")
    lines += ["", f"Platform: {manifest.get('platform', UNKNOWN)}."]
    return "\n".join(lines) + "\n"


def write_manifest(json_path: str, md_path: str, *, repo_dir, config: dict, references=()) -> dict:
    """Collect the manifest (:func:`collect_provenance`; with ``references``, the run's reference
    files, also ``references``: :func:`reference_sources`, so that a study and its bundle say which
    references came from the store) and write it atomically as JSON (sorted keys, with its
    checksum side file) to ``json_path`` and as Markdown to ``md_path``; returns it."""
    manifest = collect_provenance(repo_dir=repo_dir, config=config)
    if references:
        manifest = dict(sorted({**manifest, "references": reference_sources(references)}.items()))
    write_json(json_path, manifest)
    write_text(md_path, manifest_markdown(manifest))
    return manifest
