"""The study bundle (mcbench.pipeline.bundle) on synthetic results trees with a fake
``.snakemake/metadata``: a round trip is byte-identical with the records and the mtime order;
every refusal leaves the importing tree byte-identical; an import interrupted while moving
files completes when run again."""

from __future__ import annotations

import hashlib
import io
import json
import os
import gzip
import re
import tarfile
from base64 import urlsafe_b64decode
from pathlib import Path

import pytest

from mcbench import BenchError
from mcbench.pipeline import bundle as B

CONFIG = {"resolution": [32, 32], "spp": [4, 64], "seed": 0, "scenes": ["cornell_box", "glass_caustics"],
          "reference": {"spp": 1024, "chunks": 2, "scene_spp": {}}, "variant": "auto",
          "metrics": ["relmse"], "denoisers": ["oidn"], "combiners": []}
EXPORT_CHECKOUT = "/checkouts/exporting"

# a results tree as a run leaves it: path -> (content, mtime in s); inputs older than outputs
TREE = {
    "results/renders/cornell_box/spp4.exr": (b"render", 100),
    "results/references/cornell_box.exr": (b"reference", 100),
    "results/outputs/cornell_box/spp4/oidn.exr": (b"oidn output", 200),
    "results/outputs/cornell_box/spp4/oidn.json": (b'{"seconds": 1}', 200),
    "results/metrics.csv": (b"scene,spp,candidate,metric,value\n", 300),
    "results/tables/.ranking_relmse.csv.crc32": (b"abcd1234", 400),
    "results/tables/ranking_relmse.csv": (b"candidate,4\n", 400),
    "results/viewer/index.html": (b"<html></html>", 500),
    "results/viewer/.snakemake_timestamp": (b"", 501),
    "results/manifest.json": (b'{"git": {"commit": "abc", "clean": true}}', 600),
}
# what a bundle leaves out
LEFT_OUT = {
    "results/logs/run.log": b"log",
    "results/report.zip": b"zip",
    "results/bundle/old.tar": b"old bundle",
    "results/tables/.ranking_relmse.csv.x1y2.tmp": b"temp",
    "results/outputs/.oidn.exr.abc.tmp.exr": b"temp exr",
    "results/.staging.abc/x.exr": b"staging folder",
}
RECORDS = {
    "results/outputs/cornell_box/spp4/oidn.exr": {"rule": "run_method", "params": ["{'radius': 7}",
                                                  f"'{EXPORT_CHECKOUT}/methods/weights'"],
                                                  "input": ["results/renders/cornell_box/spp4.exr"],
                                                  "record_format_version": 6},
    "results/metrics.csv": {"rule": "gather_metrics", "params": [], "input": [], "record_format_version": 6},
    "results/viewer": {"rule": "viewer", "input": [f"{EXPORT_CHECKOUT}/workflow/report/viewer/index.html"],
                       "params": [], "record_format_version": 6},
}


def write_tree(root: Path, files: dict) -> None:
    for rel, (data, mtime) in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        os.utime(path, (mtime, mtime))


def record_file(workdir: Path, key: str) -> Path:
    """Snakemake's own record path of ``key`` (its file persistence, not the module's copy)."""
    from snakemake.persistence.file import FilePersistence

    persistence = FilePersistence.__new__(FilePersistence)
    persistence._max_len = None
    return Path(persistence._record_path(str(workdir / ".snakemake" / "metadata"), key))


@pytest.fixture
def study(tmp_path) -> Path:
    """A working folder with a finished synthetic study, its records and left-out files."""
    work = tmp_path / "study"
    write_tree(work, TREE)
    write_tree(work, {rel: (data, 50) for rel, data in LEFT_OUT.items()})
    (work / ".snakemake" / "metadata").mkdir(parents=True)
    for key, record in RECORDS.items():
        path = record_file(work, key)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record))
    return work


@pytest.fixture
def bundle(study, tmp_path) -> Path:
    path = tmp_path / "study.tar"
    B.export_study(study / "results", path, config=CONFIG, workdir=study, checkout_dir=EXPORT_CHECKOUT)
    return path


