"""Every command of README.md's ```sh blocks runs, as written, in one scripted first hour.

The commands are read from the README, not listed here: `readme_commands` enumerates the
blocks, the scenario runs each command through `_Run.start` / `_Run.check` by its exact README
text (a bounded variant where the command would run until Ctrl-C: the same command plus
``--duration``, ``--timeout``, or SIGINT once it has shown it works), and the test fails when
a README command was not run (`EXEMPT` names the exceptions and why). Everything runs in a
private folder on a private Zenoh router; the firmware emulator on a pseudo-terminal stands
in for ``/dev/ttyUSB0`` and fakenect, replaying a dump written here, for the Kinect.

Root-only steps (``sudo apt-get``, the udev rule and ``udevadm``, ``usermod``) are written
outside ```sh blocks on purpose: they change the machine, not the stack.

The commands share what a user would share: one ``eddie sim`` for the tour, with SLAM, the
map, navigation and the ROS 2-style tools attached to it; the offline commands (dataset
replays, exploration in its own process) and the real-robot steps run beside it.
"""

from __future__ import annotations

import re
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent / "transport"))
from _procs import Proc, free_port, private_router

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: where the README's dataset paths (``../shared/datasets/...``) point from a clone
SHARED = ROOT.parent / "shared"
EDDIE = [sys.executable, "-m", "eddiebot.cli.main"]

#: README commands this test does not run, and why.
EXEMPT = {
    "make demo": "the demo has its own checks (tests/demo, `eddie demo` exit status)",
    "make test": "runs the whole suite, this test included",
    "make bench": "benchmarks are measured, not tested (docs/benchmarks.md)",
}

_SH_BLOCK = re.compile(r"^[ \t]*```sh\n(.*?)^[ \t]*```", re.S | re.M)


def readme_commands(text: str) -> list[str]:
    """The commands of every ```sh block of ``text``, in order: one per line, comments
    (``#`` at a line's start or after two spaces) and blank lines dropped."""
    out = []
    for block in _SH_BLOCK.findall(text):
        for line in block.splitlines():
            command = re.split(r"(?:^|\s{2,})#", line, maxsplit=1)[0].strip()
            if command:
                out.append(command)
    return out


def test_readme_commands_are_read_from_its_sh_blocks() -> None:
    text = ("intro\n```sh\neddie sim --world office   # terminal 1\n# a comment\n\n"
            "eddie topic pub --once /chatter std_msgs/msg/String \"{data: hi}\"\n```\n"
            "```\nnot a shell block\n```\n```sh\nmake demo\n```\n")
    assert readme_commands(text) == [
        "eddie sim --world office",
        "eddie topic pub --once /chatter std_msgs/msg/String \"{data: hi}\"",
        "make demo"]
    commands = readme_commands(README.read_text())
    assert len(commands) >= 40 and "eddie sim --world office --dashboard" in commands


# -- running README commands ---------------------------------------------------------------
def _stacks(proc: Proc) -> str:
    """Kill ``proc``; if it was still running, the Python stacks of its threads (it runs with
    PYTHONFAULTHANDLER, which prints them on SIGABRT) — what a stalled command waited for."""
    if proc.popen.poll() is not None:
        return ""
    before = len(proc.stderr)
    proc.popen.send_signal(signal.SIGABRT)
    try:
        proc.popen.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.popen.kill()
    time.sleep(0.5)  # the pump thread reads the rest
    return "\nits threads when it was stopped:\n" + proc.stderr[before:][-12000:]


