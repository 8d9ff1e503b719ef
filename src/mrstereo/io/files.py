"""Safe file handling: atomic writes, staged output folders, input protection, text and YAML.

Every writer goes through :func:`atomic_write`: the data is written to a
temporary file beside the target and renamed into place, so a crash never
leaves a half-written output, and :func:`refuse_overwrite_input` keeps an
output from replacing one of the inputs. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

__all__ = ["atomic_write", "refuse_overwrite_input", "check_outputs", "check_output_dir", "staged_dir",
           "temporary_dir", "remove_stale_temporaries", "no_space_error", "read_text", "parse_yaml", "read_yaml"]



@contextlib.contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file keeps the target's suffix so that writers choosing a
    format by extension (OpenCV, matplotlib) still work; its name carries the
    writer's process id (``.NAME.PID.XXXX.tmp.SUFFIX``) so that
    :func:`remove_stale_temporaries` can tell a killed run's leftovers. A full
    disk raises ``OSError(ENOSPC)`` naming ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.{os.getpid()}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        try:
            yield tmp
        except OSError as exc:
            error = no_space_error(exc, path, tmp)
            if error is exc:
                raise
            raise error from exc
        if tmp.is_file():   # mkstemp makes 0600 files; give the output the usual umask permissions
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def no_space_error(exc: OSError, path: str | os.PathLike, written: str | os.PathLike | None = None) -> OSError:
    """``exc``, or ``OSError(ENOSPC, ..., path)`` when it comes from a full disk.

    Some writers report a full disk without errno (numpy: "28800 requested and 20976
    written"); then the free space of the file system of ``written`` (default ``path``)
    decides.
    """
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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def refuse_overwrite_input(output: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Raise ``ValueError`` if ``output`` is the same file as one of ``inputs``."""
    check_outputs({str(output): output}, inputs)


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: the same path after resolving symlinks, or the same inode
    (hard links, bind mounts) when both exist."""
    try:
        if os.path.samefile(a, b):
            return True
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` is ``folder`` or lies under it (symlinks resolved)."""
    return path.resolve().is_relative_to(folder.resolve())


def _check_parent_writable(option: str, path: Path) -> None:
    """The nearest existing ancestor of ``path`` must be a writable directory (the rest is created)."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{option}: cannot create {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: cannot write {path}: the folder {parent} is not writable")


def check_outputs(outputs, inputs: Iterable[str | os.PathLike] = (), *, suffixes=None,
                  input_dirs: Iterable[str | os.PathLike] = ()) -> None:
    """Check a command's output files before any work: raise ``ValueError`` naming the option.

    Parameters
    ----------
    outputs : mapping of str to path (or None)
        Each output file by the option (or description) that names it; None entries are skipped.
    inputs : iterable of path
        Every file the run reads. No output may be one of them (symlinks and hard links
        are resolved: :func:`os.path.samefile`).
    suffixes : mapping of str to tuple of str, optional
        Allowed suffixes (lower case, with the dot) per option.
    input_dirs : iterable of path
        Folders the run reads as a whole (e.g. a benchmark scene): no output may replace a file in one.

    Also: outputs differ from each other, an existing output is not a folder, and the
    folder it goes into exists (or can be created) and is writable.
    """
    items = [(option, Path(path)) for option, path in dict(outputs).items() if path is not None]
    inputs = [Path(p) for p in inputs if p is not None]
    for option, path in items:
        what = option if str(path) in option else f"{option} {path}"
        allowed = (suffixes or {}).get(option)
        if allowed and path.suffix.lower() not in allowed:
            raise ValueError(f"{option} must end in {', '.join(allowed[:-1])}{' or ' if len(allowed) > 1 else ''}"
                             f"{allowed[-1]}, got {path}")
        if path.is_dir():
            raise ValueError(f"{what} is a folder; give a file name")
        _check_parent_writable(option, path)
        for item in inputs:
            if _same_file(path, item):
                raise ValueError(f"{what} would overwrite the input {item}; choose another name")
        for folder in input_dirs:
            if path.exists() and _inside(path, Path(folder)):
                raise ValueError(f"{what} would overwrite a file of the input folder {folder}; choose another name")
    for k, (option_a, a) in enumerate(items):
        for option_b, b in items[k + 1:]:
            if _same_file(a, b):
                raise ValueError(f"{option_a} and {option_b} are the same file {a}; give two different names")


def check_output_dir(option: str, folder: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = (),
                     input_dirs: Iterable[str | os.PathLike] = (), must_be_empty: bool = False,
                     input_kind: str = "input") -> None:
    """Check an output folder before any work: raise ``ValueError`` naming ``option``.

    The folder must not be a file, must be creatable and writable, must not be, contain or lie
    inside any of ``input_dirs`` (e.g. an input dataset), must not contain any of ``inputs``, and
    with ``must_be_empty`` must not exist or be empty.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{option}: {folder} is a file, not a folder")
    if folder.is_dir():
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ValueError(f"{option}: the folder {folder} is not writable")
        if must_be_empty and any(folder.iterdir()):
            raise ValueError(f"{option}: {folder} already exists and is not empty; choose a new folder")
    else:
        _check_parent_writable(option, folder)
    for item in input_dirs:
        item = Path(item)
        if _inside(folder, item) or _inside(item, folder):
            relation = ("is" if folder.resolve() == item.resolve() else
                        "is inside" if _inside(folder, item) else "contains")
            raise ValueError(f"{option} {folder} {relation} the {input_kind} {item}; choose a folder apart from it")
    for item in inputs:
        if item is not None and _inside(Path(item), folder):
            raise ValueError(f"{option} {folder} holds the input {item}; choose a folder apart from the inputs")


@contextlib.contextmanager
def temporary_dir(folder: str | os.PathLike, *, prefix: str = "out") -> Iterator[Path]:
    """A fresh hidden folder ``.PREFIX.PID.XXXX.tmp`` inside ``folder``, removed at the end whatever happens.

    On the same file system as ``folder``, so what is built there can be renamed into place.
    A full disk raises ``OSError(ENOSPC)`` naming ``folder``; :func:`remove_stale_temporaries`
    removes the folder of a killed run.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{prefix}.{os.getpid()}.", suffix=".tmp", dir=folder))
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


@contextlib.contextmanager
def staged_dir(folder: str | os.PathLike, *, prefix: str = "out") -> Iterator[Path]:
    """Yield a fresh temporary folder inside ``folder``; on success move its files into ``folder``.

    Writing a set of outputs there first means a kill or a full disk leaves the previous
    set (or nothing) plus a hidden ``.PREFIX.PID.XXXX.tmp`` folder, never a mix; the moves
    at the end are renames within one file system (:func:`temporary_dir`).
    """
    folder = Path(folder)
    with temporary_dir(folder, prefix=prefix) as tmp:
        yield tmp
        for item in sorted(tmp.iterdir()):
            os.replace(item, folder / item.name)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporaries of :func:`atomic_write` / :func:`staged_dir` that a killed run left in
    ``folder`` (those whose writing process no longer runs); return what was removed."""
    folder = Path(folder)
    removed = []
    if not folder.is_dir():
        return removed
    for item in folder.iterdir():
        parts = item.name.split(".")
        if not item.name.startswith(".") or ".tmp" not in item.name or len(parts) < 4:
            continue
        pids = [p for p in parts[2:-1] if p.isdigit()]
        if not pids or _pid_alive(int(pids[0])):
            continue
        if item.is_dir() and not item.is_symlink():
            shutil.rmtree(item, ignore_errors=True)
        else:
            item.unlink(missing_ok=True)
        removed.append(item)
    return removed


def _existing(path: str | os.PathLike, what: str) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    return path


def read_text(path: str | os.PathLike, what: str = "file") -> str:
    """Read a UTF-8 text file; a missing file or one that is not text raises an error naming it."""
    path = _existing(path, what)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {path} is not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset "
                         f"{exc.start}): a binary file?") from None
    except IsADirectoryError:
        raise ValueError(f"{what} {path} is a folder, not a file") from None


def parse_yaml(text: str, what: str, path, *, loader=None):
    """YAML ``text`` of the file ``path`` as Python data; invalid YAML raises a ``ValueError``
    naming the file (as ``what``) and the line."""
    import yaml

    try:
        return yaml.load(text, Loader=loader or getattr(yaml, "CSafeLoader", yaml.SafeLoader))     # libyaml: 5x
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" (line {mark.line + 1})" if mark is not None else ""
        raise ValueError(f"{what} {path} is not valid YAML{line}") from None


def read_yaml(path: str | os.PathLike, what: str = "file"):
    """A UTF-8 YAML file as Python data; every failure names the file (:func:`read_text`, :func:`parse_yaml`)."""
    return parse_yaml(read_text(path, what), what, path)