def listing(root: Path) -> dict:
    """Every file and folder under ``root``: path -> SHA-256 of the content (folders: 'dir')."""
    out = {}
    for folder, dirs, names in os.walk(root):
        for name in dirs:
            out[os.path.relpath(os.path.join(folder, name), root)] = "dir"
        for name in names:
            path = os.path.join(folder, name)
            out[os.path.relpath(path, root)] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return out


@pytest.fixture
def clone(tmp_path) -> Path:
    """An importing checkout: a few tracked files, no results."""
    work = tmp_path / "clone"
    write_tree(work, {"Snakefile": (b"rule all:", 10), "workflow/scripts/x.py": (b"pass", 10)})
    return work


def import_into(bundle: Path, clone: Path, config=CONFIG):
    return B.import_study(bundle, config=config, workdir=clone, checkout_dir=clone / "checkout")


# --- the record path is Snakemake's --------------------------------------------------------------


@pytest.mark.parametrize("key", ["results/metrics.csv", "results/" + "x" * 400 + "/y.exr", "results/é ü.csv"])
def test_record_path_is_snakemakes_own(tmp_path, key):
    (tmp_path / ".snakemake" / "metadata").mkdir(parents=True)
    ours = B.snakemake_record_path(tmp_path / ".snakemake" / "metadata", key)
    assert ours == record_file(tmp_path, key)
    parts = ours.relative_to(tmp_path / ".snakemake" / "metadata").parts
    assert urlsafe_b64decode("".join(p.lstrip("@") for p in parts)).decode() == key


# --- export --------------------------------------------------------------------------------------


def test_export_holds_every_study_file_with_checksums_and_bundle_json_first(study, bundle):
    with tarfile.open(bundle, "r:*") as tar:
        members = tar.getmembers()
        assert members[0].name == "bundle.json"
        manifest = json.load(tar.extractfile(members[0]))
        contents = {m.name: tar.extractfile(m).read() for m in members[1:]}
    assert set(contents) == set(TREE)                     # the left-out files are not there
    assert {rel: data for rel, data in contents.items()} == {rel: data for rel, (data, _) in TREE.items()}
    for entry in manifest["files"]:
        data = TREE[entry["path"]][0]
        assert entry["size"] == len(data)
        assert entry["sha256"] == hashlib.sha256(data).hexdigest()
        assert entry["mtime_ns"] == TREE[entry["path"]][1] * 10**9
    assert manifest["bundle_version"] == B.BUNDLE_VERSION == 3
    assert manifest["config"] == CONFIG
    from mcbench.pipeline.config import config_digest
    assert manifest["config_digest"] == config_digest(CONFIG)
    assert manifest["provenance"] == json.loads(TREE["results/manifest.json"][0])
    assert manifest["snakemake_metadata"] == RECORDS      # files' and the directory output's
    assert manifest["roots"]["checkout"] == EXPORT_CHECKOUT
    assert not [p for p in bundle.parent.iterdir() if p.name.startswith(".")]   # no temp file left


def test_verify_returns_the_manifest_and_writes_nothing(bundle, tmp_path):
    before = listing(tmp_path)
    assert len(B.verify_bundle(bundle)["files"]) == len(TREE)
    assert listing(tmp_path) == before


# --- round trip --------------------------------------------------------------------------------


def test_round_trip_is_byte_identical_with_records_and_mtime_order(bundle, clone):
    import_into(bundle, clone)
    for rel, (data, _) in TREE.items():
        assert (clone / rel).read_bytes() == data, rel
    assert not (clone / "results" / "logs").exists() and not (clone / "results" / "report.zip").exists()
    # the records, where Snakemake reads them, with the exporting checkout moved to the importing one
    for key, record in RECORDS.items():
        written = json.loads(record_file(clone, key).read_text())
        expected = json.loads(json.dumps(record).replace(EXPORT_CHECKOUT, str(clone / "checkout")))
        assert written == expected
    assert "checkout/methods/weights" in json.loads(record_file(clone, next(iter(RECORDS))).read_text())["params"][1]
    # mtimes: every file newer than the checkout's, the original order kept (ties tied)
    mtimes = {rel: (clone / rel).stat().st_mtime_ns for rel in TREE}
    checkout_newest = max((clone / p).stat().st_mtime_ns for p in ("Snakefile", "workflow/scripts/x.py"))
    assert min(mtimes.values()) > checkout_newest
    for a in TREE:
        for b in TREE:
            assert (TREE[a][1] < TREE[b][1]) == (mtimes[a] < mtimes[b]), (a, b)
            assert (TREE[a][1] == TREE[b][1]) == (mtimes[a] == mtimes[b]), (a, b)
    assert (clone / "results" / "viewer").stat().st_mtime_ns == mtimes["results/viewer/.snakemake_timestamp"]
    assert not [p for p in clone.iterdir() if p.name.startswith(".mcbench-import")]