class _Run:
    """Runs README commands by their exact text in ``cwd`` on the router of ``env``."""

    def __init__(self, commands: list[str], cwd: Path, env: dict[str, str]) -> None:
        self.commands = set(commands)
        self.cwd = cwd
        self.env = env
        self.home = Path(env["HOME"])
        self.ran: set[str] = set()
        self.substitutions: dict[str, str] = {}
        self.procs: list[Proc] = []
        self._lock = threading.Lock()

    def _argv(self, command: str, extra: list[str]) -> tuple[list[str], dict[str, str]]:
        assert command in self.commands, f"not a README command: {command!r}"
        with self._lock:
            self.ran.add(command)
        words = shlex.split(command)
        env = dict(self.env)
        while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=.*", words[0]):
            name, _, value = words.pop(0).partition("=")
            env[name] = value
        assert words[0] == "eddie" and not {"|", "&&", ";", ">"} & set(words), command
        words = [self.substitutions.get(w, w) for w in words]
        for old, new in self.substitutions.items():
            words = [w.replace(old, new) if w.startswith("port:=") else w for w in words]
        return [*EDDIE, *words[1:], *extra], env

    def check(self, command: str, *extra: str, timeout: float = 60.0,
              expect: str | None = None, code: int | None = 0) -> str:
        """Run ``command`` (plus ``extra``) to its end; its stdout. It must exit with
        ``code`` (None: any) and print ``expect`` (on stdout or stderr)."""
        argv, env = self._argv(command, list(extra))
        t0 = time.monotonic()
        run = subprocess.run(argv, cwd=self.cwd, env=env, capture_output=True, text=True,
                             timeout=timeout, stdin=subprocess.DEVNULL)
        print(f"{time.monotonic() - t0:5.1f} s  {command}")  # shown with pytest -s
        assert code is None or run.returncode == code, f"{command}: exit {run.returncode}\n{run.stderr[-3000:]}"
        if expect is not None:
            assert expect in run.stdout + run.stderr, f"{command}: no {expect!r} in\n" \
                                                      f"{run.stdout[-2000:]}{run.stderr[-2000:]}"
        return run.stdout

    def start(self, command: str, *extra: str, ready: str, timeout: float = 60.0) -> Proc:
        """Start ``command`` (a long-running one) and wait until it prints ``ready``."""
        argv, env = self._argv(command, list(extra))
        # sh cds and execs: signals reach eddie itself
        proc = Proc(["/bin/sh", "-c", 'cd "$0" && exec "$@"', str(self.cwd), *argv], env)
        with self._lock:
            self.procs.append(proc)
        deadline = time.monotonic() + timeout
        while not any(ready in line for line in proc.lines) and ready not in proc.stderr:
            if proc.popen.poll() is not None or time.monotonic() > deadline:
                stacks = _stacks(proc)
                pytest.fail(f"{command}: no {ready!r} (exit {proc.popen.poll()})\n"
                            + "\n".join(proc.lines[-30:]) + f"\n{proc.stderr[-3000:]}{stacks}")
            time.sleep(0.05)
        print(f"{time.monotonic() - deadline + timeout:5.1f} s  {command} (started)")
        return proc

    def stop(self, proc: Proc, code: int | None = 0) -> str:
        """Ctrl-C ``proc``; its stdout. It must exit with ``code`` (None: any)."""
        proc.popen.send_signal(signal.SIGINT)
        got = proc.finish(timeout=30)
        if code is not None:
            assert got == code, f"{proc.popen.args}: exit {got}\n{proc.stderr[-3000:]}"
        return "\n".join(proc.lines)

    def kill_all(self) -> None:
        for proc in self.procs:
            if proc.popen.poll() is None:
                proc.popen.kill()
                proc.popen.wait(timeout=10)


def _fakenect_dump(path: Path, frames: int = 10) -> None:
    """A fakenect dump as ``fakenect-record`` writes it: INDEX.txt naming
    ``<r|d|a>-<time>-<timestamp>.<ppm|pgm|dump>`` files (RGB, raw disparity, tilt state)."""
    import numpy as np

    path.mkdir()
    names = []
    t = 1_700_000_000.0
    for i in range(frames):
        t += 1 / 30
        rgb = np.full((480, 640, 3), 20 * i + 20, np.uint8).tobytes()
        disparity = np.full((480, 640), 700 + i, "<u2").tobytes()
        for kind, ext, payload in (
                ("a", "dump", struct.pack("<hhhbxi", 0, 819, 0, 0, 0)),
                ("r", "ppm", b"P6 640 480 255\n" + rgb),
                ("d", "pgm", b"P5 640 480 65535\n" + disparity)):
            name = f"{kind}-{t:f}-{1000 * (i + 1)}.{ext}"
            (path / name).write_bytes(payload)
            names.append(name)
    (path / "INDEX.txt").write_text("\n".join(names) + "\n")


