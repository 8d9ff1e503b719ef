"""Command-line interface: parse, validate, call one library function per command.

Every failure ends as one line on stderr, never a traceback: ``mrstereo: error: ...`` (exit 2) for
what the user can fix, ``mrstereo: interrupted`` (exit 130) for Ctrl-C or SIGTERM, ``mrstereo: error:
internal error ...`` (exit 1) for a bug (``MRSTEREO_DEBUG=1`` shows the traceback): docs/errors.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import errno
import os
import signal
import sys
import threading

from .._interrupt import reached

reached("import")

# Only the standard library here: the console script imports this module first, and
# entry() installs the interrupt handler before the commands (1.5 s of imports) load.
# The commands are registered in cli/_main.py.

DEBUG_ENV = "MRSTEREO_DEBUG"
EXIT_ERROR, EXIT_BUG, EXIT_INTERRUPTED = 2, 1, 130
_EXIT_GRACE_S = 3.0           # after an interrupt: time for clean-up before a hard exit
_ISSUES_URL = "https://github.com/mrstereo/mrstereo/issues"


def __getattr__(name: str):
    if name == "main":                       # the click group, loaded on first use
        from ._main import main
        return main
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _say(line: str) -> None:
    """Write one line to stderr (to the file descriptor if sys.stderr is gone)."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except Exception:
        try:
            os.write(2, (line + "\n").encode("utf-8", "replace"))
        except OSError:
            pass