def test_import_mtimes_keep_order_and_stay_close_to_now():
    entries = [{"path": "a", "mtime_ns": 5}, {"path": "b", "mtime_ns": 10**13}, {"path": "c", "mtime_ns": 5},
               {"path": "d", "mtime_ns": 7}]
    new = B.import_mtimes(entries, now_ns=1000)
    assert new == {"a": 1000, "c": 1000, "d": 1000 + B.MTIME_STEP_NS, "b": 1000 + 2 * B.MTIME_STEP_NS}


def test_second_import_changes_no_content(bundle, clone):
    import_into(bundle, clone)
    first = listing(clone)
    import_into(bundle, clone)
    assert listing(clone) == first


# --- refusals leave the tree as it was -----------------------------------------------------------


def rewrite_bundle(source: Path, target: Path, *, manifest=None, members=None) -> Path:
    """A copy of bundle ``source`` with ``manifest(dict) -> dict`` applied to bundle.json and
    ``members(list of (name, bytes)) -> list`` to the other members."""
    with tarfile.open(source, "r:*") as tar:
        items = [(m.name, tar.extractfile(m).read()) for m in tar.getmembers()]
    data = json.loads(items[0][1])
    if manifest:
        data = manifest(data)
    rest = members(items[1:]) if members else items[1:]
    with tarfile.open(target, "w", format=tarfile.PAX_FORMAT) as tar:
        for name, content in [("bundle.json", json.dumps(data).encode()), *rest]:
            info = tarfile.TarInfo(name)
            info.size = len(content)
            tar.addfile(info, io.BytesIO(content))
    return target


def refused(bundle: Path, clone: Path, *, match: str, config=CONFIG):
    """The import is refused with a message matching ``match``; the tree is byte-identical."""
    before = listing(clone)
    with pytest.raises(BenchError, match=match):
        import_into(bundle, clone, config)
    assert listing(clone) == before


def test_the_archive_is_gzip_compressed(bundle):
    assert bundle.read_bytes()[:2] == b"\x1f\x8b"
    with tarfile.open(bundle, "r:gz") as tar:
        assert tar.getmembers()[0].name == "bundle.json"


@pytest.mark.parametrize("compressed", [True, False])
def test_a_flipped_byte_is_refused_naming_the_member(bundle, clone, tmp_path, compressed):
    """A byte of a member's content flipped inside the archive (the tar stream, then
    gzip-compressed again as an export writes it; or left uncompressed, as versions 1 and 2 were)."""
    data = bytearray(gzip.decompress(bundle.read_bytes()))
    offset = data.find(b"oidn output")
    data[offset] ^= 0x01
    bundle.write_bytes(gzip.compress(bytes(data), compresslevel=1) if compressed else bytes(data))
    refused(bundle, clone, match=r"member results/outputs/cornell_box/spp4/oidn.exr: checksum mismatch")
    with pytest.raises(BenchError, match="oidn.exr: checksum mismatch"):
        B.verify_bundle(bundle)


@pytest.mark.parametrize("where", [0.1, 0.3, 0.5, 0.7, 0.9, 0.98])
def test_a_flipped_byte_of_the_compressed_stream_is_refused_or_changes_nothing(bundle, clone, where):
    """Anywhere, the tar's padding and end blocks included (gzip's CRC covers them): the import is
    refused and writes nothing, or, where the flip falls in bits that deflate does not read (a
    block's unused bits, gzip's header time), the stream decodes to the same bytes and imports."""
    original = bundle.read_bytes()
    data = bytearray(original)
    data[int(len(data) * where)] ^= 0x10
    bundle.write_bytes(bytes(data))
    before = listing(clone)
    try:
        import_into(bundle, clone)
    except BenchError as exc:
        # gzip's CRC is checked at the stream's end: the garbage before it is refused by whatever
        # check it reaches first (bundle.json's parse, a member's header or checksum)
        assert re.search(r"checksum mismatch|unreadable|truncated|damaged|not valid JSON|export the study again",
                         str(exc))
        assert listing(clone) == before
    else:
        assert gzip.decompress(bytes(data)) == gzip.decompress(original)