# -- the scenario --------------------------------------------------------------------------
def _tour(run: _Run) -> None:
    """The tour, the ROS 2-style tools and the map → navigate story on one simulator."""
    port = free_port()
    sim = run.start("eddie sim --world office --dashboard", "--dashboard-port", str(port),
                    ready="board on emulator")
    assert f"http://127.0.0.1:{port}/" in sim.lines
    # an idle teleop window stays open through navigation
    teleop = run.start("eddie teleop", ready="Reading from the keyboard")
    slam = run.start("eddie slam", ready="slam in mapping mode")
    assert "attached to the simulator on ROS_DOMAIN_ID 0" in slam.lines[0]
    chatter = run.start("eddie topic echo /chatter", ready="")
    tools = ThreadPoolExecutor(2)
    jobs = [tools.submit(f) for f in (
        lambda: run.check("eddie topic list -t", expect="/scan [sensor_msgs/msg/LaserScan]"),
        lambda: run.check("eddie topic echo --once /odom", expect="child_frame_id: base_footprint"),
        lambda: run.check("eddie topic hz /scan", "--duration", "2", expect="average rate"),
        lambda: run.check("eddie topic type /scan", expect="sensor_msgs/msg/LaserScan"),
        lambda: run.check("eddie topic bw /depth/image_raw", "--duration", "2", expect="B/s"),
        lambda: run.check("eddie node list", expect="/slam_toolbox"),
        lambda: run.check("eddie param get /eddie poll_rate", expect="value is"),
        lambda: run.check("eddie param describe /eddie port", expect="Read only: true"),
        lambda: run.check("eddie service call /reset_encoder "
                          "eddiebot_msgs/srv/ResetEncoder \"{}\"", expect="response"),
        lambda: run.check("eddie topic pub --once /chatter std_msgs/msg/String \"{data: hi}\""),
    )]
    # the recorder starts once the tools above are done (topics are taken in name order,
    # /tf_static last)
    for job in jobs:
        job.exception()  # waits
    record = run.start("eddie record -o run1 -a", ready="recording /tf_static", timeout=120.0)
    time.sleep(2.0)  # everything for a while (the Kinect's images: 46 MB/s), SLAM's first scans
    assert "recorded" in run.stop(record)
    run.check("eddie map save office", expect="map saved to")
    doc = yaml.safe_load((run.cwd / "office.yaml").read_text())
    assert doc["free_thresh"] == pytest.approx(0.196) and len(doc["map_to_odom"]) == 3
    failed = [str(error) for job in jobs if (error := job.exception()) is not None]
    assert not failed, "\n".join(failed)
    out = run.stop(slam)
    assert "saved the session and the map to out/slam/" in out
    assert chatter.wait_for("data: hi", timeout=10)
    talker = run.start("eddie topic pub --rate 1 /chatter std_msgs/msg/String \"{data: hello}\"",
                       ready="")
    assert chatter.wait_for("data: hello", timeout=10)
    run.stop(talker, code=None)
    nav = run.start("eddie nav --map office.yaml",
                    ready="[lifecycle_manager_navigation]: Managed nodes are active")
    assert any(line.startswith("starting localised at") for line in nav.lines), nav.lines
    run.check("eddie lifecycle get /planner_server", expect="active [3]")
    run.check("eddie action info /navigate_to_pose", expect="Action servers: 1")
    # AMCL's first estimate comes with its first map -> odom (a goal before it: TF_ERROR)
    pose = subprocess.run([*EDDIE, "topic", "echo", "--once", "/amcl_pose", "--timeout", "30",
                           "--qos-durability", "transient_local"],
                          env=run.env, capture_output=True, text=True, timeout=60)
    assert "frame_id: map" in pose.stdout, pose.stderr
    # the office's walking person comes down the corridor towards the robot: standing by the
    # goal it makes the goal occupied (GOAL_OCCUPIED, 206, Nav2's answer); as an operator
    # would, wait for them to walk on and send the goal again
    argv, env = run._argv("eddie goal 2.0 0.0 0.0", ["--timeout", "300"])
    for _ in range(3):
        goal = subprocess.run(argv, cwd=run.cwd, env=env, capture_output=True, text=True,
                              timeout=330, stdin=subprocess.DEVNULL)
        if goal.returncode == 0 and "Goal reached." in goal.stdout:
            break
        assert "GOAL_OCCUPIED" in goal.stderr, f"eddie goal: exit {goal.returncode}\n{goal.stderr[-3000:]}"
        time.sleep(5.0)
    else:
        raise AssertionError("eddie goal 2.0 0.0 0.0: the goal stayed occupied for three tries")
    run.check("eddie action send_goal /navigate_to_pose nav2_msgs/action/NavigateToPose "
              "\"{pose: {header: {frame_id: map}, pose: {position: {x: 2.0}}}}\"",
              "--timeout", "60", expect="SUCCEEDED")
    (run.cwd / "tour.yaml").write_text("- {x: 2.5, y: 0.0}\n- {x: 3.0, y: 0.0}\n")
    # bounded: following has begun (the robot is already at the goal above, 0.5 m short)
    run.check("eddie waypoints tour.yaml", "--timeout", "10", code=None,
              expect="waypoint 1/2: (2.5, 0)")
    run.stop(nav)
    vslam = run.start("eddie vslam", ready="rtabmap in mapping mode")
    assert vslam.wait_for("attached to the simulator on ROS_DOMAIN_ID 0")
    time.sleep(2.0)  # a few Kinect frames
    run.stop(vslam, code=None)
    assert (run.home / ".local/share/eddiebot/rtabmap.db").is_file()
    run.stop(teleop, code=None)
    run.stop(chatter, code=None)
    assert sim.popen.poll() is None  # every tool stopped, the simulator runs on
    run.stop(sim, code=None)


