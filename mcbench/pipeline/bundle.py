"""A finished study as one checked archive: export it here, import it into a clone elsewhere.

A *study bundle* is one gzip-compressed tar archive (:data:`COMPRESS_LEVEL`; bundles of versions 1
and 2, uncompressed, are read too) holding every regular file a run made under
``results/`` (renders, references, every method's outputs, metrics, tables, figures, the viewer,
the manifest and the hidden ``.NAME.crc32`` checksum side files and ``.snakemake_timestamp``
files beside them), except ``results/logs/``, ``results/report.zip``, earlier bundles
(``results/bundle/``) and temporary files (:func:`is_temporary`). Its first member,
``bundle.json``, lists each file (path relative to the working folder, size, SHA-256, mtime in
ns) and holds :data:`BUNDLE_VERSION`, mcbench's version, the run's provenance
(``results/manifest.json``), the resolved config and its digest, and Snakemake's metadata
record of every bundled output (``snakemake_metadata``): with them, Snakemake's params, input
and code triggers keep working on the imported files (a changed method parameter reruns the
method; without the records it would silently not).

:func:`import_study` checks everything (archive, checksums, member names, version, the config's
case keys :data:`CASE_KEYS`) before it writes anything into ``results/``; it extracts into a
staging folder beside ``results/``, moves the files into place, writes the metadata records
and sets the files' mtimes (:func:`import_mtimes`), so that ``snakemake -n`` in the clone plans
nothing for what the bundle holds. Re-running an interrupted import completes it.

Commands (in the checkout's root; the config is resolved as the Snakefile does: the
``--configfile`` if given, else the checkout's ``config.yaml``, with the schema's defaults)::

    python -m mcbench.pipeline.bundle export results/bundle/study.tar.gz [--configfile CONFIG]
    python -m mcbench.pipeline.bundle import results/bundle/study.tar.gz [--configfile CONFIG]
    python -m mcbench.pipeline.bundle verify results/bundle/study.tar.gz
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import re
import shutil
import stat
import sys
import tarfile
import tempfile
import time
import zlib
from base64 import urlsafe_b64encode
from pathlib import Path, PurePosixPath

from mcbench import BenchError
from mcbench.io.tables import write_atomically
from mcbench.io.weights import file_sha256
from mcbench.pipeline.config import config_digest, key_path, read_config_file

__all__ = ["BUNDLE_VERSION", "MANIFEST_NAME", "CASE_KEYS", "MTIME_STEP_NS", "is_temporary", "study_files",
           "snakemake_record_path", "read_snakemake_records", "export_study", "verify_bundle",
           "check_case_keys", "relocate_records", "import_mtimes", "import_study", "main"]

#: The bundle format's version. Version 2 stores a file whose content (size and SHA-256) equals an
#: earlier member's as a tar hard link to it (the viewer's images are linked into three folders:
#: each stored once, with one header); version 1 stores every file whole. Version 3 is version 2's
#: members in a gzip-compressed stream: the tar's headers, padding and the manifest shrink tenfold
#: (on the default study 1.28 GB -> 1.05 GB, docs/measurements.md). All three are read; a bundle of
#: another version is refused.
BUNDLE_VERSION = 3
READ_VERSIONS = (1, 2, 3)
#: gzip level of the archive: 1, the fastest. The renders and kept outputs are already
#: Zstandard-compressed and the viewer's images JPEG/PNG; what gzip finds to shrink (headers,
#: padding, JSON, CSV) any level finds (level 6 would cost several times the CPU for a few MB).
COMPRESS_LEVEL = 1
#: The archive's first member: what the bundle holds.
MANIFEST_NAME = "bundle.json"
#: The config keys that define the study's cases (the renders and references every result was
#: computed from): ``resolution``, ``spp``, ``seed``, ``scenes``, ``reference`` (spp, chunks,
#: scene_spp) and ``variant`` (Mitsuba's variant: another one renders other noise). An import
#: whose config differs in one of them is refused: its run would rank methods on other cases
#: than the bundled ones. Every other key may differ, and Snakemake's params triggers (the
#: bundle's metadata records) rerun what it changes: methods (the point of a bundle is to add
#: one; a changed method's parameters rerun it), ``metrics`` (an added metric is computed for
#: every case; the renders do not depend on it), the study, oracle and progressive settings.
CASE_KEYS = ("resolution", "spp", "seed", "scenes", "reference", "variant")
#: Folders and files under ``results/`` that a bundle leaves out (relative to it).
EXCLUDED_DIRS = ("logs", "bundle")
EXCLUDED_FILES = ("report.zip",)
#: The step between imported files' mtimes of consecutive original mtimes (1 ms: above the
#: mtime resolution of common file systems, and 1000 files end one second after the import).
MTIME_STEP_NS = 1_000_000
#: The JSON of Snakemake's metadata records: ``.snakemake/metadata`` of the working folder.
METADATA_DIR = Path(".snakemake") / "metadata"

_CHUNK = 1 << 20
_TEMPORARY = re.compile(r"(\.tmp(\.[A-Za-z0-9]+)?|~|\.partial)$")


def is_temporary(name: str) -> bool:
    """Whether a file name is a temporary one (``X.tmp``, mcbench's ``.X.abc123.tmp.exr``,
    ``X~``, NFS's ``.nfsNNN``), never bundled. Other hidden files are bundled: mcbench's
    checksum side files ``.X.crc32`` and Snakemake's ``.snakemake_timestamp``."""
    return bool(_TEMPORARY.search(name)) or name.startswith(".nfs")


def study_files(results_dir, *, workdir=".", exclude=()) -> list[str]:
    """Every regular file under ``results_dir`` that a bundle holds, as POSIX paths relative to
    ``workdir`` (sorted): all but ``logs/``, ``bundle/``, ``report.zip``, temporary files
    (:func:`is_temporary`), hidden folders (mcbench's staging folders) and the paths ``exclude``.
    A symbolic link is refused (a bundle holds files, not links to outside files)."""
    results, work = Path(results_dir).resolve(), Path(workdir).resolve()
    if not results.is_dir():
        raise BenchError(f"{results_dir}: no results folder to bundle; run the study first (snakemake)")
    if results.parent != work or results.name != "results":
        raise BenchError(f"{results_dir}: a bundle holds the folder results/ of the working folder {workdir}; "
                         f"run the export in the folder that holds results/")
    skip = {Path(p).resolve() for p in exclude}
    files = []
    for folder, dirs, names in os.walk(results):
        here = Path(folder)
        dirs[:] = sorted(d for d in dirs if not d.startswith(".")
                         and not (here == results and d in EXCLUDED_DIRS))
        for name in names:
            path = here / name
            if (here == results and name in EXCLUDED_FILES) or is_temporary(name) or path in skip:
                continue
            mode = os.lstat(path).st_mode
            if stat.S_ISLNK(mode):
                raise BenchError(f"{path}: a symbolic link in the results; replace it with the file it "
                                 f"points to (or remove it) and export again")
            if stat.S_ISREG(mode):
                files.append(path.relative_to(work).as_posix())
    return sorted(files)


def file_entry(rel: str, *, workdir=".") -> dict:
    """``{path, size, sha256, mtime_ns}`` of file ``rel`` (relative to ``workdir``)."""
    path = Path(workdir) / rel
    info = path.stat()
    return {"path": rel, "size": info.st_size, "sha256": file_sha256(path), "mtime_ns": info.st_mtime_ns}


def snakemake_record_path(metadata_dir, key: str, *, max_len: int | None = None) -> Path:
    """Where Snakemake's file persistence keeps the metadata record of output ``key`` (the path
    as the rule names it, e.g. ``results/metrics.csv``): the URL-safe base64 of the key, cut into
    file names of at most ``max_len - 1`` characters, every part but the last prefixed ``@``
    (``snakemake.persistence.file.FilePersistence._record_path``, Snakemake 9; ``max_len``:
    the folder's file-name limit, ``PC_NAME_MAX``, 255 where unknown)."""
    if max_len is None:
        try:
            max_len = os.pathconf(metadata_dir, "PC_NAME_MAX") if os.name == "posix" else 255
        except OSError:
            max_len = 255
    if max_len == 0:
        max_len = 255
    b64 = urlsafe_b64encode(key.encode()).decode()
    parts = [b64[i:i + max_len - 1] for i in range(0, len(b64), max_len - 1)]
    parts = ["@" + p for p in parts[:-1]] + [parts[-1]]
    return Path(metadata_dir, *parts)


def _keys_with_folders(paths) -> list[str]:
    """The files ``paths`` and every folder above them (a ``directory()`` output's record is
    the folder's), in order, each once."""
    keys = {}
    for rel in paths:
        keys[rel] = None
        for parent in PurePosixPath(rel).parents:
            if str(parent) != ".":
                keys[str(parent)] = None
    return list(keys)


def read_snakemake_records(paths, *, workdir=".") -> dict:
    """``{key: record}``: Snakemake's metadata record (parsed JSON) of each file of ``paths`` and
    each folder above them that has one in ``workdir/.snakemake/metadata``."""
    metadata_dir = Path(workdir) / METADATA_DIR
    if not metadata_dir.is_dir():
        return {}
    records = {}
    for key in _keys_with_folders(paths):
        path = snakemake_record_path(metadata_dir, key)
        if path.is_file():
            try:
                records[key] = json.loads(path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError):
                continue          # Snakemake ignores a damaged record too
    return records


#: The checkout of this mcbench (the one whose Snakefile runs, in a checkout).
CHECKOUT = Path(__file__).resolve().parents[2]


def relocate_records(records: dict, roots: dict[str, str]) -> dict:
    """``records`` with every absolute path under an old root of ``roots`` (old -> new; e.g.
    the exporting checkout -> the importing one) moved under the new root. Snakemake records
    hold such paths (a checkout's files as a rule's input, the committed weights folder as a
    param); left as they are, the input and params triggers would rerun those jobs in a
    checkout at another path."""
    pairs = sorted(((old.rstrip("/"), new.rstrip("/")) for old, new in roots.items() if old and old != new),
                   key=lambda pair: -len(pair[0]))
    if not pairs:
        return records
    table = {json.dumps(old)[1:-1]: json.dumps(new)[1:-1] for old, new in pairs}
    pattern = re.compile("(?:" + "|".join(re.escape(old) for old in table) + r")(?=[/'\\\"]|$)")
    text = pattern.sub(lambda match: table[match.group(0)], json.dumps(records))
    return json.loads(text)


def _bundle_manifest(entries: list[dict], *, config: dict, records: dict, provenance: dict | None,
                     roots: dict) -> dict:
    from mcbench.pipeline.provenance import mcbench_version

    return {"bundle_version": BUNDLE_VERSION, "roots": roots,
            "mcbench": mcbench_version(Path(__file__).resolve().parents[2]),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "provenance": provenance, "config": config, "config_digest": config_digest(config),
            "files": entries, "snakemake_metadata": records}


def export_study(results_dir, bundle_path, *, config: dict, workdir=".", checkout_dir=None) -> dict:
    """Write the bundle of the study in ``results_dir`` (inside ``workdir``) to ``bundle_path``:
    one gzip-compressed tar (:data:`COMPRESS_LEVEL`), ``bundle.json`` first, then every file of :func:`study_files` under its
    path relative to ``workdir``; written to a temporary file beside it, then renamed. ``config``
    is the run's resolved config; ``checkout_dir`` the checkout whose Snakefile ran (default
    :data:`CHECKOUT`): ``bundle.json``'s ``roots`` (checkout and working folder, absolute) are
    what :func:`relocate_records` moves on import. Returns the manifest (``bundle.json``)."""
    bundle_path = Path(bundle_path)
    rels = study_files(results_dir, workdir=workdir, exclude=[bundle_path])
    if not rels:
        raise BenchError(f"{results_dir}: no files to bundle; run the study first (snakemake)")
    entries = [file_entry(rel, workdir=workdir) for rel in rels]
    provenance_path = Path(results_dir) / "manifest.json"
    provenance = json.loads(provenance_path.read_text()) if provenance_path.is_file() else None
    manifest = _bundle_manifest(entries, config=config, records=read_snakemake_records(rels, workdir=workdir),
                                provenance=provenance, roots=_roots(checkout_dir, workdir))
    data = json.dumps(manifest, indent=1, sort_keys=True).encode()

    def write_tar(tmp):
        first_with = {}                      # (size, sha256) -> the first member of that content
        with open(tmp, "wb") as raw:
            with tarfile.open(fileobj=raw, mode="w:gz", compresslevel=COMPRESS_LEVEL,
                              format=tarfile.PAX_FORMAT) as tar:
                tar.addfile(_tar_info(MANIFEST_NAME, len(data), time.time_ns()), io.BytesIO(data))
                for entry in entries:
                    content = (entry["size"], entry["sha256"])
                    if content in first_with:
                        tar.addfile(_link_info(entry["path"], first_with[content], entry["mtime_ns"]))
                        continue
                    first_with[content] = entry["path"]
                    with open(Path(workdir) / entry["path"], "rb") as handle:
                        reader = _HashingReader(handle)
                        tar.addfile(_tar_info(entry["path"], entry["size"], entry["mtime_ns"]), reader)
                        if reader.size != entry["size"] or reader.hexdigest() != entry["sha256"]:
                            raise BenchError(f"{entry['path']}: changed while the bundle was written; "
                                             f"export again when no run writes to results/")
            raw.flush()                      # after the tar's end blocks and gzip's trailer
            os.fsync(raw.fileno())

    write_atomically(bundle_path, write_tar)
    return manifest


def _roots(checkout_dir, workdir) -> dict:
    return {"checkout": str(Path(checkout_dir or CHECKOUT).resolve()), "workdir": str(Path(workdir).resolve())}


def _tar_info(name: str, size: int, mtime_ns: int) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.size, info.mode, info.mtime, info.type = size, 0o644, mtime_ns // 1_000_000_000, tarfile.REGTYPE
    return info


def _link_info(name: str, target: str, mtime_ns: int) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.mode, info.mtime, info.type, info.linkname = 0o644, mtime_ns // 1_000_000_000, tarfile.LNKTYPE, target
    return info


class _HashingReader:
    """A file object that hashes and counts what is read through it."""

    def __init__(self, handle):
        self._handle, self._digest, self.size = handle, hashlib.sha256(), 0

    def read(self, n=-1):
        data = self._handle.read(n)
        self._digest.update(data)
        self.size += len(data)
        return data

    def hexdigest(self) -> str:
        return self._digest.hexdigest()


# --- reading and checking ------------------------------------------------------------------------


def _safe_relpath(name: str, *, bundle) -> str:
    """``name`` if it is a relative path inside the working folder (no absolute path, no ``..``,
    no empty part), else a BenchError naming it."""
    path = PurePosixPath(name)
    if (not name or path.is_absolute() or name.startswith("/") or "\\" in name
            or any(part in ("..", "", ".") for part in name.split("/"))):
        raise BenchError(f"{bundle}: member {name!r} is not a plain relative path (absolute or with '..'): "
                         f"the archive is damaged or not a study bundle; export it again")
    if path.parts[0] != "results":
        raise BenchError(f"{bundle}: member {name!r} lies outside results/: not a study bundle; export it again")
    return name


def _read_manifest(tar: tarfile.TarFile, *, bundle) -> dict:
    """The first member's parsed ``bundle.json``, checked: the format's version and the file list."""
    first = tar.next()
    if first is None or first.name != MANIFEST_NAME or not first.isfile():
        raise BenchError(f"{bundle}: the first member is not {MANIFEST_NAME}: not a study bundle "
                         f"(make one with `python -m mcbench.pipeline.bundle export`)")
    try:
        manifest = json.loads(tar.extractfile(first).read())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise BenchError(f"{bundle}: {MANIFEST_NAME} is not valid JSON ({exc}); export the study again") from exc
    version = manifest.get("bundle_version") if isinstance(manifest, dict) else None
    if version not in READ_VERSIONS:
        raise BenchError(f"{bundle}: {MANIFEST_NAME}: bundle_version {version!r}: made by an incompatible version "
                         f"of mcbench ({manifest.get('mcbench') if isinstance(manifest, dict) else '?'}; this one "
                         f"reads versions {', '.join(map(str, READ_VERSIONS))}); export it with this version or import "
                         "it with that one")
    files = manifest.get("files")
    if not isinstance(files, list) or not all(isinstance(e, dict) and {"path", "size", "sha256", "mtime_ns"} <= set(e)
                                              for e in files):
        raise BenchError(f"{bundle}: {MANIFEST_NAME}: 'files' is not a list of path, size, sha256, mtime_ns; "
                         f"export the study again")
    seen = set()
    for entry in files:
        _safe_relpath(entry["path"], bundle=bundle)
        if entry["path"] in seen:
            raise BenchError(f"{bundle}: {MANIFEST_NAME} lists {entry['path']} twice; export the study again")
        seen.add(entry["path"])
    records = manifest.get("snakemake_metadata", {})
    if not isinstance(records, dict) or not all(isinstance(r, dict) for r in records.values()):
        raise BenchError(f"{bundle}: {MANIFEST_NAME}: 'snakemake_metadata' is not a mapping of path to record; "
                         f"export the study again")
    for key in records:
        _safe_relpath(key, bundle=bundle)
    return manifest


def _scan(bundle_path, *, prepare=None) -> dict:
    """Read the whole archive ``bundle_path`` and check it against its ``bundle.json``: every
    member listed once, a regular file, of the listed size and SHA-256, every listed file
    present. ``prepare(manifest)``, called once ``bundle.json`` is read (before any member),
    may refuse it or return a folder into which each member is written under its path as it is
    read. Returns the manifest; BenchError naming the archive and the member otherwise."""
    bundle = Path(bundle_path)
    try:
        tar = tarfile.open(bundle, mode="r:*")      # gzip (version 3) or uncompressed (1, 2)
    except FileNotFoundError as exc:
        raise BenchError(f"{bundle}: no such bundle; give the path of a study.tar.gz") from exc
    except (tarfile.TarError, OSError) as exc:
        raise BenchError(f"{bundle}: unreadable archive ({exc}); copy it again or export it again") from exc
    with tar:
        try:
            manifest = _read_manifest(tar, bundle=bundle)
            write_to = prepare(manifest) if prepare is not None else None
            listed = {entry["path"]: entry for entry in manifest["files"]}
            found = set()
            for index, member in enumerate(tar):
                if index == 0:
                    continue                  # bundle.json, read above
                name = _safe_relpath(member.name, bundle=bundle)
                if name not in listed:
                    raise BenchError(f"{bundle}: member {name} is not listed in {MANIFEST_NAME}: the archive was "
                                     f"altered; export the study again")
                if name in found:
                    raise BenchError(f"{bundle}: member {name} appears twice; export the study again")
                if member.islnk():
                    _check_link(member, listed, found, bundle=bundle, write_to=write_to)
                elif not member.isfile():
                    raise BenchError(f"{bundle}: member {name} is not a regular file; export the study again")
                else:
                    _check_member(tar, member, listed[name], bundle=bundle, write_to=write_to)
                found.add(name)
            while tar.fileobj.read(_CHUNK):  # to the stream's end: gzip checks its CRC and length there,
                pass                         # which covers the tar's padding and end blocks too
        except (tarfile.TarError, EOFError, OSError, zlib.error) as exc:
            raise BenchError(f"{bundle}: truncated or unreadable archive ({exc}); copy it again "
                             f"(compare its size with the original) or export it again") from exc
    missing = [path for path in listed if path not in found]
    if missing:
        raise BenchError(f"{bundle}: {len(missing)} listed file(s) missing from the archive, first {missing[0]}: "
                         f"truncated or altered; copy it again or export it again")
    return manifest


def _check_link(member, listed: dict, found: set, *, bundle, write_to: Path | None) -> None:
    """A hard-link member (bundle version 2): it must name an earlier member whose listed size and
    SHA-256 are its own; with ``write_to`` its file is made as a hard link to that member's
    (a copy where the file system has none)."""
    target = member.linkname
    if target not in found or (listed[target]["size"], listed[target]["sha256"]) != \
            (listed[member.name]["size"], listed[member.name]["sha256"]):
        raise BenchError(f"{bundle}: member {member.name} links to {target!r}, which is not an earlier member of "
                         f"the same content: the archive was altered; export the study again")
    if write_to is not None:
        source, copy = write_to / target, write_to / member.name
        copy.parent.mkdir(parents=True, exist_ok=True)
        copy.unlink(missing_ok=True)
        try:
            os.link(source, copy)
        except OSError:
            shutil.copyfile(source, copy)


def _check_member(tar, member, entry: dict, *, bundle, write_to: Path | None) -> None:
    source = tar.extractfile(member)
    digest, size = hashlib.sha256(), 0
    out = None
    if write_to is not None:
        target = write_to / member.name
        target.parent.mkdir(parents=True, exist_ok=True)
        out = open(target, "wb")
    try:
        while chunk := source.read(_CHUNK):
            digest.update(chunk)
            size += len(chunk)
            if out is not None:
                out.write(chunk)
    finally:
        if out is not None:
            out.close()
    if size != entry["size"] or digest.hexdigest() != entry["sha256"]:
        raise BenchError(f"{bundle}: member {member.name}: checksum mismatch (size {size}, listed {entry['size']}; "
                         f"SHA-256 differs from {MANIFEST_NAME}): the archive is damaged; copy it again or export "
                         f"it again")


def verify_bundle(bundle_path) -> dict:
    """The parsed ``bundle.json`` of ``bundle_path`` after checking every member's size and
    SHA-256 and the member list (nothing is written); BenchError naming the member otherwise."""
    return _scan(bundle_path)


def _first_difference(a, b, path: list):
    """The key path (list) of the first place where ``a`` and ``b`` differ, or None."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                return path + [key]
            found = _first_difference(a[key], b[key], path + [key])
            if found is not None:
                return found
        return None
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for index, (x, y) in enumerate(zip(a, b)):
            found = _first_difference(x, y, path + [index])
            if found is not None:
                return found
        return None
    return None if a == b else path


def _at(config, path):
    for part in path:
        try:
            config = config[part]
        except (KeyError, IndexError, TypeError):
            return "<absent>"
    return config


def check_case_keys(bundle_config: dict, config: dict, *, bundle="bundle") -> None:
    """BenchError naming the first key of :data:`CASE_KEYS` (as a path, e.g. ``reference.spp``)
    where the bundle's resolved config and this run's differ."""
    if not isinstance(bundle_config, dict):
        raise BenchError(f"{bundle}: {MANIFEST_NAME} holds no config; export the study again")
    for key in CASE_KEYS:
        path = _first_difference(bundle_config.get(key), config.get(key), [key])
        if path is not None:
            raise BenchError(
                f"{bundle}: config key {key_path(path)}: the bundle's study has {_at(bundle_config, path)!r}, this "
                f"run's config {_at(config, path)!r}; the keys {', '.join(CASE_KEYS)} define the study's cases and "
                f"must match: import with the study's config (bundle.json's 'config') or change the key")


# --- importing ---------------------------------------------------------------------------------


def import_mtimes(entries: list[dict], *, now_ns: int, step_ns: int = MTIME_STEP_NS) -> dict[str, int]:
    """New mtimes (ns) of the imported files: ``now_ns + rank * step_ns``, ``rank`` the rank of the
    file's original mtime among the distinct original mtimes. Every file is newer than the
    checkout (made before ``now_ns``), and the order is kept exactly (equal stays equal, an
    output stays newer than its inputs). Unlike ``now + (orig - first)``, which would put the
    last files of a study that ran for hours hours into the future, the files end
    ``step_ns`` per distinct mtime after ``now_ns`` (a second per thousand), so that what the
    clone's next run writes is newer than the imported files it reads."""
    ranks = {mtime: rank for rank, mtime in enumerate(sorted({int(e["mtime_ns"]) for e in entries}))}
    return {e["path"]: now_ns + ranks[int(e["mtime_ns"])] * step_ns for e in entries}


def _write_json_atomically(path: Path, value) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:40]}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as handle:
            json.dump(value, handle)
        os.chmod(tmp, 0o664)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def staging_dir(manifest: dict, *, workdir=".") -> Path:
    """The import's staging folder: ``workdir/.mcbench-import-<digest>`` (same file system as
    ``results/``; the digest is of the bundle's file list)."""
    text = json.dumps(manifest["files"], sort_keys=True).encode()
    return Path(workdir) / f".mcbench-import-{hashlib.sha256(text).hexdigest()[:16]}"


