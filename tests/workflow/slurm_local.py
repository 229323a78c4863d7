"""A single-node SLURM on this machine, for the cluster test (tests/workflow/test_slurm.py) and by hand:

    python tests/workflow/slurm_local.py start STATE_DIR     # prints the daemons' process ids, waits for the node
    python tests/workflow/slurm_local.py stop STATE_DIR      # stops them by those process ids

Debian's ``slurm-wlm`` and ``munge`` (``setup.sh`` installs them when run as root). One node,
this machine, runs ``slurmctld`` and ``slurmd``; ``munged`` authenticates them. Choices, each
forced by what was found when this was first tried here:

* ``slurm.conf`` sits at the default ``/etc/slurm/slurm.conf``: the SLURM executor plugin clears
  ``SLURM_*`` variables inside its jobs, so with ``SLURM_CONF`` the in-job ``srun`` fails. A file
  already there that this script did not write (no :data:`MARKER` line) is never touched: the
  cluster is then reported unavailable instead. ``stop`` removes the file it wrote.
* No accounting database (``AccountingStorageType=accounting_storage/none``): ``sacct`` then
  answers "accounting storage is disabled", so the executor must read job states from
  ``squeue`` (``--slurm-status-command squeue``), which sees finished jobs for ``MinJobAge``
  seconds (300, above the plugin's 120-s threshold).
* ``select/cons_tres`` with ``CR_CPU_Memory``: jobs get CPUs and memory, several jobs share the
  node; the node's CPUs and memory are what ``slurmd -C`` reports (memory lowered by 10 %).
* A fake GPU (``gres.conf``: ``Name=gpu File=/dev/null``; a bare ``Count=1`` leaves the node
  INVALID), so that jobs asking ``--gpus=1`` can be scheduled in tests of the GPU profile.
* ``proctrack/linuxproc`` and ``task/none``: no cgroups needed inside a container or VM.
* ``munged`` listens on a socket in ``STATE_DIR`` (``AuthInfo=socket=...``), not the system's.

The daemons run in the foreground (``-D``, ``--foreground``) as children of the starting
process group's session, their process ids kept in ``STATE_DIR/pids``; ``stop`` sends them
SIGTERM, then SIGKILL after 10 s.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

SLURM_CONF = Path("/etc/slurm/slurm.conf")
GRES_CONF = Path("/etc/slurm/gres.conf")
MUNGE_KEY = Path("/etc/munge/munge.key")
MARKER = "# written by mcbench tests/slurm_local.py"  # (its old path: kept, so configs written before still count)
DAEMONS = ("munged", "slurmctld", "slurmd")
PARTITION = "debug"


def unavailable_reason() -> str | None:
    """Why a local SLURM cannot run here (``None`` when it can): not root, the daemons or
    client commands missing, or a slurm.conf this script did not write."""
    if os.geteuid() != 0:
        return "a local SLURM needs root (slurmd runs jobs as their users)"
    missing = [tool for tool in ("munged", "slurmctld", "slurmd", "sbatch", "squeue", "scontrol", "srun")
               if shutil.which(tool) is None and not Path(f"/usr/sbin/{tool}").exists()]
    if missing:
        return f"SLURM tools not installed ({', '.join(missing)}): run setup.sh as root (Debian slurm-wlm, munge)"
    for path in (SLURM_CONF, GRES_CONF):
        if path.exists() and MARKER not in path.read_text(errors="replace"):
            return f"{path} exists and was not written by tests/workflow/slurm_local.py; not touching a real cluster's config"
    return None


def _tool(name: str) -> str:
    return shutil.which(name) or f"/usr/sbin/{name}"


def node_line(hostname: str) -> str:
    """``NodeName=... CPUs=... RealMemory=...`` for this machine from ``slurmd -C`` (memory
    lowered by 10 %, so that the node is never refused for having less than it claims)."""
    output = subprocess.run([_tool("slurmd"), "-C"], capture_output=True, text=True, check=True).stdout
    line = next(line for line in output.splitlines() if line.startswith("NodeName="))
    fields = dict(item.split("=", 1) for item in line.split() if "=" in item)
    memory = int(int(fields.get("RealMemory", "2048")) * 0.9)
    keep = ("CPUs", "Boards", "SocketsPerBoard", "CoresPerSocket", "ThreadsPerCore")
    parts = [f"NodeName={hostname}", "NodeAddr=127.0.0.1"] + [f"{k}={fields[k]}" for k in keep if k in fields]
    return " ".join(parts + [f"RealMemory={memory}", "Gres=gpu:1", "State=UNKNOWN"])


def slurm_conf(state: Path, hostname: str) -> str:
    """The single-node ``slurm.conf`` (choices in the module docstring)."""
    return "\n".join([
        MARKER,
        "ClusterName=mcbench",
        f"SlurmctldHost={hostname}(127.0.0.1)",
        "SlurmUser=root",
        "SlurmdUser=root",
        "AuthType=auth/munge",
        f"AuthInfo=socket={state / 'munge' / 'munge.socket'}",
        "CredType=cred/munge",
        "MpiDefault=none",
        "ProctrackType=proctrack/linuxproc",
        "TaskPlugin=task/none",
        "ReturnToService=2",
        "SchedulerType=sched/backfill",
        "SelectType=select/cons_tres",
        "SelectTypeParameters=CR_CPU_Memory",
        "AccountingStorageType=accounting_storage/none",
        "JobAcctGatherType=jobacct_gather/none",
        "JobCompType=jobcomp/none",
        "MinJobAge=300",
        "GresTypes=gpu",
        f"StateSaveLocation={state / 'ctld'}",
        f"SlurmdSpoolDir={state / 'spool'}",
        f"SlurmctldPidFile={state / 'slurmctld.pid'}",
        f"SlurmdPidFile={state / 'slurmd.pid'}",
        f"SlurmctldLogFile={state / 'slurmctld.log'}",
        f"SlurmdLogFile={state / 'slurmd.log'}",
        "SlurmctldTimeout=30",
        "SlurmdTimeout=30",
        node_line(hostname),
        f"PartitionName={PARTITION} Nodes=ALL Default=YES MaxTime=INFINITE State=UP",
        "",
    ])


def _wait_for(predicate, timeout: float, what: str, logs: list[Path]) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.5)
    tails = "\n".join(f"--- {log}:\n{log.read_text(errors='replace')[-2000:]}" for log in logs if log.exists())
    raise RuntimeError(f"local SLURM: {what} not within {timeout:.0f} s\n{tails}")


def _node_state(hostname: str) -> str:
    result = subprocess.run([_tool("sinfo"), "-h", "-N", "-n", hostname, "-o", "%T"],
                            capture_output=True, text=True)
    return result.stdout.strip().lower() if result.returncode == 0 else ""


def start(state: str | Path) -> dict[str, int]:
    """Write the config, start munged, slurmctld and slurmd, wait until the node is idle;
    returns ``{daemon: pid}`` (also in ``state/pids``). RuntimeError naming the cause and the
    daemons' log tails when it cannot; whatever started is stopped again first."""
    reason = unavailable_reason()
    if reason:
        raise RuntimeError(f"local SLURM unavailable: {reason}")
    state = Path(state).resolve()
    for sub in ("ctld", "spool", "munge"):
        (state / sub).mkdir(parents=True, exist_ok=True)
    hostname = socket.gethostname().split(".")[0]
    SLURM_CONF.parent.mkdir(parents=True, exist_ok=True)
    SLURM_CONF.write_text(slurm_conf(state, hostname))
    GRES_CONF.write_text(f"{MARKER}\nName=gpu File=/dev/null\n")
    if not MUNGE_KEY.exists():
        subprocess.run([_tool("mungekey"), "--create", "--keyfile", str(MUNGE_KEY)], check=True)
    socket_path = state / "munge" / "munge.socket"
    pids: dict[str, int] = {}
    logs = [state / "munged.log", state / "slurmctld.log", state / "slurmd.log"]
    try:
        munged = subprocess.Popen(
            [_tool("munged"), "--foreground", "--force", f"--socket={socket_path}",
             f"--log-file={state / 'munged.log'}", f"--pid-file={state / 'munged.pid'}",
             f"--seed-file={state / 'munge' / 'seed'}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, start_new_session=True)
        pids["munged"] = munged.pid
        _wait_for(socket_path.exists, 20, "munged's socket", logs)
        for daemon in ("slurmctld", "slurmd"):
            process = subprocess.Popen([_tool(daemon), "-D"], stdout=open(state / f"{daemon}.out", "w"),
                                       stderr=subprocess.STDOUT, start_new_session=True)
            pids[daemon] = process.pid
            if daemon == "slurmctld":
                _wait_for(lambda: subprocess.run([_tool("scontrol"), "ping"], capture_output=True,
                                                 text=True).stdout.count("UP") > 0, 30, "slurmctld answering", logs)
        _wait_for(lambda: _node_state(hostname).startswith(("idle", "mixed", "allocated")), 60,
                  f"node {hostname} idle", logs + [state / "slurmd.out"])
    except BaseException:
        _write_pids(state, pids)
        stop(state)
        raise
    _write_pids(state, pids)
    return pids


def _write_pids(state: Path, pids: dict[str, int]) -> None:
    (state / "pids").write_text("".join(f"{name} {pid}\n" for name, pid in pids.items()))


def stop(state: str | Path) -> None:
    """Stop the daemons ``start`` recorded in ``state/pids`` (SIGTERM, SIGKILL after 10 s) and
    remove the config files it wrote."""
    state = Path(state).resolve()
    pids_file = state / "pids"
    pids = {}
    if pids_file.exists():
        pids = {name: int(pid) for name, pid in (line.split() for line in pids_file.read_text().splitlines())}
    for name in reversed([n for n in DAEMONS if n in pids]):
        _terminate(pids[name])
    for path in (SLURM_CONF, GRES_CONF):
        if path.exists() and MARKER in path.read_text(errors="replace"):
            path.unlink()
    pids_file.unlink(missing_ok=True)


def _terminate(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            finished, _ = os.waitpid(pid, os.WNOHANG)
            if finished:
                return
        except ChildProcessError:            # not our child: poll for it to go away
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                return
        time.sleep(0.2)
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in ("start", "stop"):
        raise SystemExit(__doc__.split("\n\n")[1])
    if sys.argv[1] == "start":
        for name, pid in start(sys.argv[2]).items():
            print(name, pid)
    else:
        stop(sys.argv[2])
