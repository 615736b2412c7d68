"""A suite: every task against every controller, a gain sweep over it, and the written report.

    finger-sim tasks [TASK.yaml ...] [--controller LABEL=module:callable] [--ros-controller LABEL=EXECUTABLE]
                     [--param LABEL.key=value] [--vary key=v1,v2,...] [--chunk i/n] [--out DIR] [--no-figures]

Without TASK files the installed suite (`config/tasks/*.yaml`) runs; without --controller the
shipped ones (`DEFAULT_CONTROLLERS`: `grip_pi`, `grip_pi_aggressive`, and on the drive tasks
`grip_voltage` and `grip_current`). `--ros-controller` adds a ROS 2 controller node run
through finger_node in lockstep (`finger_sim.tasks.ros_runner`; its --param values become the
node's parameters): an executable (a torque controller such as finger_grip_controller), or a
`module:callable` run as a node by finger_task_controller (a voltage controller runs the drive tasks). `--vary` (repeatable) runs the first controller over
the Cartesian product of the given parameter values (a gain sweep), each combination one more
controller column, scored the same way; a key `scene.KEY` sets the dotted scene key KEY of every
task instead (an object's parameter: `scene.objects.0.break_force`, `scene.model.contact.stiffness`); on the tasks the kernel steps, the shipped grip PI's
columns run together in one compiled loop (`finger_sim.tasks.batch`, the same runs bit for bit).
The exit status is 1 when any run fails a task.
"""

from __future__ import annotations

import dataclasses
import datetime
import itertools
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from finger_sim.errors import ConfigError
from finger_sim.scene import safe_name, scene_from_dict
from finger_sim.scene_paths import scene_dirs
from finger_sim.scene_yaml import parse_scene_text
from finger_sim.sweep import chunk_range, parse_chunk, set_key
from finger_sim.tasks import batch, report
from finger_sim.tasks.controllers import Factory, commanded_input, load_factory
from finger_sim.tasks.ros_runner import run_ros_task
from finger_sim.tasks.runner import TaskRun, run_task
from finger_sim.tasks.schema import Task

#: A --vary key with this prefix sets a scene key of the tasks, not a controller parameter.
SCENE_PREFIX = "scene."

#: The controllers a suite runs when none is named: the shipped PI and its overshooting variant
#: (torque tasks), and both shipped drive controllers side by side on each drive task: the force
#: loop `grip_voltage` (written for `hold_voltage_off`) and the current loop `grip_current`, the
#: device's controller without a force sensor (written for `hold_current`).
DEFAULT_CONTROLLERS = ("grip_pi=finger_sim.tasks.controllers:grip_pi",
                       "grip_pi_aggressive=finger_sim.tasks.controllers:grip_pi_aggressive",
                       "grip_voltage=finger_sim.tasks.controllers:grip_voltage",
                       "grip_current=finger_sim.tasks.current_grip:grip_current")


@dataclass(frozen=True)
class ControllerSpec:
    """A controller column: its label, factory and parameters (passed as keyword arguments)."""

    label: str
    factory: Factory | None
    params: dict[str, float] = field(default_factory=dict)
    ros_executable: str | None = None  # a ROS 2 controller node instead of a factory
    #: dotted scene keys (as `sweep --vary` takes them, without the SCENE_PREFIX) → values set in
    #: every task's scene for this column (an object's break_force, the contact stiffness, ...)
    scene_keys: dict[str, float] = field(default_factory=dict)


def installed_tasks() -> list[Path]:
    """The suite's task files: config/tasks/*.yaml of the first scene folder that has them."""
    for d in scene_dirs():
        found = sorted((d / "tasks").glob("*.yaml"))
        if found:
            return found
    raise ConfigError("tasks", "task files in an installed config/tasks/ folder", [str(d) for d in scene_dirs()])


