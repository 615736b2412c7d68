"""finger_sim.bench.soak_offcpu on hand-made `perf script` text: every stretch and count it prints
against the one worked out here from the events written."""

from __future__ import annotations

from finger_sim.bench import soak_offcpu

STEP = 500  # the stepping thread's id


def switch_out(comm: str, t: float, state: str, stack: list[str]) -> str:
    return (f"  python {STEP} {t:.6f}: sched:sched_switch: prev_comm=python prev_pid={STEP} prev_prio=78 "
            f"prev_state={state} ==> next_comm={comm} next_pid=9 next_prio=120\n"
            + "".join(f"\tffffffff8100{i:04x} {f}\n" for i, f in enumerate(stack)) + "\n")


def switch_in(t: float) -> str:
    return (f"  other 9 {t:.6f}: sched:sched_switch: prev_comm=other prev_pid=9 prev_prio=120 prev_state=R "
            f"==> next_comm=python next_pid={STEP} next_prio=78\n\tffffffff81000001 __schedule\n\n")


def wakeup(comm: str, tid: int, t: float, stack: list[str]) -> str:
    return (f"  {comm} {tid} {t:.6f}: sched:sched_wakeup: comm=python pid={STEP} prio=78 target_cpu=001\n"
            + "".join(f"\tffffffff8200{i:04x} {f}\n" for i, f in enumerate(stack)) + "\n")


SLEEP = ["__schedule", "schedule", "futex_do_wait", "__futex_wait", "do_futex"]
TIMER = ["ttwu_do_activate", "try_to_wake_up", "hrtimer_wakeup", "__hrtimer_run_queues"]
FUTEX = ["ttwu_do_activate", "try_to_wake_up", "wake_up_q", "futex_wake", "do_futex"]


def test_stretches_wakers_and_run_queue_from_perf_text(tmp_path, capsys):
    text = (
        # 1: asleep 0.8 ms, its own timer (in another task's context), runnable 0.01 ms
        switch_out("a", 100.000, "S", SLEEP) + wakeup("kdamond.0", 77, 100.0008, TIMER) + switch_in(100.00081)
        # 2: asleep 13.4 ms in a futex, woken by another process's thread; runnable 0.02 ms
        + switch_out("b", 100.002, "S", SLEEP) + wakeup("dds.shm.33165", 7739, 100.0154, FUTEX) + switch_in(100.01542)
        # 3: asleep 0.9 ms, timer; then runnable 28.4 ms before it runs
        + switch_out("c", 100.020, "S", SLEEP) + wakeup("python", 42, 100.0209, TIMER) + switch_in(100.0493)
        # 4: preempted (R), back 6 ms later: runnable all along
        + switch_out("d", 100.060, "R", ["__schedule", "preempt_schedule_irq", "irqentry_exit"]) + switch_in(100.066)
        # another thread's wake-up: not the stepping thread's
        + "  x 1 100.070000: sched:sched_wakeup: comm=python pid=501 prio=120 target_cpu=000\n\tffffffff82000000 hrtimer_wakeup\n\n"
    )
    perf = tmp_path / "perf.txt"
    perf.write_text(text)
    assert soak_offcpu.main(["--perf", str(perf), "--tid", str(STEP), "--min-ms", "5", "--wall-offset", "1000"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        "asleep 13.4 ms from 1100.002 in futex_do_wait, woken by dds.shm.33165/7739 via futex_wake",
        "runnable 28.4 ms from 1100.021",
        "runnable 6.0 ms from 1100.060",
        "wake-ups by mechanism and waker: hrtimer_wakeup (its timer): 2; futex_wake dds.shm.33165/7739: 1",
    ]
