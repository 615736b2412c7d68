"""ROS isolation for the tests that start nodes: a DDS domain per test, loopback discovery,
child processes that always stop, and waiting on conditions with deadlines (never sleep-then-assert).

rclpy is imported lazily, inside the fixtures: the core's tests (test_core_isolation) must not
find ROS in sys.modules because this file was collected.

Domain ids: TEST_DOMAINS (60-99, or the inclusive range in FINGER_SIM_TEST_DOMAINS), from a
per-process counter offset by the pid, so that two pytest sessions running at the same time
rarely share one, and never with the ids used by hand (20-49). Discovery stays on the loopback interface.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, settings

def _test_domains() -> range:
    """60-99, or FINGER_SIM_TEST_DOMAINS="lo-hi" (inclusive) to keep parallel checkouts apart."""
    spec = os.environ.get("FINGER_SIM_TEST_DOMAINS", "")
    if not spec:
        return range(60, 100)
    low, high = (int(part) for part in spec.split("-"))
    return range(low, high + 1)


TEST_DOMAINS = _test_domains()

# Hypothesis budgets (test_fuzz.py): "default" keeps the suite's time (a fixed, repeatable set
# of examples, nothing stored in the tree); `pytest --hypothesis-profile=long` searches anew
# each run, with many more examples, and keeps failures in .hypothesis/ to replay them.
# No deadline: an example's wall time is not a property, and a first example may compile the numba
# kernels (185 s measured on a cold cache at load 6, failing as "Unreliable test timings").
settings.register_profile("default", max_examples=40, deadline=None, derandomize=True, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=2_000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("default")
_counter = itertools.count((os.getpid() * 7) % len(TEST_DOMAINS))

#: Wall-clock deadlines, s. Generous: two shared cores, other sessions running.
START_TIMEOUT = 20.0
STOP_TIMEOUT = 10.0
WAIT_TIMEOUT = 20.0
SPIN_SLICE = 0.01
SERVICE_SETTLE = 0.25  # s a new service client waits after it is ready (see RosClient.call)
RESEND_AFTER = 3.0  # s before an unanswered idempotent request is sent again
IDEMPOTENT_SERVICES = {"SetBool", "GetParameters", "SetParameters"}


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--run-slow", action="store_true", help="also run the tests marked slow (the quick bench run, long energy runs)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked slow run only with --run-slow (docs/test_suite.md says when they last ran)."""
    if config.getoption("--run-slow"):
        return
    skip = pytest.mark.skip(reason="slow: opt in with --run-slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


ROS_LAYER = Path(__file__).resolve().parent / "ros"
#: Fixtures that start a node over DDS, in the other layers (the logs are a node's real run).
NODE_FIXTURES = frozenset({"launcher", "ros_client", "ros_domain", "node_log", "hand_log", "real_log", "grasp_log"})


def pytest_itemcollected(item: pytest.Item) -> None:
    """Every test under test/ros/, and every test that starts a node, is marked `ros`:
    `pytest -m "not ros"` runs the ROS-free rest."""
    if ROS_LAYER in item.path.resolve().parents or NODE_FIXTURES & set(getattr(item, "fixturenames", ())):
        item.add_marker(pytest.mark.ros)


def allocate_domain_id() -> int:
    return TEST_DOMAINS[next(_counter) % len(TEST_DOMAINS)]


def ros_environment(domain_id: int) -> dict[str, str]:
    """Environment of a child ROS process: its domain, loopback discovery only, unbuffered logs."""
    env = dict(os.environ)
    for key in ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER", "FASTRTPS_DEFAULT_PROFILES_FILE"):
        env.pop(key, None)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PYTHONUNBUFFERED="1",
        RCUTILS_COLORIZED_OUTPUT="0",
        RCUTILS_LOGGING_BUFFERED_STREAM="0",
    )
    return env


