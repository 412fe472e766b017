"""Safe output folders: the one mechanism every command writes through.

The promise: no command deletes or replaces anything it did not write, and nothing half
written is left behind, whatever the signal or error. :func:`output_folder` keeps it:

1. **Checks first**, before any computation: ``--out`` (symlinks resolved) must not be the
   working folder or one of its ancestors, ``/``, a home folder, or a folder holding one of the
   command's inputs. An existing non-empty folder is replaced only with ``--overwrite`` and only
   when markerplan wrote it: its ``provenance.json`` (:data:`PROVENANCE_FILE`) lists every file
   in it with its SHA-256, and a folder holding anything else (or a changed file) is refused.
2. **A lock** (``.<name>.lock`` beside the destination, ``flock``) held for the whole run: a
   second run on the same ``--out`` fails at once with a message.
3. **A staging folder** (``.<name>.partial-XXXXXXXX`` beside the destination) receives the
   files; at the end it gets its ``provenance.json`` and is moved into place. Its marker
   :data:`STAGE_MARKER` says markerplan made it and stays locked (``flock``) while its run
   lives. If the destination appeared during the run (another program wrote it) and
   ``--overwrite`` was not given, the run fails and keeps both: the staged result is moved to a
   visible sibling folder the message names.
4. **Cleanup**: any exception, SIGINT, SIGTERM and SIGHUP remove the staging folder, the lock
   and any parent folder the run created. SIGKILL cannot be caught: the next run on the same
   destination removes the staging folders such a run left (:func:`remove_stale_stages`: the
   name, the marker and its free lock prove them ours and dead; anything else is left alone).
   Write errors (a full disk, a folder where no file can be made) become one
   :class:`~markerplan.errors.OutputError` line; a library that writes without telling why it
   failed (GDAL) writes inside :func:`library_write`, which asks the disk.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import signal
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from markerplan import __version__
from markerplan.errors import MarkerPlanError, OutputError

#: The file that marks a folder as written by markerplan (and lists what it wrote).
PROVENANCE_FILE = "provenance.json"

#: The file inside a staging folder that says markerplan made it; locked while its run lives.
STAGE_MARKER = ".markerplan-stage"

#: Bytes :func:`library_write`'s probe writes beyond the size of the file a library failed on.
PROBE_MARGIN_BYTES = 1 << 20

_HANDLED_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class Terminated(MarkerPlanError, RuntimeError):
    """The run received SIGTERM or SIGHUP; raised from the signal handler so cleanup runs."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"stopped by {signal.Signals(signum).name}; nothing was written")


