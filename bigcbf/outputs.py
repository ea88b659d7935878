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
- ``check_distinct(inputs, outputs)`` runs before the work too: no output is one of the command's inputs, lies
  inside an input folder (a ROS 2 bag) or is another output of the same command -- the same file after symbolic
  links are followed, or a hard link to it (same device and inode) -- so ``run sc.toml --log sc.toml`` or
  ``--video X --log X`` is one ``UserError`` line instead of a destroyed scenario or a lost video.
- ``strict_json`` prints JSON that strict parsers accept: NaN and +-Infinity (numpy's too) become ``null``.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterator, Mapping

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


class _Where:
    """A path as the file system sees it: its real path (symbolic links followed) and, when it exists, its
    (device, inode) pair (two hard links of one file share it) and whether it is a folder."""

    def __init__(self, path: str | Path):
        self.real = os.path.realpath(path)
        try:
            st = os.stat(self.real)
        except OSError:
            self.inode, self.is_dir = None, False
        else:
            self.inode, self.is_dir = (st.st_dev, st.st_ino), stat.S_ISDIR(st.st_mode)

    def same(self, other: "_Where") -> bool:
        return self.real == other.real or (self.inode is not None and self.inode == other.inode)

    def inside(self, folder: "_Where") -> bool:
        """This path lies somewhere below ``folder`` (an existing folder)."""
        return folder.is_dir and os.path.commonpath([self.real, folder.real]) == folder.real != self.real


def same_file(a: str | Path, b: str | Path) -> bool:
    """``a`` and ``b`` name one file: the same real path, or (both existing) the same device and inode."""
    return _Where(a).same(_Where(b))


def check_distinct(inputs: Mapping[str, str | Path | None], outputs: Mapping[str, str | Path | None]) -> None:
    """Refuse, before any work, outputs that would destroy an input or each other: every output (label -> path;
    None entries are skipped) must differ from every input and every other output -- compared by real path and,
    where the file exists, by (device, inode), so symbolic and hard links are seen through -- and must not lie
    inside an input that is a folder (a ROS 2 bag folder, say). The labels name the options in the one-line
    ``UserError`` (e.g. ``{"scenario": "sc.toml"}``, ``{"--log": "sc.toml"}``). An output folder is given as the
    files the command writes in it (``{"--report calibration.json": DIR / "calibration.json", ...}``)."""
    ins = [(label, p, _Where(p)) for label, p in inputs.items() if p is not None]
    outs = [(label, p, _Where(p)) for label, p in outputs.items() if p is not None]
    for k, (label, path, where) in enumerate(outs):
        for in_label, in_path, in_where in ins:
            if where.same(in_where):
                raise UserError(f"{label} is the same file as the {in_label} ({in_path}); writing it would destroy "
                                f"the {in_label}: give {label} another path", file=str(path))
            if where.inside(in_where):
                raise UserError(f"{label} lies inside the {in_label} folder ({in_path}); writing it would change "
                                f"the {in_label}: give {label} a path outside it", file=str(path))
        for other_label, other_path, other_where in outs[:k]:
            if where.same(other_where):
                raise UserError(f"{label} and {other_label} are the same file ({other_path}); one would replace "
                                f"the other: give each output its own path", file=str(path))


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
