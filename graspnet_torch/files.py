"""The files a user names, read and written safely.

- :func:`read_document`: a problem or config file (YAML or JSON) with a size cap, UTF-8 only, a
  bounded expansion of YAML aliases (a "billion laughs" file is refused before it expands),
  bounded nesting.
- :func:`confined_file`: a path written *inside* such a file (a mesh, a URDF) must stay within the
  file's folder, the repository or an installed Python package, unless the user allows any path;
  a path outside gets the same message whether or not a file is there.
- :func:`check_output_path`: a result or checkpoint path must be a regular file (or not exist yet)
  in a folder that can be written, checked before any work.
"""

from __future__ import annotations

import json
import os
import re
import site
import stat
import sysconfig
import tempfile
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from graspnet_torch.errors import GraspnetError
from graspnet_torch.paths import repo_root
from graspnet_torch.settings import clip, short

__all__ = [
    "MAX_DOCUMENT_BYTES",
    "MAX_EXPANDED_VALUES",
    "MAX_MESH_BYTES",
    "allowed_roots",
    "check_output_path",
    "confined_file",
    "parse_document",
    "read_document",
    "regular_file_stat",
]

MAX_DOCUMENT_BYTES = 1 << 20  # a problem or config file: 1 MiB (the shipped ones are about 1 KiB)
MAX_MESH_BYTES = 64 << 20  # a mesh file named by a problem or URDF: 64 MiB


MAX_EXPANDED_VALUES = 100_000  # a problem file has about 100; an alias bomb has billions


