"""One case job's CPU under the former storage (render ZIP, kept outputs uncompressed) and the
current one (both Zstandard), alternated in one process. A script, not a timed test:

    python benchmarks/case_storage.py before|after --workdir DIR [--scene veach_ajar --spp 64]

``DIR``: a working folder whose ``results/renders/<scene>/spp<N>.exr`` and
``results/references/<scene>.exr`` exist (e.g. copied from a finished default run) and whose
``config.yaml`` (a link to the checkout's) plans the case. The render is written again under the
chosen compression, the case's outputs, values and viewer images are removed, the case job runs
once untimed (imports, numba's cache, the methods' warm-ups) and once measured. Prints the
process's CPU seconds (user + system), wall seconds, the case record's phases and the load average.
"""
import argparse
import os
import resource
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import yaml  # noqa: E402
import mcbench.pipeline.cases as C  # noqa: E402
from mcbench.io.exr import read_layers, read_metadata, write_layers  # noqa: E402
from mcbench.pipeline.study_setup import setup_study  # noqa: E402

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("mode", choices=["before", "after"])
parser.add_argument("--workdir", type=Path, required=True)
parser.add_argument("--scene", default="veach_ajar")
parser.add_argument("--spp", type=int, default=64)
args = parser.parse_args()
os.chdir(args.workdir)
mode, scene, spp = args.mode, args.scene, args.spp
cfg = yaml.safe_load(open('config.yaml'))
study = setup_study(cfg)
render = f'results/renders/{scene}/spp{spp}.exr'
meta = read_metadata(render)
write_layers(render, read_layers(render), metadata=meta, compression='zip' if mode == 'before' else 'zstd')
C.KEPT_OUTPUT_COMPRESSION = 'none' if mode == 'before' else 'zstd'
shutil.rmtree('results/outputs', ignore_errors=True); shutil.rmtree('results/metrics', ignore_errors=True)
for d in ('results/viewer_entries', 'results/viewer_cases', 'results/cases', 'results/values'):
    shutil.rmtree(d, ignore_errors=True)
outputs = {k: f'results/{p}/{scene}/spp{spp}{ext}' for k, p, ext in (('metrics', 'metrics', '.csv'), ('viewer', 'viewer_cases', ''), ('record', 'cases', '.json'))}
job = study.case_job(scene, spp, outputs)
from mcbench.pipeline.threads import limit_threads
limit_threads(1)
# warm (imports, numba, warm-ups) on a first run, then the measured one
C.run_case(job)
for d in ('results/outputs', 'results/metrics', 'results/viewer_entries', 'results/viewer_cases', 'results/cases', 'results/values'):
    shutil.rmtree(d, ignore_errors=True)
r0 = resource.getrusage(resource.RUSAGE_SELF); t = time.perf_counter()
rec = C.run_case(job)
r1 = resource.getrusage(resource.RUSAGE_SELF)
print(mode, 'cpu', round(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime, 2), 'wall', round(time.perf_counter() - t, 2),
      {k: round(v['cpu'], 2) for k, v in rec['seconds'].items()}, 'load', os.getloadavg()[0])