def import_study(bundle_path, *, config: dict, workdir=".", checkout_dir=None) -> dict:
    """Import the bundle ``bundle_path`` into ``workdir`` (its ``results/`` and
    ``.snakemake/metadata``), for a run of the resolved ``config``; returns the manifest.

    Refused (BenchError naming the member or config key) before anything is written into
    ``results/``: an unreadable or truncated archive, a member whose size or SHA-256 differs
    from ``bundle.json``, a member it does not list or a listed file the archive lacks, an
    absolute path or ``..``, another ``bundle_version``, a config that differs in a key of
    :data:`CASE_KEYS`, a file of ``results/`` that exists with other content.

    ``checkout_dir``: the checkout whose Snakefile will run (default :data:`CHECKOUT`); the
    records' paths under the exporting checkout and working folder are moved to it and to
    ``workdir`` (:func:`relocate_records`).

    Steps: the archive is extracted into :func:`staging_dir` and checked there; then each
    file is moved into place (``os.replace``; a file already there with the same content is
    kept); then Snakemake's metadata records are written (each atomically) and the files' mtimes
    set (:func:`import_mtimes`); the staging folder is removed. Interrupted before the moves,
    ``results/`` is untouched; after, running the import again completes it (identical files
    are skipped), and a finished import run again changes nothing but the mtimes (which makes
    what a run wrote since the first import older than the imported files: it reruns)."""
    work, bundle = Path(workdir), Path(bundle_path)
    staging = None

    def prepare(manifest):
        nonlocal staging
        check_case_keys(manifest.get("config"), config, bundle=bundle)
        staging = staging_dir(manifest, workdir=work)
        if staging.exists():
            shutil.rmtree(staging)            # an earlier, interrupted import's
        staging.mkdir(parents=True)
        return staging

    try:
        manifest = _scan(bundle, prepare=prepare)
        entries = manifest["files"]
        _check_destinations(entries, work, bundle=bundle)
    except BaseException:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
        raise
    for entry in entries:                     # the move phase
        target = work / entry["path"]
        if target.exists():
            continue                          # identical content (checked above)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / entry["path"], target)
    old, new = manifest.get("roots") or {}, _roots(checkout_dir, workdir)
    roots = {old[k]: new[k] for k in ("checkout", "workdir") if isinstance(old.get(k), str)}
    _write_records(relocate_records(manifest.get("snakemake_metadata") or {}, roots), work)
    _set_mtimes(entries, work, now_ns=time.time_ns())
    shutil.rmtree(staging)
    return manifest