@pytest.mark.parametrize("where", ["inside bundle.json", "after bundle.json", "inside the last member",
                                   "before the last member's data"])
def test_a_truncated_archive_is_refused(bundle, clone, where):
    with tarfile.open(bundle, "r:*") as tar:
        members = tar.getmembers()
    first, last = members[0], members[-1]
    cut = {"inside bundle.json": first.offset_data + first.size // 2,
           "after bundle.json": first.offset_data + first.size + (-first.size % 512),
           "inside the last member": last.offset_data + last.size // 2,
           "before the last member's data": last.offset_data - 100}[where]
    bundle.write_bytes(gzip.compress(gzip.decompress(bundle.read_bytes())[:cut], compresslevel=1))
    refused(bundle, clone, match=r"truncated|missing from the archive|unreadable")


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.995])
def test_a_truncated_compressed_archive_is_refused(bundle, clone, fraction):
    """Cut anywhere, the tar's end blocks and gzip's trailer included (gzip's length and CRC)."""
    data = bundle.read_bytes()
    bundle.write_bytes(data[:int(len(data) * fraction)])
    refused(bundle, clone, match=r"truncated|missing from the archive|unreadable")


def test_an_unlisted_member_is_refused(bundle, clone, tmp_path):
    bad = rewrite_bundle(bundle, tmp_path / "bad.tar", members=lambda items: items + [("results/extra.csv", b"x")])
    refused(bad, clone, match=r"member results/extra.csv is not listed")


def test_a_listed_file_missing_from_the_archive_is_refused(bundle, clone, tmp_path):
    bad = rewrite_bundle(bundle, tmp_path / "bad.tar",
                         members=lambda items: [i for i in items if i[0] != "results/metrics.csv"])
    refused(bad, clone, match=r"missing from the archive, first results/metrics.csv")


@pytest.mark.parametrize("name", ["results/../../evil.txt", "/tmp/evil.txt", "results/a/../../x"])
def test_a_traversal_path_is_refused(bundle, clone, tmp_path, name):
    def add(manifest):
        manifest["files"].append({"path": name, "size": 1, "sha256": hashlib.sha256(b"x").hexdigest(),
                                  "mtime_ns": 0})
        return manifest

    bad = rewrite_bundle(bundle, tmp_path / "bad.tar", manifest=add, members=lambda items: items + [(name, b"x")])
    refused(bad, clone, match=r"not a plain relative path")
    assert not (tmp_path / "evil.txt").exists()


def test_a_traversal_member_alone_is_refused(bundle, clone, tmp_path):
    bad = rewrite_bundle(bundle, tmp_path / "bad.tar", members=lambda items: items + [("../evil.txt", b"x")])
    refused(bad, clone, match=r"'../evil.txt' is not a plain relative path")


def test_another_bundle_version_is_refused(bundle, clone, tmp_path):
    bad = rewrite_bundle(bundle, tmp_path / "bad.tar", manifest=lambda m: {**m, "bundle_version": 4})
    refused(bad, clone, match=r"bundle_version 4: made by an incompatible version")


@pytest.mark.parametrize("key, change, named", [
    ("resolution", [64, 64], "resolution[0]"),
    ("spp", [4, 16], "spp[1]"),
    ("seed", 1, "seed"),
    ("scenes", ["cornell_box"], "scenes"),
    ("reference", {"spp": 512, "chunks": 2, "scene_spp": {}}, "reference.spp"),
    ("reference", {"spp": 1024, "chunks": 4, "scene_spp": {}}, "reference.chunks"),
    ("reference", {"spp": 1024, "chunks": 2, "scene_spp": {"cornell_box": 4096}}, "reference.scene_spp.cornell_box"),
    ("variant", "scalar_rgb", "variant"),
])
def test_a_config_differing_in_a_case_key_is_refused_naming_it(bundle, clone, key, change, named):
    refused(bundle, clone, config={**CONFIG, key: change}, match="config key " + re.escape(named) + ":")


