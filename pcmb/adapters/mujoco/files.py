"""The files of an MJCF scene, found by parsing its XML (no mujoco import): the scene, the
files it ``<include>``s (recursively) and the asset files it names."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ElementTree
from pathlib import Path

__all__ = ["mjcf_files"]

# Cube-map textures name one file per side.
_FILE_ATTRIBUTES = ("file", *(f"file{side}" for side in ("right", "left", "up", "down")))
_FILE_ATTRIBUTES += ("filefront", "fileback")
_MESH_TAGS = frozenset({"mesh", "hfield", "skin"})


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