def wait_until(condition: Callable[[], Any], timeout: float, what: str, *, spin: Callable[[float], None] | None = None,
               poll: float = SPIN_SLICE) -> Any:
    """Return condition()'s first truthy value; AssertionError naming `what` at the deadline.

    spin(dt): called between checks (e.g. an executor's spin_once) instead of sleeping.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        if spin is not None:
            spin(poll)
        else:
            time.sleep(poll)


class RosProcess:
    """A child process in its own process group, its output in a file (stderr in a second one
    with `stderr_path`, else merged into the first); stop() is safe to repeat."""

    def __init__(self, argv: list[str], env: dict[str, str], log_path: Path, cwd: Path | None = None, *,
                 stderr_path: Path | None = None) -> None:
        self.argv = argv
        self.log_path = log_path
        self.stderr_path = stderr_path
        self._log = open(log_path, "wb")
        self._err = open(stderr_path, "wb") if stderr_path is not None else None
        self.proc = subprocess.Popen(argv, env=env, cwd=cwd, stdout=self._log,
                                     stderr=self._err if self._err is not None else subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def running(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        """What the process wrote to stdout (and stderr, unless kept apart); also after stop()."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def errors(self) -> str:
        """What the process wrote to stderr when kept apart (stderr_path), else ''."""
        return "" if self.stderr_path is None else self.stderr_path.read_text(errors="replace")

    def finish(self, timeout: float) -> tuple[int, str, str]:
        """Wait for the exit: (status, stdout, stderr); AssertionError if it does not exit in time."""
        return self.wait(timeout), self.output(), self.errors()

    def send_signal(self, sig: int) -> None:
        """A signal to the process itself (stop() signals its whole group)."""
        self.proc.send_signal(sig)

    def wait(self, timeout: float) -> int:
        """Exit status; AssertionError with the output if it does not exit in time."""
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{self.argv[:4]} did not exit within {timeout:g} s; output:\n"
                                 f"{self.output()}{self.errors()}") from None

    def stop(self) -> int | None:
        """SIGINT to the group, then SIGKILL after STOP_TIMEOUT; returns the exit status."""
        if self.proc.poll() is None:
            self._signal(signal.SIGINT)
            try:
                self.proc.wait(STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                self._signal(signal.SIGKILL)
                self.proc.wait(STOP_TIMEOUT)
        else:  # the leader is gone; make sure nothing it started lingers
            self._signal(signal.SIGKILL)
        self._log.close()
        if self._err is not None:
            self._err.close()
        return self.proc.returncode

    def _signal(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass


class Launcher:
    """Starts nodes and scripts for one test; the fixture stops every one of them."""

    def __init__(self, env: dict[str, str], tmp: Path) -> None:
        self.env = env
        self.tmp = tmp
        self.processes: list[RosProcess] = []

    def start(self, argv: list[str], name: str, *, separate_stderr: bool = False) -> RosProcess:
        """Start `argv` in the test's folder; its output in <name>.log (stderr in <name>.err if separate)."""
        stderr_path = self.tmp / f"{name}.err" if separate_stderr else None
        proc = RosProcess(argv, self.env, self.tmp / f"{name}.log", cwd=self.tmp, stderr_path=stderr_path)
        self.processes.append(proc)
        return proc

    def node(self, module: str, params: dict[str, Any] | None = None, *, name: str | None = None,
             ros_args: list[str] = ()) -> RosProcess:
        """`python -m module --ros-args --params-file <params> [ros_args]`; floats stay floats (YAML)."""
        name = name or module.rsplit(".", 1)[-1]
        argv = [sys.executable, "-m", module, "--ros-args"]
        if params:
            path = self.tmp / f"{name}.params.yaml"
            path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
            argv += ["--params-file", str(path)]
        return self.start(argv + list(ros_args), name)

    def stop_all(self) -> None:
        for proc in reversed(self.processes):
            proc.stop()


class RosClient:
    """The test's own ROS node in a private context on the test's domain; spun only while waiting."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("test_client", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: dict[str, Any] = {}

    def spin(self, timeout: float = SPIN_SLICE) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def wait_for(self, condition: Callable[[], Any], what: str, timeout: float = WAIT_TIMEOUT) -> Any:
        return wait_until(condition, timeout, what, spin=self.spin)

    def collect(self, msg_type: type, topic: str, qos: Any = None) -> list:
        """Every message received on `topic`, in arrival order (reliable, deep history by default)."""
        from rclpy.qos import QoSProfile

        received: list = []
        self.node.create_subscription(msg_type, topic, received.append, qos if qos is not None else QoSProfile(depth=10_000))
        return received

    def publisher(self, msg_type: type, topic: str, qos: Any = 10):
        return self.node.create_publisher(msg_type, topic, qos)

    def call(self, srv_type: type, name: str, request: Any = None, timeout: float = WAIT_TIMEOUT) -> Any:
        """Call a service and return its response.

        A client is made once per service and kept: each new one is a DDS endpoint to discover. A
        ready client (our request writer matched) does not mean the server has matched our
        response reader yet, and a response sent before that is lost for good (volatile
        durability), so a new client waits SERVICE_SETTLE before its first call, and requests
        that can be repeated without effect (SetBool, parameters) are sent again every
        RESEND_AFTER until answered."""
        client = self._clients.get(name)
        if client is None or not client.service_is_ready():
            client = client or self._clients.setdefault(name, self.node.create_client(srv_type, name))
            self.wait_for(client.service_is_ready, f"service {name}", timeout)
            settled = time.monotonic() + SERVICE_SETTLE
            self.wait_for(lambda: time.monotonic() > settled, f"service {name} to settle", timeout)
        request = request if request is not None else srv_type.Request()
        resend = srv_type.__name__ in IDEMPOTENT_SERVICES
        deadline = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            window = min(deadline, time.monotonic() + RESEND_AFTER) if resend else deadline
            try:
                wait_until(future.done, max(window - time.monotonic(), 0.0), f"a response from {name}", spin=self.spin)
                return future.result()
            except AssertionError:
                client.remove_pending_request(future)
                if not resend or time.monotonic() >= deadline:
                    raise AssertionError(f"timed out after {timeout:g} s waiting for a response from {name}") from None

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def join_domain(monkeypatch: pytest.MonkeyPatch, domain_id: int) -> None:
    """This process's environment set for `domain_id` (loopback discovery), undone by `monkeypatch`."""
    for key, value in ros_environment(domain_id).items():
        if os.environ.get(key) != value:
            monkeypatch.setenv(key, value)
    for key in ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER", "FASTRTPS_DEFAULT_PROFILES_FILE"):
        monkeypatch.delenv(key, raising=False)


@contextlib.contextmanager
def ros_client_on(domain_id: int) -> Iterator[RosClient]:
    """A RosClient on `domain_id` where the function fixtures do not reach (a module fixture), with
    this process's environment set for that domain while it lives."""
    with pytest.MonkeyPatch.context() as monkeypatch:
        join_domain(monkeypatch, domain_id)
        client = RosClient(domain_id)
        try:
            yield client
        finally:
            client.close()


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A DDS domain for this test alone; this process's environment is set for it too."""
    domain = allocate_domain_id()
    join_domain(monkeypatch, domain)
    return domain


@pytest.fixture
def launcher(ros_domain: int, tmp_path: Path) -> Iterator[Launcher]:
    launcher = Launcher(ros_environment(ros_domain), tmp_path)
    try:
        yield launcher
    finally:
        launcher.stop_all()


@pytest.fixture
def ros_client(ros_domain: int) -> Iterator[RosClient]:
    client = RosClient(ros_domain)
    try:
        yield client
    finally:
        client.close()