def parse_controllers(specs: Sequence[str], params: Sequence[str], vary: Sequence[str],
                      ros_specs: Sequence[str] = ()) -> list[ControllerSpec]:
    """--controller LABEL=module:callable, --ros-controller LABEL=EXECUTABLE, --param LABEL.key=value,
    --vary key=v1,v2 → the columns."""
    out: list[ControllerSpec] = []
    for spec in specs or ([] if ros_specs else DEFAULT_CONTROLLERS):
        label, sep, target = spec.partition("=")
        if not sep:
            label, target = spec.rpartition(":")[2], spec
        if any(c.label == label for c in out):
            raise ConfigError("--controller", "a label no other controller uses", label)
        out.append(ControllerSpec(label, load_factory(target), {}))
    for spec in ros_specs:
        label, sep, target = spec.partition("=")
        if not sep:
            label = target = spec
        if not target or any(c.label == label for c in out):
            raise ConfigError("--ros-controller", "LABEL=EXECUTABLE with a label no other controller uses", spec)
        # a module:callable runs as a node (finger_task_controller); its factory says which input it commands
        out.append(ControllerSpec(label, load_factory(target) if ":" in target else None, {}, target))
    for item in params:
        key, sep, value = item.partition("=")
        label, dot, name = key.partition(".")
        match = [c for c in out if c.label == label]
        if not (sep and dot and name and match):
            raise ConfigError("--param", f"LABEL.key=value with LABEL one of {[c.label for c in out]}", item)
        match[0].params[name] = _number(value, f"--param {key}")
    if vary:
        base = out[0]
        axes = []
        for item in vary:
            name, sep, values = item.partition("=")
            if not (sep and name and values):
                raise ConfigError("--vary", "key=v1,v2,... (a parameter of the first controller, or scene.KEY: "
                                  "a dotted key of the tasks' scenes)", item)
            axes.append([(name, _number(v, f"--vary {name}")) for v in values.split(",")])
        if base.ros_executable is not None and any(name.startswith(SCENE_PREFIX) for name, _ in itertools.chain(*axes)):
            raise ConfigError("--vary", "controller parameters only with a ROS controller", "a scene. key")
        out = [ControllerSpec(base.label + "[" + ",".join(f"{k}={v:g}" for k, v in combo) + "]", base.factory,
                              {**base.params, **{k: v for k, v in combo if not k.startswith(SCENE_PREFIX)}},
                              base.ros_executable,
                              {k.removeprefix(SCENE_PREFIX): v for k, v in combo if k.startswith(SCENE_PREFIX)})
               for combo in itertools.product(*axes)]
    return out


def chunk_of(controllers: Sequence[ControllerSpec], chunk: str) -> list[ControllerSpec]:
    """The i-th of n contiguous slices of the controllers (`chunk` = "i/n", as `finger-sim sweep
    --chunk`): a gain sweep split over processes or machines; the slices' reports in order are
    the whole sweep's."""
    index, count = parse_chunk(chunk)
    start, stop = chunk_range(len(controllers), index, count)
    return list(controllers[start:stop])


def run_suite(tasks: Sequence[Task], controllers: Sequence[ControllerSpec], workdir: Path | None = None) -> list[TaskRun]:
    """Every task against every controller that commands its input, task by task (a torque
    controller skips a drive task, a voltage controller the others); a ROS controller's files (scene, logs,
    node output) go to `workdir`/ros/<task>_<label>/ (default: a temporary folder). Several columns
    of the shipped grip PI (a gain sweep) on a task the kernel steps run together there
    (`finger_sim.tasks.batch`: the same runs bit for bit); the others one by one."""
    runs = []
    with tempfile.TemporaryDirectory(prefix="finger_tasks_") as tmp:
        for task in tasks:
            swept = _swept(task, controllers)
            for c in controllers:
                if c.ros_executable is None:
                    assert c.factory is not None
                    if commanded_input(c.factory) != task.input:
                        continue
                    if c.label in swept:
                        runs.append(swept[c.label])
                        continue
                    runs.append(run_task(with_scene_keys(task, c.scene_keys), c.factory, label=c.label,
                                         params=c.params))
                elif task.input == (commanded_input(c.factory) if c.factory is not None else "torque"):
                    folder = (workdir or Path(tmp)) / "ros" / f"{task.name}_{safe_name(c.label)}"
                    runs.append(run_ros_task(task, c.ros_executable, folder, label=c.label, params=c.params))
    return runs