class _TooLarge(yaml.YAMLError):
    def __init__(self, size: int):
        super().__init__(f"{size} values")
        self.size = size


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """Values the document holds once every alias is expanded (counted, not expanded: each
    distinct node is visited once)."""
    key = id(node)
    if key not in memo:
        if isinstance(node, yaml.SequenceNode):
            memo[key] = 1 + sum(_expanded_size(n, memo) for n in node.value)
        elif isinstance(node, yaml.MappingNode):
            memo[key] = 1 + sum(_expanded_size(k, memo) + _expanded_size(v, memo) for k, v in node.value)
        else:
            memo[key] = 1
    return memo[key]


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader with a bounded expansion of aliases (``*name``): a document whose
    expanded size exceeds :data:`MAX_EXPANDED_VALUES` is refused before anything is built, so an
    alias bomb ("billion laughs") cannot grow into gigabytes, while the aliases ``yaml.safe_dump``
    writes for repeated values still load."""

    def compose_document(self):
        node = super().compose_document()
        size = _expanded_size(node, {})
        if size > MAX_EXPANDED_VALUES:
            raise _TooLarge(size)
        return node


# YAML 1.1 (PyYAML) reads 1e3 and 1.0e308 as strings (its floats need a '.' and a signed exponent);
# read them as numbers, as YAML 1.2 and JSON do. Integers still match the int resolver first.
_BoundedLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+|\.[0-9_]+(?:[eE][-+]?[0-9]+)?)$"),
    list("-+0123456789."),
)


def _path_text(path: Any, what: str, error: type[GraspnetError]) -> str:
    if isinstance(path, os.PathLike):
        path = os.fspath(path)
    if not isinstance(path, str) or not path or "\x00" in path or len(path) > 4096:
        raise error(f"{what}: expected a file path, got {short(path)}")
    return path


def regular_file_stat(path: Path, missing: GraspnetError, not_regular: GraspnetError) -> os.stat_result:
    """The ``os.stat`` of a file that must exist and be a regular file; raises ``missing`` or
    ``not_regular`` (the caller's error, its message naming what and where)."""
    try:
        st = os.stat(path)
    except OSError:
        raise missing from None
    if not stat.S_ISREG(st.st_mode):
        raise not_regular
    return st


def read_document(path: str | os.PathLike, what: str, error: type[GraspnetError],
                  max_bytes: int = MAX_DOCUMENT_BYTES) -> Any:
    """The parsed content of a YAML (or ``.json``) file, refused with one line naming ``path``.

    Args:
        path: the file; ``what`` names it in messages ('problem file', 'robot config').
        error: the exception class to raise (``ProblemError``, ``ConfigError``).
        max_bytes: size cap; larger files are refused before they are read.
    """
    text = _path_text(path, what, error)
    p = Path(text)
    st = regular_file_stat(p, error(f"{what} not found: {clip(text, 200)}"),
                           error(f"{clip(text, 200)}: the {what} is not a regular file"))
    if st.st_size > max_bytes:
        raise error(f"{clip(text, 200)}: {st.st_size} bytes; a {what} may have at most {max_bytes} bytes")
    try:
        with open(p, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{clip(text, 200)}: cannot read the {what} ({exc.strerror})") from None
    if len(raw) > max_bytes:
        raise error(f"{clip(text, 200)}: a {what} may have at most {max_bytes} bytes")
    return parse_document(raw, clip(text, 200), json_=p.suffix.lower() == ".json", error=error)


def parse_document(raw: bytes, where: str, json_: bool, error: type[GraspnetError]) -> Any:
    """Decode UTF-8 bytes and parse JSON or YAML (aliases bounded), refusing with one line."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{where}: not UTF-8 text (invalid byte at offset {exc.start})") from None
    try:
        if json_:
            return json.loads(text)
        return yaml.load(text, Loader=_BoundedLoader)  # a SafeLoader subclass
    except _TooLarge as exc:
        raise error(f"{where}: expands to {exc.size} values through YAML aliases (*name); at most "
                    f"{MAX_EXPANDED_VALUES} are allowed") from None
    except json.JSONDecodeError as exc:
        raise error(f"{where}: malformed JSON (line {exc.lineno}: {exc.msg})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" (line {mark.line + 1}: {clip(getattr(exc, 'problem', '') or '', 80)})" if mark is not None else ""
        raise error(f"{where}: malformed YAML{line}") from None
    except RecursionError:
        raise error(f"{where}: nested too deeply") from None
    except ValueError as exc:  # e.g. an integer literal with thousands of digits
        raise error(f"{where}: unreadable value ({clip(str(exc), 80)})") from None


@cache
def _package_roots() -> tuple[Path, ...]:
    roots = {sysconfig.get_paths()[k] for k in ("purelib", "platlib")}
    try:
        roots.update(site.getsitepackages())
    except AttributeError:  # some virtualenvs
        pass
    user = site.getusersitepackages() if hasattr(site, "getusersitepackages") else None
    if user:
        roots.add(user)
    return tuple(Path(r).resolve() for r in sorted(roots) if r)


def allowed_roots(bases: tuple[Path, ...] = ()) -> tuple[Path, ...]:
    """Folders a path inside a user's file may point into: ``bases`` (the file's own folder), the
    repository and the installed Python packages (where third-party robots ship their URDFs)."""
    return (*(Path(b).resolve() for b in bases), repo_root().resolve(), *_package_roots())


def _inside(path: Path, roots: tuple[Path, ...]) -> bool:
    return any(path == r or path.is_relative_to(r) for r in roots)


def confined_file(raw: Any, where: str, bases: tuple[Path, ...], error: type[GraspnetError],
                  allow_outside: bool = False, max_bytes: int = MAX_MESH_BYTES) -> Path:
    """Resolve a file path written in a user's file.

    A relative path is looked up in each of ``bases`` in order (the file's folder first, then the
    repository root). Symbolic links and ``..`` are resolved before the check, so neither leads
    out. A path outside :func:`allowed_roots` is refused with the same message whether or not it
    exists, unless ``allow_outside``.
    """
    text = _path_text(raw, where, error)
    p = Path(text).expanduser()
    candidates = [p] if p.is_absolute() else [Path(b) / p for b in bases]
    resolved = [c.resolve() for c in candidates]
    roots = allowed_roots(tuple(bases))
    if not allow_outside:
        resolved = [r for r in resolved if _inside(r, roots)]
        if not resolved:
            raise error(f"{where}: {clip(text, 120)} is outside the file's folder, the repository and installed "
                        f"packages; set allow_outside_paths=true to use it")
    for r in resolved:
        try:
            st = os.stat(r)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{where}: {clip(text, 120)} is not a regular file")
        if st.st_size > max_bytes:
            raise error(f"{where}: {clip(text, 120)} has {st.st_size} bytes, more than the {max_bytes} allowed")
        return r
    raise error(f"{where}: file not found: {clip(text, 120)}")


def _name_max(folder: Path) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def check_output_path(path: Any, what: str, error: type[GraspnetError]) -> Path:
    """A path a result will be written to, checked before any work: a regular file or nothing yet,
    below folders that exist or can be made, the nearest existing one writable (probed with a
    temporary file, removed at once: permission bits alone mislead root and read-only mounts)."""
    text = _path_text(path, what, error)
    if text.endswith(("/", os.sep)):
        raise error(f"{what}={clip(text, 120)} ends with '/': give a file path, not a folder")
    p = Path(text).expanduser()
    if os.path.lexists(p):
        try:
            st = os.stat(p)
        except OSError:
            raise error(f"{what}={clip(text, 120)}: exists and is not a regular file (a broken link)") from None
        if stat.S_ISDIR(st.st_mode):
            raise error(f"{what}={clip(text, 120)} is a directory; give a file path")
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{what}={clip(text, 120)}: exists and is not a regular file; it will not be replaced")
    folder = p.absolute().parent
    created = [p.name]
    while not os.path.lexists(folder) and folder != folder.parent:
        created.append(folder.name)
        folder = folder.parent
    limit = _name_max(folder)
    for k, name in enumerate(created):  # the file itself also gets a temporary name 16 bytes longer
        if len(name.encode()) + (16 if k == 0 else 0) > limit:
            raise error(f"{what}={clip(text, 120)}: the name {clip(name, 40)} is too long for the file system "
                        f"(at most {limit - (16 if k == 0 else 0)} bytes)")
    if not folder.is_dir():
        raise error(f"{what}={clip(text, 120)}: {clip(str(folder), 120)} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".graspnet-write-test.", dir=folder)
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise error(f"{what}={clip(text, 120)}: cannot write in {clip(str(folder), 120)} ({exc.strerror})") from None
    return p
