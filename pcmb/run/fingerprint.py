"""What a resume journal belongs to: a digest of the run's settings and the model's files.

A journal may only be continued by a run that would compute the same value at every node.
Its :class:`Fingerprint` has two parts, compared separately so that a refusal can say what
changed:

- ``digest``: a hash of the settings that change node values (the nodes, the time grid,
  the outputs, an explicit chunk size, the model's settings; see ``Study.fingerprint``);
- ``files``: path -> SHA-256 of the *content* of every file pcmb knows the model reads, so
  that editing the simulator between a kill and ``--resume`` is refused, naming the file.

Which files are known is each adapter's to say (everything else a model reads is the
user's responsibility): its factory's ``model_files()`` lists those known before the model
is built (:func:`model_files`), its ``loaded_files()`` those the model loaded while it was
built in a worker (a python model's own modules; see
:class:`~pcmb.adapters.protocol.ModelFactory`).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["MISSING", "Fingerprint", "changed_files", "digest_files", "model_files"]

#: The digest recorded for a file that does not exist (or cannot be read).
MISSING = "missing"

_CHUNK = 1 << 20


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


def model_files(factory: object) -> list[Path]:
    """The files a model factory declares it depends on (its ``model_files()``, see
    :class:`~pcmb.adapters.protocol.ModelFactory`); none for any other callable."""
    declared = getattr(factory, "model_files", None)
    return list(declared()) if callable(declared) else []