def _swept(task: Task, controllers: Sequence[ControllerSpec]) -> dict[str, TaskRun]:
    """The runs of `task` that the compiled gain sweep takes, by label: every factory with more than
    one column (offline) whose task the kernel steps (`batch.batch_reason`)."""
    groups: dict[Factory, list[ControllerSpec]] = {}
    for c in controllers:
        if c.ros_executable is None and c.factory is not None:
            groups.setdefault(c.factory, []).append(c)
    out: dict[str, TaskRun] = {}
    for factory, columns in groups.items():
        tasks = [with_scene_keys(task, c.scene_keys) for c in columns]
        if len(columns) > 1 and batch.rows_reason(tasks, factory) is None:
            runs = batch.run_task_rows(task, factory, [(c.label, c.params) for c in columns],
                                       scenes=[t.scene for t in tasks])
            out.update({r.controller: r for r in runs})
    return out


def with_scene_keys(task: Task, keys: dict[str, float]) -> Task:
    """`task` with the dotted scene keys set in its scene (`sweep.set_key`; ConfigError names a bad one)."""
    if not keys:
        return task
    data = task.scene.to_dict()
    try:
        for key, value in keys.items():
            set_key(data, key, value)
        return dataclasses.replace(task, scene=scene_from_dict(data))
    except ConfigError as exc:
        raise ConfigError(f"--vary {SCENE_PREFIX}{exc.key.removeprefix('--vary ')} (task '{task.name}')", exc.allowed,
                          exc.got) from None


def write_report(runs: Sequence[TaskRun], tasks: Sequence[Task], out: Path, *, figures: bool = True,
                 command: str = "") -> Path:
    """report.md, metrics.json and one figure per task (tasks_<name>.png) into `out`; the report's path."""
    out.mkdir(parents=True, exist_ok=True)
    drawn: dict[str, str] = {}
    if figures:
        for task in tasks:
            name = f"tasks_{task.name}.png"
            report.figure([r for r in runs if r.task == task.name], out / name)
            drawn[task.name] = name
    descriptions = {t.name: t.description for t in tasks}
    text = ["# Grasp tasks: scores", ""]
    if command:
        text += [f"Made by `{command}` on {datetime.date.today().isoformat()}.", ""]
    text += [summary_table(runs), "", report.markdown(runs, descriptions, drawn)]
    path = out / "report.md"
    path.write_text("\n".join(text) + "\n", encoding="utf-8")
    (out / "metrics.json").write_text(report.to_json(runs) + "\n", encoding="utf-8")
    return path


def summary_table(runs: Sequence[TaskRun]) -> str:
    """Pass/fail of every task (rows) per controller (columns), Markdown."""
    labels = list(dict.fromkeys(r.controller for r in runs))
    lines = ["| task | " + " | ".join(f"`{c}`" for c in labels) + " |", "|---|" + "---|" * len(labels)]
    for task in dict.fromkeys(r.task for r in runs):
        by = {r.controller: r for r in runs if r.task == task}
        cells = []
        for c in labels:
            if c not in by:
                cells.append("—")  # the controller commands another input than the task's
                continue
            r = by[c]
            failed = [k for k, ok in r.passed.items() if not ok]
            cells.append("pass" if r.ok else "FAIL (" + ", ".join(failed) + ")")
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _number(text: str, key: str) -> float:
    value = parse_scene_text(text, key) if text.strip() else None
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise ConfigError(key, "a number", text)
    return float(value)