def test_methods_and_metrics_may_differ(bundle, clone):
    config = {**CONFIG, "denoisers": ["oidn", "jbf"], "metrics": ["relmse", "smape"]}
    import_into(bundle, clone, config)
    assert (clone / "results" / "metrics.csv").exists()


def test_a_destination_file_with_other_content_is_refused_naming_it(bundle, clone):
    target = clone / "results" / "metrics.csv"
    target.parent.mkdir(parents=True)
    target.write_bytes(b"another study's metrics\n")
    refused(bundle, clone, match=r"results/metrics.csv exists with other content")


# --- an interrupted import completes -----------------------------------------------------------


@pytest.mark.parametrize("after", [0, 3, len(TREE) - 1])
def test_an_import_interrupted_while_moving_completes_when_run_again(bundle, clone, tmp_path, monkeypatch, after):
    reference_clone = tmp_path / "reference_clone"
    write_tree(reference_clone, {"Snakefile": (b"rule all:", 10), "workflow/scripts/x.py": (b"pass", 10)})
    B.import_study(bundle, config=CONFIG, workdir=reference_clone, checkout_dir=clone / "checkout")

    real_replace, moved = os.replace, []

    def failing_replace(src, dst):
        if str(dst).startswith(str(clone / "results")):
            if len(moved) == after:
                raise OSError("interrupted")
            moved.append(dst)
        return real_replace(src, dst)

    monkeypatch.setattr(B.os, "replace", failing_replace)
    with pytest.raises(OSError, match="interrupted"):
        import_into(bundle, clone)
    monkeypatch.setattr(B.os, "replace", real_replace)
    import_into(bundle, clone)
    assert listing(clone) == listing(reference_clone)


def test_files_of_equal_content_are_stored_once_as_links_and_imported_whole(study, clone, tmp_path):
    """A viewer image linked into three folders (and any file equal to an earlier one) is one
    member and two hard-link members; the import makes all three files with that content."""
    image = study / "results/viewer_entries/cornell_box/spp4/oidn/oidn_ev0.jpg"
    image.parent.mkdir(parents=True)
    image.write_bytes(b"jpeg bytes" * 1000)
    for rel in ("results/viewer_cases/cornell_box/spp4/oidn_ev0.jpg", "results/viewer/cases/cornell_box/spp4/oidn_ev0.jpg"):
        (study / rel).parent.mkdir(parents=True, exist_ok=True)
        os.link(image, study / rel)
    path = tmp_path / "linked.tar"
    B.export_study(study / "results", path, config=CONFIG, workdir=study, checkout_dir=EXPORT_CHECKOUT)
    with tarfile.open(path) as tar:
        members = {m.name: m for m in tar.getmembers()}
    jpegs = sorted(name for name in members if name.endswith("oidn_ev0.jpg"))
    assert [members[name].isfile() for name in jpegs] == [True, False, False]   # the first in path order
    assert {members[name].linkname for name in jpegs[1:]} == {jpegs[0]}
    assert path.stat().st_size < 2 * 10_000 + 30_000                       # the image's bytes once
    import_into(path, clone)
    for name in jpegs:
        assert (clone / name).read_bytes() == b"jpeg bytes" * 1000
    assert B.verify_bundle(path)["bundle_version"] == 3


def test_a_link_to_a_member_of_other_content_is_refused(bundle, clone, tmp_path):
    with tarfile.open(bundle, "r:*") as tar:
        items = [(m, tar.extractfile(m).read() if m.isfile() else None) for m in tar.getmembers()]
    manifest = json.loads(items[0][1])
    manifest["files"].append({"path": "results/extra.exr", "size": 6, "sha256": hashlib.sha256(b"xxxxxx").hexdigest(),
                              "mtime_ns": 10**9})
    bad = tmp_path / "bad_link.tar"
    with tarfile.open(bad, "w", format=tarfile.PAX_FORMAT) as tar:
        data = json.dumps(manifest).encode()
        info = tarfile.TarInfo("bundle.json")
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
        for member, content in items[1:]:
            tar.addfile(member, io.BytesIO(content))
        link = tarfile.TarInfo("results/extra.exr")
        link.type, link.linkname = tarfile.LNKTYPE, "results/renders/cornell_box/spp4.exr"
        tar.addfile(link)
    refused(bad, clone, match=r"member results/extra.exr links to .*not an earlier member of the same content")