def _is_within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _forbidden_reason(out: Path, inputs: Iterable[Path]) -> str | None:
    """Why ``out`` (resolved) may never be an output folder, or ``None``."""
    cwd = Path.cwd().resolve()
    if out == Path(out.anchor):
        return "is the file-system root"
    if _is_within(cwd, out):
        return "is the current folder" if out == cwd else "holds the current folder"
    home = Path.home().resolve()
    if out == home or out.parent == Path("/home"):
        return "is a home folder"
    if _is_within(home, out):
        return "holds a home folder"
    for p in inputs:
        p = Path(p).resolve()
        if _is_within(p, out):
            return f"holds the input {p}" if p != out else "is an input of this command"
    return None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _listing(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder`` (sorted; provenance and the
    stage marker excluded)."""
    return {str(p.relative_to(folder)): _sha256(p)
            for p in sorted(folder.rglob("*"))
            if p.is_file() and str(p.relative_to(folder)) not in (PROVENANCE_FILE, STAGE_MARKER)}


def _foreign_content(folder: Path) -> str | None:
    """What in an existing folder markerplan did not write, or ``None`` if it wrote it all."""
    marker = folder / PROVENANCE_FILE
    try:
        record = json.loads(marker.read_text(encoding="utf-8"))
        files = record["files"]
        if record.get("written_by") != "markerplan" or not isinstance(files, dict):
            raise ValueError
    except FileNotFoundError:
        return f"it has no {PROVENANCE_FILE}, so markerplan did not write it"
    except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError):
        return f"its {PROVENANCE_FILE} is not one markerplan wrote"
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink() or not (p.is_dir() or p.is_file()):
            return f"{rel} is not a plain file markerplan wrote"
        if p.is_file() and rel != PROVENANCE_FILE:
            if rel not in files:
                return f"{rel} was not written by markerplan"
            if _sha256(p) != files[rel]:
                return f"{rel} was changed after markerplan wrote it"
    return None


def check_destination(out: Path, overwrite: bool, inputs: Iterable[Path] = ()) -> Path:
    """Refuse an unsafe ``--out`` (see the module docstring); return it resolved.

    Parameters
    ----------
    out : Path
        The ``--out`` folder as given.
    overwrite : bool
        Whether an existing folder markerplan wrote may be replaced.
    inputs : iterable of Path
        The command's input files and folders; ``out`` may not hold any of them.

    Raises
    ------
    OutputError
        With the reason and the way forward.
    """
    resolved = Path(out).expanduser().resolve()
    reason = _forbidden_reason(resolved, inputs)
    if reason is not None:
        raise OutputError(f"`out` {out} {reason}; markerplan replaces its `out` folder, so "
                          "give a new folder for the results, e.g. `out` results/")
    if resolved.exists() and not resolved.is_dir():
        raise OutputError(f"`out` {out} exists and is not a folder; choose another path")
    if resolved.is_dir() and any(resolved.iterdir()):
        if not overwrite:
            raise OutputError(f"`out` {out} already exists; pass `overwrite` to replace it or "
                              "choose another folder")
        foreign = _foreign_content(resolved)
        if foreign is not None:
            raise OutputError(f"`out` {out} cannot be overwritten: {foreign}; move what you "
                              "want to keep out of it, or choose another folder")
    probe = resolved.parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"`out` {out} is not writable (no write permission in {probe}); "
                          "choose a writable folder")
    return resolved


def _raise_terminated(signum, frame):
    raise Terminated(signum)


@contextlib.contextmanager
def _signals_raise() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` (main thread only) while inside."""
    try:
        previous = {s: signal.signal(s, _raise_terminated) for s in _HANDLED_SIGNALS}
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def _lock(destination: Path, out: Path) -> Iterator[None]:
    """Hold ``.<name>.lock`` beside ``destination`` exclusively; remove it on exit."""
    path = destination.parent / f".{destination.name}.lock"
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(f"`out` {out} is being written by another markerplan run; wait "
                              "for it to finish or choose another folder") from None
        try:  # the holder before us may have removed the file between our open and flock
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


def _stage_pattern(destination: Path) -> re.Pattern:
    """The names :func:`tempfile.mkdtemp` gives ``destination``'s staging folders."""
    return re.compile(rf"\.{re.escape(destination.name)}\.partial-[a-z0-9_]{{8}}")


@contextlib.contextmanager
def _staging(destination: Path, command: str) -> Iterator[tuple[Path, Callable[[], None]]]:
    """Make a staging folder beside ``destination`` holding a locked :data:`STAGE_MARKER`;
    yield it and the function that removes the marker (before the folder is moved into place);
    remove the folder on exit."""
    stage = Path(tempfile.mkdtemp(prefix=f".{destination.name}.partial-", dir=destination.parent))
    try:
        fd = os.open(stage / STAGE_MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW,
                     0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            os.write(fd, json.dumps({"written_by": "markerplan", "command": command,
                                     "pid": os.getpid()}).encode() + b"\n")
            yield stage, lambda: (stage / STAGE_MARKER).unlink()
        finally:
            os.close(fd)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _is_dead_stage(folder: Path) -> bool:
    """Whether ``folder`` holds a :data:`STAGE_MARKER` markerplan wrote whose run is gone (its
    lock is free: ``flock`` locks die with their process)."""
    try:
        fd = os.open(folder / STAGE_MARKER, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with os.fdopen(os.dup(fd), encoding="utf-8") as fh:
            return json.loads(fh.read()).get("written_by") == "markerplan"
    except (OSError, ValueError, AttributeError):  # held by a live run, or not our marker
        return False
    finally:
        os.close(fd)


def remove_stale_stages(destination: Path) -> list[Path]:
    """Remove the staging folders of ``destination`` that runs killed by SIGKILL left: named
    like :func:`_staging`'s, not a symlink, with a :data:`STAGE_MARKER` markerplan wrote whose
    lock no live run holds. Anything else (a look-alike, a live run's stage) is left alone.

    Parameters
    ----------
    destination : Path
        The resolved ``--out`` folder.

    Returns
    -------
    removed : list of Path
        The staging folders removed, sorted.
    """
    pattern = _stage_pattern(destination)
    try:
        names = sorted(os.listdir(destination.parent))
    except OSError:  # a folder one may write into but not list: no stage can be found
        return []
    removed = []
    for folder in (destination.parent / n for n in names):
        if (pattern.fullmatch(folder.name) and not folder.is_symlink() and folder.is_dir()
                and _is_dead_stage(folder)):
            shutil.rmtree(folder)
            removed.append(folder)
    return removed


def _make_parents(folder: Path) -> list[Path]:
    """``mkdir -p folder``; return the folders created, deepest first."""
    created = []
    probe = folder
    while not probe.exists():
        created.append(probe)
        probe = probe.parent
    folder.mkdir(parents=True, exist_ok=True)
    return created


def _remove_empty(folders: list[Path]) -> None:
    for f in folders:
        with contextlib.suppress(OSError):
            f.rmdir()


def write_provenance(folder: Path, command: str) -> None:
    """Write ``folder/provenance.json``: who wrote the folder and every file's SHA-256."""
    record = {"written_by": "markerplan", "markerplan_version": __version__,
              "command": command, "files": _listing(folder)}
    (folder / PROVENANCE_FILE).write_text(json.dumps(record, indent=1, sort_keys=True) + "\n",
                                          encoding="utf-8")


def _free_sibling(destination: Path) -> Path:
    for n in range(2, 10_000):
        candidate = destination.with_name(f"{destination.name}-{n}")
        if not candidate.exists():
            return candidate
    raise OutputError(f"no free folder name beside {destination}")  # pragma: no cover


def _move_into_place(stage: Path, destination: Path, out: Path, overwrite: bool,
                     existed_before: bool) -> None:
    """Move the finished ``stage`` to ``destination`` under the rules of the module docstring."""
    occupied = destination.exists() and (not destination.is_dir() or any(destination.iterdir()))
    if occupied and not (overwrite and existed_before):
        kept = _free_sibling(destination)
        os.rename(stage, kept)
        raise OutputError(f"`out` {out} appeared while this run was working and was kept; this "
                          f"run's results are in {kept}")
    if not occupied:
        if destination.is_dir():
            destination.rmdir()  # empty: nothing of anyone's is lost
        os.rename(stage, destination)
        return
    foreign = _foreign_content(destination)
    if foreign is not None:
        kept = _free_sibling(destination)
        os.rename(stage, kept)
        raise OutputError(f"`out` {out} changed during the run ({foreign}) and was kept; this "
                          f"run's results are in {kept}")
    old = Path(tempfile.mkdtemp(prefix=f".{destination.name}.old-", dir=destination.parent))
    os.rename(destination, old / "previous")
    try:
        os.rename(stage, destination)
    except BaseException:
        os.rename(old / "previous", destination)
        old.rmdir()
        raise
    shutil.rmtree(old)


@contextlib.contextmanager
def output_folder(out: Path, overwrite: bool, command: str,
                  inputs: Iterable[Path] = ()) -> Iterator[Path]:
    """Check ``out``, lock it, and yield a staging folder that becomes ``out`` on success.

    Enter it before any computation, so that a bad ``--out`` fails at once.

    Parameters
    ----------
    out : Path
        The ``--out`` folder as the user gave it.
    overwrite : bool
        ``--overwrite``: replace a folder markerplan wrote.
    command : str
        Sub-command name, recorded in ``provenance.json``.
    inputs : iterable of Path
        The command's input files and folders (``out`` may not hold them).

    Yields
    ------
    stage : Path
        Empty folder to write the results into.

    Raises
    ------
    OutputError
        Unsafe or busy ``--out``, a write error (e.g. a full disk), or a destination that
        appeared during the run.
    Terminated
        SIGTERM or SIGHUP arrived; the staging folder is gone.
    """
    out = Path(out)
    destination = check_destination(out, overwrite, inputs)
    with _signals_raise():
        try:
            created = _make_parents(destination.parent)
        except OSError as exc:
            raise OutputError(f"`out` {out} cannot be created ({exc.strerror}); choose a "
                              "writable folder") from exc
        try:
            with _lock(destination, out):
                remove_stale_stages(destination)
                existed_before = destination.is_dir() and any(destination.iterdir())
                with _staging(destination, command) as (stage, unmark):
                    yield stage
                    write_provenance(stage, command)
                    os.chmod(stage, 0o755)  # mkdtemp makes 0700; results are meant to be shared
                    unmark()
                    _move_into_place(stage, destination, out, overwrite, existed_before)
        except OSError as exc:
            _remove_empty(created)
            if isinstance(exc, MarkerPlanError):
                raise
            raise OutputError(_write_error(out, destination, exc)) from exc
        except BaseException:
            _remove_empty(created)
            raise


def _write_error(out: Path, destination: Path, exc: OSError) -> str:
    """The one line of a failed write into ``out`` (resolved: ``destination``): the file (in a
    staging folder: as it would have been in ``out``), the system's reason, the fix."""
    where = f" ({_shown_path(exc.filename, out, destination)})" if exc.filename else ""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        fix = "free some space or choose a folder on another disk"
    elif exc.errno == errno.EFBIG:
        fix = "raise the file-size limit (ulimit -f) or choose another folder"
    else:
        fix = "choose a writable folder on a disk (e.g. `out` results/)"
    return f"`out` {out}: writing failed{where}: {exc.strerror or exc}; nothing was written; {fix}"


def _shown_path(filename: str | bytes | os.PathLike, out: Path, destination: Path) -> str:
    """``filename``, but ``out/<file>`` for a file of one of ``destination``'s staging folders."""
    path = Path(os.fsdecode(filename))
    pattern = _stage_pattern(destination)
    for folder in path.parents:
        if folder.parent == destination.parent and pattern.fullmatch(folder.name):
            return str(out / path.relative_to(folder))
    return str(path)


@contextlib.contextmanager
def library_write(path: Path) -> Iterator[None]:
    """Write ``path`` with a library that does not say why a write failed (GDAL through
    pyogrio raises e.g. ``DataSourceError("Failed to commit transaction")`` or SQLite's
    "no such table" on a full disk); on its failure, ask the disk.

    The probe writes the failed file's size plus :data:`PROBE_MARGIN_BYTES` of zeros into a
    temporary file beside ``path`` (and removes it): a full disk, a file-size limit, a read-only
    or vanished folder refuse it as they refused the library.

    Parameters
    ----------
    path : Path
        The file the library writes.

    Raises
    ------
    OSError
        The disk's refusal (its errno and message), for ``path``; :func:`output_folder` makes
        it the one-line :class:`~markerplan.errors.OutputError`.
    Exception
        The library's own error, unchanged, when the disk takes the probe (a bug, not the disk).
    """
    path = Path(path)
    try:
        yield
    except Exception as exc:
        if isinstance(exc, MarkerPlanError):
            raise
        refusal = _disk_refusal(path)
        if refusal is None:
            raise
        raise OSError(refusal.errno, refusal.strerror, str(path)) from exc


def _disk_refusal(path: Path) -> OSError | None:
    """The OSError the folder of ``path`` gives a probe as big as ``path`` plus
    :data:`PROBE_MARGIN_BYTES`, or ``None`` when it takes the probe."""
    try:
        size = path.stat().st_size + PROBE_MARGIN_BYTES
    except OSError:
        size = PROBE_MARGIN_BYTES
    block = bytes(1 << 16)
    probe = None
    try:
        fd, probe = tempfile.mkstemp(prefix=".markerplan-probe-", dir=path.parent)
        with os.fdopen(fd, "wb", buffering=0) as fh:
            while size > 0:
                size -= fh.write(block[:size])
            os.fsync(fh.fileno())
    except OSError as refusal:
        return refusal
    finally:
        if probe is not None:
            with contextlib.suppress(OSError):
                os.unlink(probe)
    return None