def _bag(run: _Run) -> None:
    """The bag recorded during the tour: played on a graph of its own, read, drawn, mapped."""
    run.check("eddie bag info run1", expect="/scan")
    run.check("eddie play run1 --rate 2", expect="")
    run.check("eddie view run1 -o run1.png")
    assert (run.cwd / "run1.png").stat().st_size > 1000
    run.check("eddie slam replay run1 --scan-topic /scan -o out/run1")
    assert (run.cwd / "out/run1/map.yaml").is_file()


def _offline(run: _Run) -> None:
    """Commands that need no running robot."""
    run.check("eddie world list", expect="warehouse")
    run.check("eddie interface show eddiebot_msgs/msg/Encoders", expect="int32 left")
    run.check("eddie posegraph optimize ../shared/datasets/slam2d/intel/intel.g2o",
              expect="1728 poses")
    run.check("eddie slam replay ../shared/datasets/slam2d/mit-csail/mit-csail.clf "
              "-o out/csail", expect="loops closed")
    run.check("eddie explore --world office -o out/explore", "--time-limit", "5",
              expect="out/explore/map.yaml")


def _robot(run: _Run, dump: Path) -> None:
    """The real-robot steps: the emulator on a pty as /dev/ttyUSB0, fakenect as the Kinect."""
    from eddiebot.robot.constants import FIRMWARE_PROFILES
    from eddiebot.robot.emulator import FirmwareEmulator
    from eddiebot.robot.pty_server import PtyServer

    server = PtyServer(FirmwareEmulator(FIRMWARE_PROFILES["1.1"]))
    serving = threading.Thread(target=server.serve_forever, daemon=True)
    serving.start()
    run.substitutions["/dev/ttyUSB0"] = server.device_path
    try:
        bringup = run.start("eddie launch bringup port:=/dev/ttyUSB0",
                            ready=f"board on {server.device_path}")
        lib = run.cwd / "libfreenect-fakenect.so"
        shutil.copyfile(_fakenect_library(), lib)
        run.env = {**run.env, "EDDIE_FREENECT_LIBRARY": str(lib), "FAKENECT_PATH": str(dump)}
        kinect = run.start("eddie run eddiebot.robot.kinect -p depth_registration:=true",
                           ready="")
        info = subprocess.run([*EDDIE, "topic", "echo", "--once", "/depth/camera_info",
                               "--field", "height", "--timeout", "30"], env=run.env,
                              capture_output=True, text=True, timeout=60)
        assert info.stdout.split()[:1] == ["480"], info.stdout + info.stderr
        run.stop(kinect, code=None)
        # mapping with the robot: the Kinect's depth as the scan, SLAM attached to /odom
        kinect = run.start("eddie run eddiebot.robot.kinect", ready="")
        scan = run.start("eddie run eddiebot.perception.depth_to_scan "
                         "-p output_frame:=camera_depth_frame", ready="")
        slam = run.start("eddie slam", ready="slam in mapping mode")
        assert slam.lines[0].startswith("attached to the robot on ROS_DOMAIN_ID 5"), slam.lines
        run.check("eddie teleop", expect="Reading from the keyboard")  # stdin closed: it ends
        for proc in (slam, scan, kinect, bringup):
            run.stop(proc, code=None)
    finally:
        server.stop()
        serving.join(timeout=10)


