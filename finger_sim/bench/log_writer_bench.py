"""CPU per message of the log writer process, this checkout against an old one; prints a table.

    python -m finger_sim.bench.log_writer_bench --old /work/main [--messages 120000] [--rounds 5]

The writer process (finger_sim.log.writer_process.main) is run on a prepared input: a `Start`,
three channels, `--messages` messages as a node logs them at 1 kHz (joint_states, fingertip_pose
and /clock every step: 148, 84 and 12 bytes of CDR, log times 1 ms apart; in runs of 750, a
default handover) and `Close`; chunks close
every 0.5 s of log time, zstd, as finger_node records. The input comes from a file, so that the
writer never waits for a caller. CPU: utime + stime of the writer process (os.wait4), less the
median of the same process given no messages (interpreter start and imports), per message.
Each round runs this checkout, then `--old` (put first on PYTHONPATH), then an empty input
for each (A B A B); medians over the rounds and their ratio. Each checkout writes its own input
(its own stdin format), the same messages. The two files must hold the same
messages (mcap's reader); whether they are equal byte for byte is printed (they differ when the two
compress at different zstd levels: writer_process.ZSTD_LEVEL, 1 since 2026-11-27, against mcap's 3
before), with each file's size.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path

from finger_sim.log.writer_process import Close, Register, Start, control_record, message_record, message_run

ROOT = Path(__file__).resolve().parents[2]
#: The node's three per-step messages: topic, type, CDR bytes (a JointState of three joints, a PoseStamped, a Clock).
TOPICS = (("/joint_states", "sensor_msgs/msg/JointState", 148), ("/fingertip_pose", "geometry_msgs/msg/PoseStamped", 84),
          ("/clock", "rosgraph_msgs/msg/Clock", 12))
STEP_NS = 1_000_000  # 1 kHz
RUN_MESSAGES = 750  # messages a run: 0.25 s of the node's three topics at 1 kHz (the handover its figures were made with)
CHUNK_INTERVAL_NS = 500_000_000  # finger_sim.log.recorder.DEFAULT_CHUNK_INTERVAL_S
CHUNK_SIZE = 1 << 20
ZSTD = 3  # mcap.writer.CompressionType.ZSTD
WRITER = "import sys; from finger_sim.log.writer_process import main; sys.exit(main())"


def writer_input(path: Path, log: Path, messages: int) -> None:
    """The writer process's stdin for `messages` messages (a multiple of the topics is used)."""
    parts = [control_record(Start(str(log), CHUNK_INTERVAL_NS, CHUNK_SIZE, ZSTD, 1.0, 1.0))]
    parts += [control_record(Register(i, topic, type_name, "", {})) for i, (topic, type_name, _) in enumerate(TOPICS)]
    payloads = [b"\x00\x01\x00\x00" + bytes((i * 37 + k) % 256 for k in range(size - 4)) for i, (_, _, size) in enumerate(TOPICS)]
    records = []
    for n in range(messages):
        step, index = divmod(n, len(TOPICS))
        t = step * STEP_NS
        data = payloads[index][:-4] + (step % (1 << 32)).to_bytes(4, "little")  # a changing field, as in a real log
        records.append((message_record(index, step + 1, t, t, data), len(data)))
    for first in range(0, messages, RUN_MESSAGES):  # in runs, as the recorder hands them over
        run = records[first:first + RUN_MESSAGES]
        parts.append(message_run(b"".join(record for record, _ in run), [size for _, size in run]))
    parts.append(control_record(Close()))
    path.write_bytes(b"".join(parts))


def _env(pythonpath: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = pythonpath + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def side_input(path: Path, log: Path, messages: int, pythonpath: str, workdir: Path) -> None:
    """`writer_input` as the checkout at `pythonpath` writes it (its own stdin format)."""
    code = f"from pathlib import Path; from finger_sim.bench.log_writer_bench import writer_input; writer_input(Path({str(path)!r}), Path({str(log)!r}), {messages})"
    subprocess.run([sys.executable, "-c", code], env=_env(pythonpath), cwd=workdir, check=True)


def run_writer(stdin: Path, pythonpath: str, workdir: Path) -> float:
    """CPU seconds of one writer process fed `stdin`."""
    env = _env(pythonpath)
    with stdin.open("rb") as f:
        # cwd outside any checkout: `python -c` puts the working folder first on sys.path
        proc = subprocess.Popen([sys.executable, "-c", WRITER], stdin=f, stdout=subprocess.DEVNULL, env=env, cwd=workdir)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"the writer process exited with {proc.returncode}")
    return usage.ru_utime + usage.ru_stime


def messages_in(path: Path) -> list[tuple[int, int, int, bytes]]:
    from mcap.reader import make_reader
    with path.open("rb") as f:
        return [(m.channel_id, m.sequence, m.log_time, m.data) for _, _, m in make_reader(f).iter_messages(log_time_order=False)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old", required=True, help="a checkout of finger_sim to compare with (put first on PYTHONPATH)")
    parser.add_argument("--messages", type=int, default=120_000)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        sides = {"new": str(ROOT), "old": args.old}
        for name, path in sides.items():  # each checkout's own stdin format
            side_input(work / f"{name}_full.in", work / "log.mcap", args.messages, path, work)
            side_input(work / f"{name}_empty.in", work / "empty.mcap", 0, path, work)
        cpu: dict[str, list[float]] = {"new": [], "old": [], "new empty": [], "old empty": []}
        for _ in range(args.rounds):
            for name, path in sides.items():
                cpu[name].append(run_writer(work / f"{name}_full.in", path, work))
                os.replace(work / "log.mcap", work / f"{name}.mcap")
                cpu[f"{name} empty"].append(run_writer(work / f"{name}_empty.in", path, work))
        new_messages, old_messages = messages_in(work / "new.mcap"), messages_in(work / "old.mcap")
        if new_messages != old_messages or len(new_messages) != args.messages:
            raise RuntimeError("the new and the old writer's files hold different messages")
        same = (work / "new.mcap").read_bytes() == (work / "old.mcap").read_bytes()
        sizes = {name: (work / f"{name}.mcap").stat().st_size for name in sides}
    per = {name: (statistics.median(cpu[name]) - statistics.median(cpu[f"{name} empty"])) / args.messages * 1e6
           for name in ("new", "old")}
    load = os.getloadavg()[0]
    print(f"Command: `python -m finger_sim.bench.log_writer_bench --old {args.old} --messages {args.messages} "
          f"--rounds {args.rounds}` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, load average {load:.1f} on "
          f"{os.cpu_count()} cores).\n")
    print("| writer process, CPU per message | new | old | new / old |")
    print("|---|---|---|---|")
    print(f"| µs (median of {args.rounds}, less start-up) | {per['new']:.2f} | {per['old']:.2f} | {per['new'] / per['old']:.2f} |")
    print("| each round, CPU s (new; old) | " + ", ".join(f"{c:.2f}" for c in cpu["new"]) + " | "
          + ", ".join(f"{c:.2f}" for c in cpu["old"]) + " | |")
    print(f"| start-up alone, CPU s (median) | {statistics.median(cpu['new empty']):.2f} | "
          f"{statistics.median(cpu['old empty']):.2f} | |")
    print(f"\nBoth files hold the same {len(new_messages)} messages; byte for byte {'equal' if same else 'different'} "
          f"({sizes['new']} bytes new, {sizes['old']} old).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
