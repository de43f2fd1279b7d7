"""What a resume journal belongs to: a digest of the run's settings and the model's files.

A journal may only be continued by a run that would compute the same value at every node.
Its :class:`Fingerprint` has two parts, compared separately so that a refusal can say what
changed:

- ``digest``: a hash of the settings that change node values (the nodes, the time grid,
  the outputs, an explicit chunk size, the model's settings; see ``Study.fingerprint``);
- ``files``: path -> SHA-256 of the *content* of every file pcmb knows the model reads
  (:func:`model_files`), so that editing the simulator between a kill and ``--resume`` is
  refused, naming the file.

Which files are known (everything else a model reads is the user's responsibility):

- python: the entry file (``path/to/file.py:Name``) or the module file of a
  ``package.module:Name`` entry; not the modules it imports nor the data it reads;
- command: the program when it is given as a path (``./sim``, ``../models/x.py``; a bare
  name found on PATH is not hashed), every argument that is an absolute path of an existing
  file, every ``templates`` and ``files`` entry;
- mujoco: the MJCF file and the files it references, found by parsing the XML: ``<include
  file>`` (recursively, relative to the main file's folder), and the ``file`` (and a cube
  texture's ``file<side>``) attributes of assets, relative to ``<compiler meshdir>`` (meshes,
  height fields, skins), ``texturedir`` (textures) or ``assetdir``. A file that is not valid
  XML is hashed alone.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "MISSING",
    "Fingerprint",
    "changed_files",
    "command_files",
    "digest_files",
    "mjcf_files",
    "model_files",
    "python_entry_files",
]

#: The digest recorded for a file that does not exist (or cannot be read).
MISSING = "missing"

_CHUNK = 1 << 20
# Cube-map textures name one file per side.
_FILE_ATTRIBUTES = ("file", *(f"file{side}" for side in ("right", "left", "up", "down")))
_FILE_ATTRIBUTES += ("filefront", "fileback")
_MESH_TAGS = frozenset({"mesh", "hfield", "skin"})


@dataclass(frozen=True)
class Fingerprint:
    """What a journal belongs to.

    Attributes
    ----------
    digest:
        Hash of every setting that changes the node values.
    files:
        Absolute path -> SHA-256 hex digest of the file's content (:data:`MISSING` when it
        does not exist), for every file the model is known to depend on.
    """

    digest: str
    files: Mapping[str, str] = field(default_factory=dict)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            while block := handle.read(_CHUNK):
                digest.update(block)
    except OSError:
        return MISSING
    return digest.hexdigest()


def digest_files(paths: Iterable[str | os.PathLike[str]]) -> dict[str, str]:
    """Absolute path -> SHA-256 of its content (:data:`MISSING` if unreadable), sorted."""
    resolved = {str(Path(p).resolve()) for p in paths}
    return {path: _sha256(Path(path)) for path in sorted(resolved)}


def changed_files(recorded: Mapping[str, str], current: Mapping[str, str]) -> list[str]:
    """The paths whose digest differs between two tables (a path in only one of them too)."""
    return sorted(p for p in set(recorded) | set(current) if recorded.get(p) != current.get(p))


# --------------------------------------------------------------------------- python


def python_entry_files(entry: str, base_dir: str | os.PathLike[str]) -> list[Path]:
    """The file of a python entry: ``file.py:Name`` -> that file; ``pkg.mod:Name`` -> the
    module's file (found as the adapter imports it: ``base_dir`` first on ``sys.path``).

    A module that cannot be found or has no file (built-in, namespace package) gives none.
    """
    target = entry.rpartition(":")[0]
    if not target:
        return []
    if target.endswith(".py"):
        return [(Path(base_dir) / target).resolve()]
    module = sys.modules.get(target)
    origin = getattr(module, "__file__", None) if module is not None else None
    if origin is None:
        sys.path.insert(0, str(Path(base_dir).resolve()))
        try:
            spec = importlib.util.find_spec(target)
        except (ImportError, ValueError):
            spec = None
        finally:
            sys.path.remove(str(Path(base_dir).resolve()))
        origin = spec.origin if spec is not None and spec.has_location else None
    return [] if origin is None else [Path(origin).resolve()]


# --------------------------------------------------------------------------- command


def command_files(
    command: Iterable[str],
    templates: Iterable[str],
    files: Iterable[str],
    base_dir: str | os.PathLike[str],
) -> list[Path]:
    """The files of a command model (see the module docstring), resolved like the adapter does."""
    base = Path(base_dir)
    argv = list(command)
    found = [base / name for name in (*templates, *files)]
    if argv and os.sep in argv[0]:
        found.append(base / argv[0])
    found += [Path(arg) for arg in argv[1:] if os.path.isabs(arg) and Path(arg).is_file()]
    return [path.resolve() for path in found]


# --------------------------------------------------------------------------- mujoco


def _parse(path: Path) -> ElementTree.Element | None:
    try:
        return ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError):
        return None


def mjcf_files(xml: str | os.PathLike[str]) -> list[Path]:
    """An MJCF file and the files it references: includes (recursively) and asset files.

    Paths resolve as MuJoCo resolves them: includes against the main file's folder, mesh,
    height-field and skin files against ``meshdir``, textures against ``texturedir`` (each
    defaulting to ``assetdir``, then to the main file's folder). Attribute values holding
    a ``{{ placeholder }}`` are skipped.
    """
    main = Path(xml).resolve()
    folder = main.parent
    documents: list[tuple[Path, ElementTree.Element]] = []
    queue, seen = [main], {main}
    while queue:
        path = queue.pop(0)
        root = _parse(path)
        if root is None:
            continue
        documents.append((path, root))
        for element in root.iter("include"):
            name = element.get("file")
            if name and "{{" not in name:
                target = (folder / name).resolve()
                if target not in seen:
                    seen.add(target)
                    queue.append(target)
    compiler: dict[str, str] = {}
    for _, root in documents:
        for element in root.iter("compiler"):
            compiler.update({k: v for k, v in element.attrib.items() if k.endswith("dir")})
    assets = folder / compiler.get("assetdir", "")
    meshdir = folder / compiler["meshdir"] if "meshdir" in compiler else assets
    texturedir = folder / compiler["texturedir"] if "texturedir" in compiler else assets
    found = set(seen)
    for _, root in documents:
        for element in root.iter():
            if element.tag in ("include", "compiler"):
                continue
            base = (
                meshdir
                if element.tag in _MESH_TAGS
                else texturedir
                if element.tag == "texture"
                else folder
            )
            for attribute in _FILE_ATTRIBUTES:
                name = element.get(attribute)
                if name and "{{" not in name:
                    found.add((base / name).resolve())
    return sorted(found)


# --------------------------------------------------------------------------- any factory


def model_files(factory: object) -> list[Path]:
    """The files a model factory built by pcmb's adapters is known to depend on.

    A :class:`~pcmb.adapters.python.model.PythonModelFactory` (python entry), a
    :class:`~pcmb.adapters.command.model.CommandModelFactory`, a
    :class:`~pcmb.adapters.mujoco.model.MujocoModelFactory` or a
    :class:`~pcmb.adapters.fmu.factory.FmuModelFactory` (its ``.fmu`` file), whether built
    from a config or by hand; any other factory (a Python object given to ``Study``) has
    none: it is fingerprinted by pickling.
    """
    from pcmb.adapters.command.model import CommandModelFactory
    from pcmb.adapters.fmu.factory import FmuModelFactory
    from pcmb.adapters.python.model import PythonModelFactory

    if isinstance(factory, PythonModelFactory):
        return python_entry_files(factory.entry, factory.base_dir)
    if isinstance(factory, CommandModelFactory):
        base = Path.cwd() if factory.base_dir is None else factory.base_dir
        return command_files(factory.command, factory.templates, factory.files, base)
    if isinstance(factory, FmuModelFactory):
        return [Path(factory.fmu)] if Path(factory.fmu).is_file() else []
    # Only loaded (it imports mujoco) when a MuJoCo factory exists.
    mujoco_model = sys.modules.get("pcmb.adapters.mujoco.model")
    if mujoco_model is not None and isinstance(factory, mujoco_model.MujocoModelFactory):
        return mjcf_files(factory.xml)
    return []
