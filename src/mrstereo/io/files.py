"""Safe file handling: protected inputs, atomic writes, staged output folders, temporaries, bounded YAML.

An :class:`Inputs` set holds what a command reads; :func:`check_outputs`, :func:`check_output_dir`
and every writer (:func:`atomic_write`, :func:`staged_dir`, :func:`staged_new_dir`,
:func:`replace_dir`) refuse to replace an input. Writes go to a temporary beside the target and are
renamed into place; only mrstereo's own temporaries (``.mrstereo-tmp-PID-XXXXXXXX.NAME``) are ever
removed; :func:`parse_yaml` counts every value, aliases expanded, up to ``MRSTEREO_MAX_YAML_NODES``.
The guarantees: docs/errors.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import secrets
import shutil
import signal
import threading
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from .. import _checks, _limits

__all__ = ["Inputs", "protecting_inputs", "note_read", "note_inputs", "atomic_write", "refuse_overwrite_input",
           "check_outputs", "check_output_dir", "staged_dir", "staged_new_dir", "replace_dir", "temporary_dir",
           "new_temporary_dir",
           "uninterruptible", "remove_stale_temporaries", "is_temporary", "no_space_error", "read_text", "parse_yaml",
           "read_yaml"]


# ------------------------------------------------------------------------------------------ inputs

def _resolved(path) -> str:
    return str(Path(path).resolve())


class Inputs:
    """Every file a command reads and every folder it reads as a whole.

    ``add`` files, ``add_folder`` folders no output may be written inside (a dataset, a ROS 2 bag).
    Paths are compared resolved, and an existing output also by inode (hard links, bind mounts).
    """

    def __init__(self, files: Iterable = (), folders: Iterable = (), *, kind: str = "input folder") -> None:
        self._files: dict[str, Path] = {}
        self._folders: dict[str, tuple[Path, str]] = {}
        self._inodes: dict[tuple[int, int], Path] | None = None
        self._outputs: set[str] = set()
        self._lock = threading.Lock()
        self.add(*files)
        self.add_folder(*folders, kind=kind)

    def add(self, *paths, resolved: bool = False) -> Inputs:
        """Add files (None entries are skipped); ``resolved``: the paths are absolute with symbolic links
        resolved already (``Path.resolve``), which saves a system call per file on large recordings."""
        with self._lock:
            for path in paths:
                if path is None:
                    continue
                key = str(path) if resolved else _resolved(path)
                if key not in self._files:
                    self._files[key] = Path(path)
                    if self._inodes is not None:
                        self._add_inode(key, Path(path))
        return self

    def add_folder(self, *folders, kind: str = "input folder") -> Inputs:
        """Add folders read as a whole; ``kind`` names them in messages (``"dataset"``, ``"bag"``)."""
        with self._lock:
            for folder in folders:
                if folder is not None:
                    self._folders.setdefault(_resolved(folder), (Path(folder), kind))
        return self

    def add_output(self, *paths) -> Inputs:
        """Register output folders checked by :func:`check_output_dir`: what the command reads back from them
        (a resumed run's own results) is no input."""
        with self._lock:
            self._outputs.update(_resolved(p) for p in paths if p is not None)
        return self

    def is_output(self, path) -> bool:
        """Whether ``path`` is, or lies inside, a registered output."""
        key = Path(_resolved(path))
        with self._lock:
            return any(str(p) in self._outputs for p in (key, *key.parents))

    def update(self, other: Inputs) -> Inputs:
        """Add everything of ``other``."""
        with other._lock:
            files = list(other._files.items())
        with self._lock:
            for key, path in files:
                if key not in self._files:
                    self._files[key] = path
                    if self._inodes is not None:
                        self._add_inode(key, path)
        for folder, kind in other._folders.values():
            self.add_folder(folder, kind=kind)
        return self

    @property
    def files(self) -> list[Path]:
        return list(self._files.values())

    @property
    def folders(self) -> list[Path]:
        return [folder for folder, _ in self._folders.values()]

    def _add_inode(self, key: str, path: Path) -> None:
        try:
            st = os.stat(key)
        except OSError:
            return
        self._inodes.setdefault((st.st_dev, st.st_ino), path)

    def conflict(self, path) -> tuple[str, str] | None:
        """Whether writing ``path`` would touch an input: ``("is", "the input X")``, ``("is", "the dataset
        D")`` (the folder itself), ``("inside", "the dataset D")``, or None."""
        path = Path(path)
        key = _resolved(path)
        with self._lock:
            if key in self._files:
                return "is", f"the input {self._files[key]}"
            try:
                st = os.stat(path)
            except OSError:
                st = None
            if st is not None and not os.path.isdir(path):
                if self._inodes is None:
                    self._inodes = {}
                    for k, p in self._files.items():
                        self._add_inode(k, p)
                if (st.st_dev, st.st_ino) in self._inodes:
                    return "is", f"the input {self._inodes[(st.st_dev, st.st_ino)]}"
            for parent in (Path(key), *Path(key).parents):
                if str(parent) in self._folders:
                    folder, kind = self._folders[str(parent)]
                    return ("is" if parent == Path(key) else "inside"), f"the {kind} {folder}"
        return None

    def inside(self, folder) -> list[tuple[Path, str]]:
        """Inputs (files and folders, with their kind) that lie inside ``folder``."""
        root = Path(_resolved(folder))
        with self._lock:
            found = [(p, "input") for k, p in self._files.items() if Path(k).is_relative_to(root)]
            found += [(p, kind) for k, (p, kind) in self._folders.items() if Path(k).is_relative_to(root)]
        return found

    def __len__(self) -> int:
        return len(self._files) + len(self._folders)


_active: list[Inputs] = []


@contextlib.contextmanager
def protecting_inputs(inputs: Inputs | None = None) -> Iterator[Inputs]:
    """Within the block, what mrstereo reads is an input and no writer of this module replaces one.

    The readers of :mod:`mrstereo.io` add what they read (:func:`note_read`); the output checks and
    writers refuse it. Yields the set (``inputs`` or a new one).
    """
    inputs = Inputs() if inputs is None else inputs
    _active.append(inputs)
    try:
        yield inputs
    finally:
        _active.remove(inputs)


def note_read(*paths, folder: bool = False, kind: str = "input folder") -> None:
    """Add files (or, with ``folder``, folders read as a whole) to the inputs of :func:`protecting_inputs`."""
    for inputs in _active:
        if folder:
            inputs.add_folder(*paths, kind=kind)
        else:
            inputs.add(*(p for p in paths if p is not None and not inputs.is_output(p)))


def note_inputs(inputs: Inputs) -> None:
    """Add a whole :class:`Inputs` set (a recording's files and folder) to those of :func:`protecting_inputs`."""
    for active in _active:
        active.update(inputs)


def _input_error(what: str, hit: tuple[str, str]) -> ValueError:
    relation, which = hit
    if relation == "is":
        return ValueError(f"{what} would overwrite {which}; choose another name")
    return ValueError(f"{what} lies inside {which}: outputs never go into an input; choose another folder")


def _refuse_input(what: str, path) -> None:
    for inputs in _active:
        hit = inputs.conflict(path)
        if hit is not None:
            raise _input_error(what, hit)


# ------------------------------------------------------------------------------------------ temporaries

_TEMP_PREFIX = ".mrstereo-tmp-"
_TEMP_NAME = re.compile(r"\A\.mrstereo-tmp-(\d+)-[0-9a-f]{8}\.")


def _temporary_name(name: str) -> str:
    """A name only mrstereo writes: ``.mrstereo-tmp-PID-XXXXXXXX.NAME`` (NAME keeps the target's suffix)."""
    return f"{_TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.{name or 'out'}"


def _create_temporary(folder: Path, name: str) -> Path:
    """A new empty file with a temporary name in ``folder`` (permissions as the umask says)."""
    while True:
        path = folder / _temporary_name(name)
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return path
        except FileExistsError:
            continue


def is_temporary(path) -> bool:
    """Whether ``path`` is named as mrstereo's temporaries are (:func:`atomic_write`, :func:`temporary_dir`)."""
    return _TEMP_NAME.match(Path(path).name) is not None


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _stale(path: Path) -> bool:
    match = _TEMP_NAME.match(path.name)
    return match is not None and not _pid_alive(int(match.group(1)))


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove what a killed mrstereo run left in ``folder``: its temporary files and folders, recognised by
    their marker (``.mrstereo-tmp-PID-XXXXXXXX.``) and a process id that no longer runs. Nothing else is
    touched. Returns what was removed."""
    folder = Path(folder)
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        item = Path(entry.path)
        if not _stale(item):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(item, ignore_errors=True)
        else:
            item.unlink(missing_ok=True)
        removed.append(item)
    return removed


# ------------------------------------------------------------------------------------------ atomic writes

@contextlib.contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary keeps the target's suffix (writers choose a format by it). Inside
    :func:`protecting_inputs` an input is never the target (``ValueError``); a full disk raises
    ``OSError(ENOSPC)`` naming ``path``.
    """
    path = Path(path)
    _refuse_input(f"the output {path}", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _create_temporary(path.parent, path.name)
    try:
        try:
            yield tmp
        except OSError as exc:
            error = no_space_error(exc, path, tmp)
            if error is exc:
                raise
            raise error from exc
        os.replace(tmp, path)
    finally:
        if tmp.exists() or tmp.is_symlink():
            tmp.unlink()


def no_space_error(exc: OSError, path: str | os.PathLike, written: str | os.PathLike | None = None) -> OSError:
    """``exc``, or ``OSError(ENOSPC, ..., path)`` when it comes from a full disk.

    Some writers report a full disk without errno (numpy: "28800 requested and 20976
    written"); then the free space of the file system of ``written`` (default ``path``)
    decides.
    """
    if not isinstance(exc, OSError):
        raise TypeError(f"exc must be an OSError, got {type(exc).__name__}")
    if exc.errno == errno.ENOSPC:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    if exc.errno is None and "requested and" in str(exc) and _disk_full(Path(written or path).parent):
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    return exc


def _disk_full(folder: Path, *, slack_bytes: int = 1 << 20) -> bool:
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < slack_bytes


@contextlib.contextmanager
def uninterruptible() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back while the block runs (a few renames); they take effect right after it.

    Python runs signal handlers in the main thread only, so from another thread the block runs as is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[tuple[int, object]] = []
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.signal(sig, lambda signum, frame: held.append((signum, frame))) for sig in signals}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        if held:
            signum, frame = held[0]
            handler = previous[signum]
            if callable(handler):
                handler(signum, frame)
            elif handler in (signal.SIG_DFL, None):
                os.kill(os.getpid(), signum)


def new_temporary_dir(folder: str | os.PathLike, *, prefix: str = "out") -> Path:
    """Create and return a fresh hidden folder ``.mrstereo-tmp-PID-XXXXXXXX.PREFIX`` inside ``folder`` (created);
    the caller removes it (:func:`temporary_dir` does both)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    while True:
        tmp = folder / _temporary_name(prefix)
        try:
            tmp.mkdir()
            return tmp
        except FileExistsError:
            continue


@contextlib.contextmanager
def temporary_dir(folder: str | os.PathLike, *, prefix: str = "out") -> Iterator[Path]:
    """A fresh hidden folder ``.mrstereo-tmp-PID-XXXXXXXX.PREFIX`` inside ``folder``, removed at the end
    whatever happens.

    On the same file system as ``folder`` (so it can be renamed into place); a full disk raises
    ``OSError(ENOSPC)`` naming ``folder``.
    """
    folder = Path(folder)
    tmp = new_temporary_dir(folder, prefix=prefix)
    try:
        try:
            yield tmp
        except OSError as exc:
            target = folder
            if exc.filename and Path(exc.filename).is_relative_to(tmp):     # name the file as it will be called
                target = folder / Path(exc.filename).relative_to(tmp)
            error = no_space_error(exc, target, tmp)
            if error is exc:
                raise
            raise error from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _move_all(source: Path, folder: Path) -> None:
    """Move every entry of ``source`` into ``folder`` (checked first, moved with interrupts held back)."""
    items = sorted(source.iterdir())
    for item in items:
        _refuse_input(f"the output {folder / item.name}", folder / item.name)
    with uninterruptible():
        for item in items:
            os.replace(item, folder / item.name)


@contextlib.contextmanager
def staged_dir(folder: str | os.PathLike, *, prefix: str = "out") -> Iterator[Path]:
    """Yield a fresh temporary folder inside ``folder``; on success move its files into ``folder``.

    A failure, a full disk or an interrupt leaves the previous set, never a mix: the moves are renames
    with SIGINT/SIGTERM held back (:func:`uninterruptible`). Stale temporaries are removed first.
    """
    folder = Path(folder)
    _refuse_input(f"the output folder {folder}", folder / ".")
    remove_stale_temporaries(folder)
    with temporary_dir(folder, prefix=prefix) as tmp:
        yield tmp
        _move_all(tmp, folder)


@contextlib.contextmanager
def staged_new_dir(folder: str | os.PathLike, *, option: str = "out_dir") -> Iterator[Path]:
    """Build a new folder: yield a temporary folder that becomes ``folder`` when the block succeeds.

    ``folder`` must not exist or be empty (:func:`check_output_dir`); an existing empty one (the
    working directory, a mount point) is kept and filled by renames.
    """
    folder = Path(folder).absolute()
    check_output_dir(option, folder, must_be_empty=True)
    if folder.is_dir():
        remove_stale_temporaries(folder)
        with temporary_dir(folder, prefix="new") as tmp:
            yield tmp
            _move_all(tmp, folder)
        return
    remove_stale_temporaries(folder.parent)
    with temporary_dir(folder.parent, prefix=folder.name) as tmp:
        yield tmp
        _refuse_input(f"the output folder {folder}", folder)
        os.rename(tmp, folder)


_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux ``renameat2(RENAME_EXCHANGE)``); False where it is not available."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
    at_fdcwd = -100
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EPERM):
        return False
    raise OSError(code, os.strerror(code), str(b))


def replace_dir(new: str | os.PathLike, target: str | os.PathLike) -> None:
    """Put the folder ``new`` in the place of ``target`` in one step; the old ``target`` is then removed.

    A reader sees the old folder or the new one, whole (``renameat2(RENAME_EXCHANGE)``, else two renames
    with signals held back). ``new`` must be on the same file system (a :func:`temporary_dir` beside ``target``).
    """
    new, target = Path(new), Path(target)
    _refuse_input(f"the output folder {target}", target)
    if not target.exists() and not target.is_symlink():
        os.rename(new, target)
        return
    if _exchange(new, target):
        shutil.rmtree(new, ignore_errors=True)
        return
    aside = new.with_name(new.name + ".old")
    with uninterruptible():
        os.replace(target, aside)
        os.replace(new, target)
    shutil.rmtree(aside, ignore_errors=True)


# ------------------------------------------------------------------------------------------ output checks

def refuse_overwrite_input(output: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Raise ``ValueError`` if ``output`` is the same file as one of ``inputs``."""
    check_outputs({str(output): output}, inputs)


def _check_parent_writable(option: str, path: Path) -> None:
    """The nearest existing ancestor of ``path`` must be a writable directory (the rest is created)."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{option}: cannot create {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: cannot write {path}: the folder {parent} is not writable")


def _all_inputs(inputs: Iterable, input_dirs: Iterable, input_kind: str) -> Inputs:
    """The inputs given, with those the running command has read (:func:`protecting_inputs`)."""
    given = inputs if isinstance(inputs, Inputs) else Inputs(inputs)
    merged = Inputs().update(given)
    merged.add_folder(*input_dirs, kind=input_kind)
    for active in _active:
        merged.update(active)
    return merged


def _suffix_error(option: str, allowed: tuple[str, ...], path: Path) -> ValueError:
    choices = f"{', '.join(allowed[:-1])}{' or ' if len(allowed) > 1 else ''}{allowed[-1]}"
    return ValueError(f"{option} must end in {choices}, got {path}")


def check_outputs(outputs: Mapping, inputs: Iterable[str | os.PathLike] | Inputs = (), *,
                  suffixes: Mapping[str, tuple[str, ...]] | None = None,
                  input_dirs: Iterable[str | os.PathLike] = (), input_kind: str = "input folder") -> None:
    """Check a command's output files before any work: raise ``ValueError`` naming the option.

    Parameters
    ----------
    outputs : mapping of str to path (or None)
        Each output file by the option (or description) that names it; None entries are skipped.
    inputs : iterable of path, or Inputs
        Every file the run reads (with those read so far inside :func:`protecting_inputs`). No output
        may be one of them (symbolic and hard links resolved) or lie inside an input folder.
    suffixes : mapping of str to tuple of str, optional
        Allowed suffixes (lower case, with the dot) per option.
    input_dirs : iterable of path
        Folders the run reads as a whole (a dataset, a bag, a scene), named ``input_kind``.
    input_kind : str
        What ``input_dirs`` are, for the message.

    Also: outputs differ from each other, an existing output is not a folder, and the folder it goes
    into exists (or can be created) and is writable.
    """
    items = [(option, Path(path)) for option, path in dict(outputs).items() if path is not None]
    protected = _all_inputs(inputs, input_dirs, input_kind)
    for option, path in items:
        what = option if str(path) in option else f"{option} {path}"
        allowed = (suffixes or {}).get(option)
        if allowed and path.suffix.lower() not in allowed:
            raise _suffix_error(option, tuple(allowed), path)
        if path.is_dir():
            raise ValueError(f"{what} is a folder; give a file name")
        _check_parent_writable(option, path)
        hit = protected.conflict(path)
        if hit is not None:
            raise _input_error(what, hit)
    for k, (option_a, a) in enumerate(items):
        for option_b, b in items[k + 1:]:
            if _resolved(a) == _resolved(b) or (a.exists() and b.exists() and os.path.samefile(a, b)):
                raise ValueError(f"{option_a} and {option_b} are the same file {a}; give two different names")


def check_output_dir(option: str, folder: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] | Inputs = (),
                     input_dirs: Iterable[str | os.PathLike] = (), must_be_empty: bool = False,
                     input_kind: str = "input folder", may_hold_inputs: bool = False) -> None:
    """Check an output folder before any work: raise ``ValueError`` naming ``option``.

    The folder must be creatable and writable, not be or lie inside an input folder (``input_dirs``,
    named ``input_kind``), not hold an input (unless ``may_hold_inputs``), and with ``must_be_empty``
    not exist or be empty (mrstereo temporaries do not count).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{option}: {folder} is a file, not a folder")
    if folder.is_dir():
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ValueError(f"{option}: the folder {folder} is not writable")
        if must_be_empty and any(not _stale(item) for item in folder.iterdir()):
            raise ValueError(f"{option}: {folder} already exists and is not empty; choose a new folder")
    else:
        _check_parent_writable(option, folder)
    protected = _all_inputs(inputs, input_dirs, input_kind)
    hit = protected.conflict(folder)
    if hit is not None:
        relation, which = hit
        raise ValueError(f"{option} {folder} {'is' if relation == 'is' else 'is inside'} {which}; choose a folder "
                         "apart from it")
    if not may_hold_inputs:
        held = protected.inside(folder)
        if held:
            path, kind = held[0]
            what = f"the {kind} {path}" if kind != "input" else f"the input {path}"
            raise ValueError(f"{option} {folder} holds {what}; choose a folder apart from it")
    for active in _active:
        active.add_output(folder)


# ------------------------------------------------------------------------------------------ text and YAML

def _existing(path: str | os.PathLike, what: str) -> Path:
    path = Path(path)
    if not path.is_file():
        if path.is_dir():
            raise ValueError(f"{what} {path} is a folder, not a file")
        raise FileNotFoundError(f"{what} not found: {path}")
    note_read(path)
    return path


def read_text(path: str | os.PathLike, what: str = "file", *, max_bytes: int | None = None) -> str:
    """Read a UTF-8 text file (an input: :func:`note_read`); a missing file, one that is not text or one
    larger than ``max_bytes`` raises an error naming it."""
    path = _existing(path, what)
    if max_bytes is not None and path.stat().st_size > max_bytes:
        raise ValueError(f"{what} {path} is {_checks.format_bytes(path.stat().st_size)}, more than the "
                         f"{_checks.format_bytes(max_bytes)} such a file may have")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {path} is not a text file (not UTF-8: byte 0x{exc.object[exc.start]:02x} at "
                         f"offset {exc.start})") from None


_YAML_BYTES_PER_NODE = 128      # a file larger than this times the node limit is refused unread


def parse_yaml(text: str, what: str, path, *, tags: Iterable[str] = (), max_nodes: int | None = None):
    """YAML ``text`` of the file ``path`` as Python data (the safe subset: mappings, lists, scalars).

    Built from the parser's events, without the intermediate node graph. Every value counts, aliases expanded; beyond
    ``max_nodes`` (default ``MRSTEREO_MAX_YAML_NODES``) the file is refused with the count reached, so an
    alias bomb ends after reading at most that many. ``tags`` are extra collection tags read as their
    plain mapping or list (OpenCV's ``tag:yaml.org,2002:opencv-matrix``). Invalid YAML, a tag that is not
    allowed and more than one document raise a ``ValueError`` naming the file (as ``what``) and the line.
    """
    import yaml

    from ._yaml import YamlLimit, build

    limit = _limits.limit("MRSTEREO_MAX_YAML_NODES") if max_nodes is None else int(max_nodes)
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)         # libyaml: 5x faster events
    try:
        return build(yaml.parse(text, Loader=loader), max_nodes=limit, tags=frozenset(tags))
    except YamlLimit as exc:
        raise ValueError(f"{what} {path}: {exc}; set MRSTEREO_MAX_YAML_NODES to raise the limit") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        line = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None)
        raise ValueError(f"{what} {path} is not valid YAML{line}" + (f": {problem}" if problem else "")) from None


def read_yaml(path: str | os.PathLike, what: str = "file", *, tags: Iterable[str] = (),
              max_nodes: int | None = None):
    """A UTF-8 YAML file as Python data; every failure names the file (:func:`read_text`, :func:`parse_yaml`)."""
    limit = _limits.limit("MRSTEREO_MAX_YAML_NODES") if max_nodes is None else int(max_nodes)
    text = read_text(path, what, max_bytes=max(1 << 20, limit * _YAML_BYTES_PER_NODE))
    return parse_yaml(text, what, path, tags=tags, max_nodes=limit)