class _Interrupts:
    """SIGINT / SIGTERM: one line, exit 130, whatever the program is doing.

    The first signal prints the line, silences stderr and raises KeyboardInterrupt in the main
    thread (``finally`` blocks clean up); a watchdog or a second signal exits at once.
    """

    def __init__(self) -> None:
        self.fired = False
        self._previous = {}
        self._stderr_fd = None

    def install(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return                      # signals can only be handled in the main thread
        try:
            self._stderr_fd = os.dup(2)     # the terminal, even while fd 2 is redirected (parallel.py)
        except OSError:
            self._stderr_fd = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handler)

    def linger(self) -> None:
        """After the command, while the interpreter shuts down (Dask threads, atexit): a signal
        still ends the process with one line and code 130, without unwinding anything."""
        if not self._previous:
            return
        for sig in self._previous:
            signal.signal(sig, self._late_handler)
        self._previous.clear()

    def _late_handler(self, signum, frame) -> None:
        self._say_interrupted()
        _hard_exit(EXIT_INTERRUPTED)

    def _say_interrupted(self) -> None:
        """The one line, on the terminal's stderr even while fd 2 is redirected."""
        if self._stderr_fd is not None:
            try:
                os.write(self._stderr_fd, b"mrstereo: interrupted\n")
            except OSError:
                pass
        else:
            _say("mrstereo: interrupted")

    def uninstall(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
        if self._stderr_fd is not None and not self.fired:
            os.close(self._stderr_fd)
            self._stderr_fd = None

    def _handler(self, signum, frame) -> None:
        if self.fired:
            _hard_exit(EXIT_INTERRUPTED)
        self.fired = True
        try:
            sys.stderr.flush()
        except Exception:
            pass
        self._say_interrupted()
        _silence_stderr()
        timer = threading.Timer(_EXIT_GRACE_S, _hard_exit, args=(EXIT_INTERRUPTED,))
        timer.daemon = True
        timer.start()
        raise KeyboardInterrupt


def _silence_stderr() -> None:
    """Send everything later written to stderr (tracebacks of dying threads, logging) to /dev/null."""
    import logging

    logging.disable(logging.CRITICAL)
    threading.excepthook = lambda args: None
    sys.unraisablehook = lambda args: None
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
    except OSError:
        pass


def _hard_exit(code: int) -> None:
    """End the process now: terminate child processes (Dask workers), skip the interpreter's clean-up."""
    try:
        import multiprocessing

        for child in multiprocessing.active_children():
            child.kill()
    except Exception:
        pass
    os._exit(code)


class _UsageError(Exception):
    """A click usage error, carried out of the click imports' scope."""


def _message(exc: BaseException) -> str:
    """One line for an error the user can fix."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return f"no space left on device: {exc.filename}" if exc.filename else "no space left on device"
    if isinstance(exc, UnicodeDecodeError):
        return f"a file is not UTF-8 text: {exc}"
    if isinstance(exc, MemoryError):
        return "out of memory" + (f": {exc}" if str(exc) else "")
    message = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in message:
        if isinstance(exc, FileNotFoundError):
            return f"file not found: {exc.filename}"
        return f"{exc.strerror or message}: {exc.filename}"
    return " ".join(message.split())        # one line


def entry(argv: list[str] | None = None) -> int:
    """Console-script entry point (also ``python -m mrstereo``): run the CLI, every failure one line.

    Without ``argv`` the process is mrstereo's own: once the command has finished (its outputs
    written, its clusters closed), the process ends here with the command's exit code, without
    the interpreter's teardown of numba, Dask and matplotlib -- during that teardown Python no
    longer handles signals, so a Ctrl-C there would end the process without the one line and code.
    """
    code = _run(argv)
    if argv is None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:
                pass
        _hard_exit(code)
    return code


def _run(argv: list[str] | None) -> int:
    debug = os.environ.get(DEBUG_ENV, "") not in ("", "0")
    interrupts = _Interrupts()
    interrupts.install()
    stdout = _QuietPipe.install()
    try:
        reached("start")
        import warnings

        import click

        from ..io import protecting_inputs, quiet_decoders
        from .._executor import keep_freed_memory
        from ._main import main

        keep_freed_memory()          # this process is ours: no page faults on every frame's arrays
        quiet_decoders()             # the command reports a bad image itself, in one line
        args = sys.argv[1:] if argv is None else list(argv)
        try:
            with main.make_context("mrstereo", args) as ctx, protecting_inputs(), warnings.catch_warnings():
                warnings.showwarning = _show_warning
                _shown_warnings.clear()
                main.invoke(ctx)
        except click.exceptions.Exit as exc:           # --help, --version
            return exc.exit_code
        except click.exceptions.Abort:
            raise KeyboardInterrupt from None
        except click.ClickException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":     # plain ``mrstereo``: the help, as --help
                click.echo(exc.format_message())
                return 0
            raise _UsageError(exc.format_message()) from None
    except BrokenPipeError:
        if stdout is not None and stdout.broken:
            return 0
        raise
    except KeyboardInterrupt:
        if not interrupts.fired:
            _say("mrstereo: interrupted")
        return _interrupted(interrupts)
    except (_UsageError, ValueError, TypeError, OSError, RuntimeError, MemoryError, LookupError) as exc:
        if debug:
            raise
        if interrupts.fired:                       # an error raised while unwinding after Ctrl-C
            return _interrupted(interrupts)
        _say(f"mrstereo: error: {_message(exc)}")
        return EXIT_ERROR
    except Exception as exc:
        if debug:
            raise
        if interrupts.fired:
            return _interrupted(interrupts)
        _say(f"mrstereo: error: internal error {type(exc).__name__}: {_message(exc)} -- please report it "
             f"at {_ISSUES_URL} (set {DEBUG_ENV}=1 to see the traceback)")
        return EXIT_BUG
    finally:
        if stdout is not None:
            stdout.uninstall()
        if argv is None and not interrupts.fired:
            interrupts.linger()         # the process is ours (console script, python -m): to its very end
        else:
            interrupts.uninstall()      # called from Python: leave its signal handlers as they were
    if interrupts.fired:                            # the interrupt was swallowed somewhere: still 130
        return _interrupted(interrupts)
    return 0


_shown_warnings: set[str] = set()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning of mrstereo as one line ``mrstereo: warning: ...``, each once (a recording read twice warns
    once); those of other packages are dropped."""
    if issubclass(category, UserWarning) and f"{os.sep}mrstereo{os.sep}" in str(filename):
        text = f"mrstereo: warning: {' '.join(str(message).split())}"
        if text not in _shown_warnings:
            _shown_warnings.add(text)
            _say(text)


class _QuietPipe:
    """stdout that goes quiet when its reader has gone (``mrstereo ... | head``): the command still
    writes its files and ends normally, its remaining lines are dropped, as command-line tools do."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self.broken = False

    @classmethod
    def install(cls):
        if isinstance(sys.stdout, cls) or sys.stdout is None:
            return None
        pipe = cls(sys.stdout)
        sys.stdout = pipe
        return pipe

    def uninstall(self) -> None:
        if sys.stdout is self:
            sys.stdout = self._stream

    def _quiet(self) -> None:
        if not self.broken:
            self.broken = True
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, self._stream.fileno())
                os.close(devnull)
            except (OSError, ValueError, AttributeError):
                pass

    def write(self, text):
        if self.broken:
            return len(text)
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._quiet()
            return len(text)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._quiet()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _interrupted(interrupts: _Interrupts) -> int:
    """After a signal: exit 130 now (the ``finally`` blocks have run; the interpreter's own shutdown
    would wait for a Dask cluster's threads and print their complaints)."""
    if interrupts.fired:
        try:
            sys.stdout.flush()
        except Exception:
            pass
        _hard_exit(EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(entry())
