"""``eddie``: the command-line front door, in the ros2 CLI's habits.

Each sub-command lives in ``eddiebot.cli.<module>`` and exposes
``add_arguments(parser)`` and ``run(args) -> int``; modules are imported only when their
command runs, so ``eddie --help`` is instant.

How every command ends, decided here once:

- a typed error — any exception of a class defined in a package's ``errors`` module
  (``eddiebot.sim.errors.UnknownWorldError``, ``eddiebot.core.launch.LaunchError``'s base,
  ``eddiebot.cli.errors.ParamsFileError``, ...), an ``OSError`` (a busy port, a missing
  file) or a YAML syntax error — prints one line ``eddie: error: <message>`` on stderr and
  exits 2 (``--log-level debug`` shows the traceback instead);
- Ctrl-C exits 130, quietly;
- stdout closed by its reader (``eddie topic echo /scan | head -3``) exits 141 (128 +
  SIGPIPE, as a program killed by SIGPIPE), quietly, also when the write happened in a
  subscription callback;
- run as the program, a Zenoh session still closing (a peer that does not answer) gets at
  most ``EDDIE_ZENOH_CLOSE_TIMEOUT`` (0.5 s) and is then left behind; once Zenoh's native
  library is loaded the process always ends with ``os._exit`` (see
  `_exit_without_waiting_for_zenoh`).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any, TextIO

#: Exit statuses: a fatal start-up error, Ctrl-C, stdout closed by its reader.
EXIT_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_CLOSED_PIPE = 141

#: (command, module, one-line help) — the explicit registry of sub-commands.
COMMANDS: list[tuple[str, str, str]] = [
    ("demo", "eddiebot.cli.demo", "run the main job in the simulator and write a report under out/demo/"),
    ("launch", "eddiebot.cli.launch", "run a YAML launch file (eddie launch bringup port:=/dev/ttyUSB0)"),
    ("run", "eddiebot.cli.run", "run one registered node (eddie run eddiebot.base.odometry)"),
    ("sim", "eddiebot.cli.sim", "start the simulator with the bring-up stack"),
    ("teleop", "eddiebot.cli.teleop", "drive with the keyboard (teleop_twist_keyboard keys)"),
    ("slam", "eddiebot.cli.slam", "2D SLAM: live in the simulator, or replay a log"),
    ("explore", "eddiebot.cli.explore", "explore and map a world by itself, then come home"),
    ("map", "eddiebot.cli.map", "save or show maps"),
    ("nav", "eddiebot.cli.nav", "navigation in a saved map (simulator or robot)"),
    ("goal", "eddiebot.cli.goal", "send a navigation goal X Y YAW"),
    ("waypoints", "eddiebot.cli.waypoints", "follow waypoints from a file"),
    ("vslam", "eddiebot.cli.vslam", "RGB-D SLAM: live, replay, loops, database tools"),
    ("posegraph", "eddiebot.cli.posegraph", "pose-graph tools (optimize g2o/TORO files)"),
    ("world", "eddiebot.cli.world", "list simulator worlds and render their previews"),
    ("emulator", "eddiebot.cli.emulator", "serve the Eddie firmware emulator on a pty"),
    ("board", "eddiebot.cli.board", "send a raw firmware command to the board (eddie board VER)"),
    ("calibrate", "eddiebot.cli.calibrate", "UMBmark calibration of track width and wheel radius"),
    ("topic", "eddiebot.cli.topic", "list|echo|hz|bw|info|type|find|pub topics"),
    ("node", "eddiebot.cli.node_cmd", "list nodes"),
    ("param", "eddiebot.cli.param", "list|get|set|describe|delete|dump|load parameters"),
    ("service", "eddiebot.cli.service", "list|type|find|call services"),
    ("lifecycle", "eddiebot.cli.lifecycle", "nodes|get|list|set lifecycle nodes"),
    ("action", "eddiebot.cli.action", "list|info|send_goal actions"),
    ("interface", "eddiebot.cli.interface", "show message, service and action definitions"),
    ("record", "eddiebot.cli.record", "record topics to a rosbag2 (MCAP)"),
    ("play", "eddiebot.cli.play", "play a rosbag2 with its original timing"),
    ("bag", "eddiebot.cli.bag", "bag info"),
    ("daemon", "eddiebot.cli.daemon", "run the Zenoh router other processes meet at"),
    ("bridge", "eddiebot.cli.bridge", "mirror topics to and from ROS 2 on DDS (eddie bridge dds)"),
    ("dashboard", "eddiebot.cli.dashboard", "web dashboard: map, robot, scan, camera, teleop"),
    ("foxglove", "eddiebot.cli.foxglove", "Foxglove WebSocket bridge"),
    ("view", "eddiebot.cli.view", "render a map, bag or trajectory to PNG"),
]


def _available() -> list[tuple[str, str, str]]:
    """Registered commands whose module is installed."""
    import importlib.util

    return [c for c in COMMANDS if importlib.util.find_spec(c[1]) is not None]


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    parser = argparse.ArgumentParser(
        prog="eddie",
        description="eddiebot: bring up, drive, map and navigate a Parallax Eddie "
        "(or any differential-drive robot with an RGB-D camera), in ROS 2's formats.",
    )
    parser.add_argument("--log-level", default=os.environ.get("EDDIE_LOG_LEVEL", "info"),
                        choices=["debug", "info", "warn", "error"], help="logging level")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers = {}
    for name, module, help_text in _available():
        subparsers[name] = sub.add_parser(name, help=help_text, description=help_text)
        subparsers[name].set_defaults(_module=module)
    return parser, subparsers


def configure_logging(level: str) -> None:
    levels = {"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING,
              "error": logging.ERROR}
    logging.basicConfig(
        level=levels[level],
        format="[%(levelname)s] [%(asctime)s] [%(name)s]: %(message)s",
        stream=sys.stderr,
    )


def _parse_and_run(argv: Sequence[str] | None) -> int:
    """Run the chosen command; its exit status (2 with one line for a typed error)."""
    parser, subparsers = build_parser()
    args_list = list(sys.argv[1:] if argv is None else argv)
    # Only the chosen command's module is imported to add its arguments.
    chosen = None
    skip = False
    for a in args_list:
        if skip:
            skip = False
        elif a == "--log-level":
            skip = True  # its value is not the command
        elif not a.startswith("-"):
            chosen = a
            break
    if chosen in subparsers:
        module = importlib.import_module(subparsers[chosen].get_default("_module"))
        module.add_arguments(subparsers[chosen])
    args = parser.parse_args(args_list)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    configure_logging(args.log_level)
    module = importlib.import_module(args._module)
    try:
        return int(module.run(args) or 0)
    except BrokenPipeError:
        raise  # stdout's reader went away: not an error of the command
    except Exception as exc:
        message = fatal_message(exc)
        if message is None or args.log_level == "debug":
            raise
        print(f"eddie: error: {message}", file=sys.stderr, flush=True)
        return EXIT_ERROR


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``eddie`` with ``argv`` (default: the command line) and return the exit status.

    Called without ``argv`` (as the program) it may end the process itself: see the
    module docstring about Zenoh sessions still closing.
    """
    as_program = argv is None
    interrupted = _InterruptFlag(install=as_program)
    if as_program:
        os.environ.setdefault("EDDIE_ZENOH_CLOSE_TIMEOUT", "0.5")
    stdout = sys.stdout
    sys.stdout = _GuardedStdout(stdout)  # type: ignore[assignment]
    try:
        code = _parse_and_run(argv)
    except (_StdoutClosed, BrokenPipeError):
        code = _stdout_closed(stdout)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except BaseException:
        if not interrupted.seen:
            raise
        # Ctrl-C inside C code often surfaces as another error (an import that failed)
        code = EXIT_INTERRUPTED
    finally:
        sys.stdout = stdout
        interrupted.restore()
    if as_program:
        _exit_without_waiting_for_zenoh(code)
    return code