def _check_destinations(entries: list[dict], work: Path, *, bundle) -> None:
    """BenchError naming the first file of ``results/`` that exists with other content than the
    bundle's (or is a folder there)."""
    for entry in entries:
        target = work / entry["path"]
        if target.is_dir() or (target.exists() and (target.stat().st_size != entry["size"]
                                                      or file_sha256(target) != entry["sha256"])):
            raise BenchError(f"{bundle}: {target} exists with other content than the bundle's; the import "
                             f"would replace a result: move it away (or import into a fresh clone) and import again")


def _write_records(records: dict, work: Path) -> None:
    metadata_dir = work / METADATA_DIR
    metadata_dir.mkdir(parents=True, exist_ok=True)
    # Snakemake's file persistence migrates a metadata folder that has no incomplete/ beside it
    (metadata_dir.parent / "incomplete").mkdir(exist_ok=True)
    for key, record in records.items():
        _write_json_atomically(snakemake_record_path(metadata_dir, key), record)


def _set_mtimes(entries: list[dict], work: Path, *, now_ns: int) -> None:
    """Files get :func:`import_mtimes`; each folder above them (under ``results/``) the newest
    mtime of the files below it, so that a ``directory()`` output without a
    ``.snakemake_timestamp`` is as new as its contents."""
    new = import_mtimes(entries, now_ns=now_ns)
    folders: dict[str, int] = {}
    for rel, mtime in new.items():
        os.utime(work / rel, ns=(mtime, mtime))
        for parent in PurePosixPath(rel).parents:
            if str(parent) != ".":
                folders[str(parent)] = max(folders.get(str(parent), 0), mtime)
    for rel in sorted(folders, key=lambda p: -p.count("/")):
        os.utime(work / rel, ns=(folders[rel], folders[rel]))


