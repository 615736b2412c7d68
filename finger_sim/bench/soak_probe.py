"""Per-thread scheduling probe for a soak: which thread of a process tree waited, faulted or ran.

Samples every thread of `--pid` and of all its descendants every `--period` wall s from /proc
(Linux only): the scheduling policy and priority, run time and run-queue wait
(/proc/<pid>/task/<tid>/schedstat, ns), the CPU it last ran on, minor and major page faults, voluntary and forced
context switches; and the machine's steal time and major faults (/proc/stat, /proc/vmstat).
Each sample is one CSV row per thread, with the wall time (time.time(), s) so that a late
/diagnostics window can be matched with what each thread did in it. Read only; it changes nothing.

    python -m finger_sim.bench.soak_probe --pid <pytest pid> --out probe.csv [--period 0.05]

Runs until the process `--pid` exits (or is a zombie).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

#: Sampling period, wall s (20 Hz: a 10 ms stall shows in the sample that holds it).
DEFAULT_PERIOD_S = 0.05
#: Clock ticks per second of /proc/stat (USER_HZ).
USER_HZ = os.sysconf("SC_CLK_TCK")
HEADER = ("wall_s,pid,tid,proc,thread,cpu,policy,rtprio,run_ns,wait_ns,slices,minflt,majflt,"
          "vol_switches,forced_switches,steal_s,vm_majflt\n")


def descendants(root: int) -> list[int]:
    """`root` and every process below it (through /proc/<pid>/task/*/children)."""
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        for children in Path(f"/proc/{pid}/task").glob("*/children"):
            try:
                todo += [int(c) for c in children.read_text().split()]
            except OSError:
                pass
    return out


def alive(pid: int) -> bool:
    """True while `pid` runs (neither gone nor a zombie waiting for its parent)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def machine_counters() -> tuple[float, int]:
    """(steal s since boot, major faults since boot) of the whole machine."""
    steal = int(Path("/proc/stat").read_text().split("\n", 1)[0].split()[8]) / USER_HZ
    majflt = 0
    for line in Path("/proc/vmstat").read_text().splitlines():
        if line.startswith("pgmajfault "):
            majflt = int(line.split()[1])
    return steal, majflt


def thread_row(pid: int, tid: int, proc: str) -> str | None:
    """One CSV row (without the wall time and machine columns) for thread `tid`, None if gone."""
    base = f"/proc/{pid}/task/{tid}"
    try:
        stat = Path(f"{base}/stat").read_text()
        run_ns, wait_ns, slices = Path(f"{base}/schedstat").read_text().split()
        status = Path(f"{base}/status").read_text()
    except OSError:
        return None
    name = stat[stat.index("(") + 1:stat.rindex(")")].replace(",", ";")
    f = stat[stat.rindex(")") + 2:].split()  # fields from 3 (state) on: f[i] is field i + 3
    vol = forced = "0"
    for line in status.splitlines():
        if line.startswith("voluntary_ctxt_switches:"):
            vol = line.split()[1]
        elif line.startswith("nonvoluntary_ctxt_switches:"):
            forced = line.split()[1]
    return f"{pid},{tid},{proc},{name},{f[36]},{f[38]},{f[37]},{run_ns},{wait_ns},{slices},{f[7]},{f[9]},{vol},{forced}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pid", type=int, required=True, help="root of the process tree to sample")
    parser.add_argument("--out", type=Path, required=True, help="CSV file to write")
    parser.add_argument("--period", type=float, default=DEFAULT_PERIOD_S, help="sampling period, wall s")
    args = parser.parse_args(argv)
    with args.out.open("w") as out:
        out.write(HEADER)
        while alive(args.pid):
            wall = time.time()
            steal, vm_majflt = machine_counters()
            for pid in descendants(args.pid):
                try:
                    proc = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                    tids = os.listdir(f"/proc/{pid}/task")
                except OSError:
                    continue
                label = next((p.decode() for p in proc if p.startswith(b"finger_sim")), proc[0].decode().rsplit("/", 1)[-1])
                for tid in tids:
                    row = thread_row(pid, int(tid), label)
                    if row is not None:
                        out.write(f"{wall:.3f},{row},{steal:.2f},{vm_majflt}\n")
            time.sleep(max(0.0, wall + args.period - time.time()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