def fatal_message(exc: BaseException) -> str | None:
    """The one line ``eddie: error:`` prints for ``exc``, or None if it is a bug (a
    traceback then says where)."""
    if _is_typed(exc):
        text = str(exc) or type(exc).__name__
    elif isinstance(exc, OSError):
        text = _os_error_text(exc)
    elif _is_yaml_error(exc):
        text = f"malformed YAML: {exc}"
    else:
        return None
    return " ".join(text.split())


def _is_typed(exc: BaseException) -> bool:
    """An exception of a class from an ``eddiebot.<package>.errors`` module (or a subclass)."""
    for cls in type(exc).__mro__:
        module = cls.__module__
        if module.startswith("eddiebot.") and module.rsplit(".", 1)[-1] == "errors":
            return True
    return False


def _os_error_text(exc: OSError) -> str:
    if exc.strerror and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror}"
    return exc.strerror or str(exc) or type(exc).__name__


def _is_yaml_error(exc: BaseException) -> bool:
    yaml = sys.modules.get("yaml")
    return yaml is not None and isinstance(exc, yaml.YAMLError)


class _InterruptFlag:
    """Python's SIGINT handler, remembering that it ran."""

    def __init__(self, *, install: bool) -> None:
        self.seen = False
        self._previous: Any = None
        if install and threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum: int, frame: Any) -> None:
        self.seen = True
        raise KeyboardInterrupt

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


class _StdoutClosed(BaseException):
    """stdout's reader went away. A BaseException, as KeyboardInterrupt, so that no
    ``except Exception`` around a callback logs it and carries on printing."""


class _GuardedStdout:
    """sys.stdout, except that a write to a closed pipe from the main thread raises
    `_StdoutClosed`."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def _guard(self, exc: BrokenPipeError) -> BaseException:
        if threading.current_thread() is threading.main_thread():
            return _StdoutClosed()
        return exc

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError as exc:
            raise self._guard(exc) from None

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError as exc:
            raise self._guard(exc) from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _stdout_closed(stdout: TextIO) -> int:
    """Point stdout at /dev/null so that the interpreter's last flush does not fail again
    (the recipe of Python's ``signal`` documentation)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # not a file (a capture): leave it
        pass
    return EXIT_CLOSED_PIPE


def _exit_without_waiting_for_zenoh(code: int) -> None:
    """Exit now, without the interpreter's shutdown, once Zenoh's native library is loaded.

    A session opening or closing in a helper thread would hang the exit; and any thread
    that comes back from Zenoh into Python while the interpreter shuts down (a session
    open that finished just after Ctrl-C, a subscription callback) is ended by a forced
    unwind that Zenoh's Rust frames turn into an abort ("FATAL: exception not rethrown",
    SIGABRT). Every command has closed its own files by the time it returns here.
    """
    if "zenoh" not in sys.modules:
        return
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
