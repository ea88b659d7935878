"""Files the user asked for: checked before the work starts, written atomically, and strict JSON.

Every output of the command line (videos, logs, profiles, reports, the bench's files) goes through here:

- ``check_output_file`` / ``check_output_dir`` run *before* an episode, a calibration or a bench starts: the path
  is not a directory (or not a file), its folder can be created, and a file can be created in it (a probe file is
  made and removed). A read-only file system, a missing permission or a full disk is then one ``UserError`` line
  naming the path, instead of a traceback after minutes of work.
- ``atomic_output(path)`` yields a temporary path in the same folder (same suffix, so tools that infer the format
  from it -- ffmpeg, matplotlib -- still do); when the block ends without an exception it is renamed over ``path``
  (``os.replace``, atomic on POSIX), otherwise it is deleted. A failed or interrupted write never leaves a
  half-written file and never destroys the previous one: nothing the user made is lost.
- ``strict_json`` prints JSON that strict parsers accept: NaN and +-Infinity (numpy's too) become ``null``.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import UserError


_PROBE_BYTES = 4096
_UMASK = os.umask(0)
os.umask(_UMASK)


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc)


def _resolve(path: str | Path) -> Path:
    """An existing symbolic link is written through (its target is replaced, the link stays)."""
    p = Path(path)
    return Path(os.path.realpath(p)) if p.is_symlink() else p


def _probe(folder: Path, path: Path, what: str) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=".bigcbf-probe-", dir=folder)
    except OSError as exc:
        raise UserError(f"cannot write the {what} here ({_why(exc)})", file=str(path)) from None
    try:
        os.write(fd, b"\0" * _PROBE_BYTES)     # a full disk refuses this block (creating an empty file may pass)
    except OSError as exc:
        raise UserError(f"cannot write the {what} here ({_why(exc)})", file=str(path)) from None
    finally:
        os.close(fd)
        os.unlink(probe)


def _no_file_on_the_way(folder: Path, path, what: str) -> None:
    """The nearest existing ancestor of ``folder`` must be a folder (else mkdir fails with a puzzling errno)."""
    for q in (folder, *folder.parents):
        if q.exists():
            if not q.is_dir():
                raise UserError(f"cannot put the {what} there: {q} is a file, not a folder", file=str(path))
            return


def check_output_file(path: str | Path, what: str) -> Path:
    """Refuse an output file path that would fail late or destroy something (see the module docstring).
    Creates the missing parent folders. Returns the path to write (a symbolic link's target)."""
    p = _resolve(path)
    if p.is_dir():
        raise UserError(f"the {what} path is a directory, expected a file path", file=str(path))
    if p.exists() and not p.is_file():
        raise UserError(f"the {what} path exists and is not a regular file", file=str(path))
    _no_file_on_the_way(p.parent, path, what)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create the folder of the {what} ({_why(exc)})", file=str(path)) from None
    _probe(p.parent, p, what)
    return p


def check_output_dir(path: str | Path, what: str) -> Path:
    """An output folder: created when missing, must be writable (see the module docstring)."""
    p = _resolve(path)
    if p.exists() and not p.is_dir():
        raise UserError(f"the {what} must be a folder, found a file", file=str(path))
    _no_file_on_the_way(p, path, what)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create the {what} ({_why(exc)})", file=str(path)) from None
    _probe(p, p, what)
    return p


class AtomicFile:
    """A temporary file beside ``path`` (same suffix) that ``commit()`` renames over ``path`` and ``discard()``
    deletes; for writers that outlive one ``with`` block (videos, logs). OSErrors are UserErrors naming ``path``."""

    def __init__(self, path: str | Path, what: str = "output"):
        self.path, self.what = Path(path), what
        target = _resolve(path)
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp_name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}",
                                            dir=target.parent)
        except OSError as exc:
            raise UserError(f"cannot write the {what} ({_why(exc)})", file=str(path)) from None
        try:
            os.fchmod(fd, 0o666 & ~_UMASK)          # mkstemp's 0600 -> what open() would have given
        finally:
            os.close(fd)
        self.target, self.tmp = target, Path(tmp_name)

    def commit(self) -> None:
        try:
            os.replace(self.tmp, self.target)
        except OSError as exc:
            self.discard()
            raise UserError(f"cannot write the {self.what} ({_why(exc)})", file=str(self.path)) from None

    def discard(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.tmp.unlink()


@contextlib.contextmanager
def atomic_output(path: str | Path, what: str = "output") -> Iterator[Path]:
    """``with atomic_output(p) as tmp: write tmp`` -> ``p`` replaced by ``tmp`` at the end, or untouched if the
    block raised (the temporary file is deleted). An OSError while writing or renaming is a UserError naming
    ``p``."""
    f = AtomicFile(path, what)
    try:
        yield f.tmp
    except OSError as exc:
        f.discard()
        raise UserError(f"cannot write the {what} ({_why(exc)})", file=str(path)) from None
    except BaseException:
        f.discard()
        raise
    f.commit()


def write_text(path: str | Path, text: str, what: str = "output") -> Path:
    """Write a text file atomically (UTF-8)."""
    with atomic_output(path, what) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def json_safe(obj):
    """``obj`` with every non-finite float (Python or numpy) replaced by None, numpy scalars and arrays as Python
    numbers and lists, tuples as lists."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):    # numpy scalar or array
        return json_safe(obj.tolist())
    return obj


def strict_json(obj, **kwargs) -> str:
    """JSON text without NaN or Infinity (they become null; see ``json_safe``)."""
    return json.dumps(json_safe(obj), allow_nan=False, **kwargs)