def _two_stacks(run: _Run) -> None:
    """A second graph beside the tour's: its own simulator, SLAM attached to that one."""
    sim = run.start("ROS_DOMAIN_ID=1 eddie sim --world warehouse --camera 320x240@10",
                    ready="board on emulator")
    slam = run.start("ROS_DOMAIN_ID=1 eddie slam", ready="slam in mapping mode")
    assert "attached to the simulator on ROS_DOMAIN_ID 1" in slam.lines[0]
    run.check("ROS_DOMAIN_ID=1 eddie topic echo --once /odom", expect="frame_id: odom")
    run.stop(slam)
    run.stop(sim, code=None)


def _fakenect_library() -> Path:
    import glob

    found = sorted(glob.glob("/usr/lib/*/fakenect/libfreenect.so*")
                   + glob.glob("/usr/lib/fakenect/libfreenect.so*")
                   + glob.glob("/usr/local/lib/fakenect/libfreenect.so*"))
    if not found:
        pytest.skip("fakenect not installed: apt-get install libfreenect-dev libfreenect-bin")
    return Path(found[0])


def test_every_readme_command_runs(tmp_path: Path) -> None:
    commands = readme_commands(README.read_text())
    _fakenect_library()
    if not (SHARED / "datasets").is_dir():
        pytest.skip(f"the README's datasets are not at {SHARED / 'datasets'}")
    clone = tmp_path / "eddiebot"
    clone.mkdir()
    (tmp_path / "shared").symlink_to(SHARED)
    dump = tmp_path / "kinect-dump"
    _fakenect_dump(dump)
    with private_router() as env:
        # the user's home is the test's: the vSLAM database, the calibration file
        (tmp_path / "home").mkdir()
        # a command stopped for hanging prints its threads' stacks (SIGABRT, see _stacks)
        env = {**env, "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1",
               "HOME": str(tmp_path / "home")}
        env.pop("ROS_DOMAIN_ID", None)
        run = _Run(commands, clone, env)
        (clone / "robot").mkdir()
        robot = _Run(commands, clone / "robot", {**env, "ROS_DOMAIN_ID": "5"})
        try:
            # the tour (a simulator, SLAM, navigation with a goal to reach) runs alone: beside
            # the other jobs on a 2-core machine its robot pose went stale and the goal aborted
            _tour(run)
            with ThreadPoolExecutor(3) as pool:
                side: list[Future[None]] = [pool.submit(_offline, run),
                                            pool.submit(_robot, robot, dump),
                                            pool.submit(_two_stacks, run)]
                _bag_on_its_own_graph(run)
                for job in side:
                    job.result()
        finally:
            run.kill_all()
            robot.kill_all()
    missing = [c for c in commands if c not in run.ran | robot.ran and c not in EXEMPT]
    assert not missing, f"README commands this test does not run: {missing}"


def _bag_on_its_own_graph(run: _Run) -> None:
    bag = _Run(sorted(run.commands), run.cwd, {**run.env, "ROS_DOMAIN_ID": "7"})
    _bag(bag)
    run.ran |= bag.ran