# --- the command ---------------------------------------------------------------------------------


def _resolved_config(configfile) -> dict:
    """The config as the Snakefile resolves it: ``configfile`` if given, else the checkout's
    ``config.yaml``, with the schema's defaults."""
    path = Path(configfile) if configfile else Path(__file__).resolve().parents[2] / "config.yaml"
    return read_config_file(path)


def main(argv=None) -> int:
    """``python -m mcbench.pipeline.bundle export|import|verify``; 0 on success, 1 with the
    error's one line on stderr."""
    parser = argparse.ArgumentParser(prog="python -m mcbench.pipeline.bundle",
                                     description="Export, import or verify a study bundle (docs/bundle.md).")
    sub = parser.add_subparsers(dest="command", required=True)
    export = sub.add_parser("export", help="bundle results/ of the working folder into one archive")
    export.add_argument("bundle", help="the archive to write, e.g. results/bundle/study.tar.gz")
    export.add_argument("--results", default="results", help="the results folder (default results)")
    imp = sub.add_parser("import", help="import a bundle into the working folder's results/")
    imp.add_argument("bundle")
    for command in (export, imp):
        command.add_argument("--configfile", help="the run's config (default: the checkout's config.yaml)")
        command.add_argument("--workdir", default=".", help="the working folder (default .)")
    verify = sub.add_parser("verify", help="check every member's checksum; writes nothing")
    verify.add_argument("bundle")
    args = parser.parse_args(argv)
    try:
        if args.command == "verify":
            manifest = verify_bundle(args.bundle)
            print(f"{args.bundle}: {len(manifest['files'])} files verified (config digest {manifest['config_digest']})")
        elif args.command == "export":
            start = time.monotonic()
            manifest = export_study(Path(args.workdir) / args.results, args.bundle,
                                    config=_resolved_config(args.configfile), workdir=args.workdir)
            print(f"{args.bundle}: {len(manifest['files'])} files, {Path(args.bundle).stat().st_size} bytes "
                  f"in {time.monotonic() - start:.1f} s")
        else:
            start = time.monotonic()
            manifest = import_study(args.bundle, config=_resolved_config(args.configfile), workdir=args.workdir)
            print(f"{args.bundle}: {len(manifest['files'])} files imported in {time.monotonic() - start:.1f} s")
    except BenchError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
