"""The model's own part of a traceback: which frames are the model's code, and where it raised.

A frame is pcmb's (a file of the pcmb package), the installed environment's (the standard
library, site-packages) or the model's (any other file: the user's code). A model's
traceback keeps the model's frames and what they call, and drops pcmb's frames and the
environment's frames that merely call into the model.
"""

from __future__ import annotations

import functools
import os
import site
import sysconfig
import traceback
from pathlib import Path

from pcmb.run.status import ModelTraceback

__all__ = ["PCMB_FOLDER", "installed", "installed_folders", "model_exception", "model_traceback"]

#: The pcmb package's folder.
PCMB_FOLDER = Path(__file__).resolve().parents[1]

_PCMB, _ENVIRONMENT, _MODEL = "pcmb", "environment", "model"
_CAUSED = "\nThe above exception was the direct cause of the following exception:\n\n"
_DURING = "\nDuring handling of the above exception, another exception occurred:\n\n"


def installed_folders() -> tuple[Path, ...]:
    """The folders of the installed environment: the standard library, site-packages and
    pcmb itself."""
    paths = sysconfig.get_paths()
    found = {paths[key] for key in ("stdlib", "platstdlib", "purelib", "platlib") if key in paths}
    found.update(site.getsitepackages(), [site.getusersitepackages()])
    found.add(str(PCMB_FOLDER))
    return tuple(Path(folder).resolve() for folder in found)


def installed(path: Path, folders: tuple[Path, ...]) -> bool:
    """Whether the resolved ``path`` is in one of ``folders`` (:func:`installed_folders`) or
    in any site-packages folder."""
    return any(path.is_relative_to(folder) for folder in folders) or bool(
        {"site-packages", "dist-packages"} & set(path.parts)
    )


@functools.cache
def _kind(filename: str) -> str:
    """Whose code the file of a frame is: pcmb's, the environment's or the model's."""
    if filename.startswith("<frozen "):  # the import machinery
        return _ENVIRONMENT
    if filename.startswith("<"):  # code compiled from a string: the model's, if anyone's
        return _MODEL
    path = Path(os.path.realpath(filename))
    if path.is_relative_to(PCMB_FOLDER):
        return _PCMB
    return _ENVIRONMENT if installed(path, _folders()) else _MODEL


@functools.cache
def _folders() -> tuple[Path, ...]:
    return installed_folders()


def _frames(error: BaseException) -> list[traceback.FrameSummary]:
    """The frames of ``error``'s traceback that belong to the model's traceback: from the
    first frame of the model's code on, pcmb's excepted (none if the model has no frame)."""
    frames = traceback.extract_tb(error.__traceback__)
    kinds = [_kind(frame.filename) for frame in frames]
    if _MODEL not in kinds:
        return []
    first = kinds.index(_MODEL)
    return [f for f, kind in zip(frames[first:], kinds[first:], strict=True) if kind != _PCMB]


def _chain(error: BaseException) -> list[BaseException]:
    """``error`` and the exceptions it was raised from or while handling, outermost first,
    as Python prints them."""
    chain: list[BaseException] = []
    current: BaseException | None = error
    while current is not None and all(current is not seen for seen in chain):
        chain.append(current)
        current = current.__cause__ or (
            None if current.__suppress_context__ else current.__context__
        )
    return chain


def model_exception(error: BaseException) -> BaseException:
    """The exception the model's code raised, of ``error`` raised from it (pcmb's adapters
    wrap a model's error in their own): the outermost of its chain with a frame of the
    model's code, else ``error``."""
    return next((found for found in _chain(error) if _frames(found)), error)


def model_traceback(error: BaseException, full: bool = False) -> ModelTraceback | None:
    """Where the model's code raised ``error`` (or the exception it was raised from), with
    the model's part of the traceback, as Python prints it; ``full``: the whole traceback,
    pcmb's frames included. ``None`` when no frame is the model's (an error of pcmb's own,
    a command's failure)."""
    raised = model_exception(error)
    frames = _frames(raised)
    if not frames:
        return None
    innermost = next(f for f in reversed(frames) if _kind(f.filename) == _MODEL)
    text = "".join(traceback.format_exception(error)) if full else _format(raised)
    return ModelTraceback(
        error=type(raised).__name__,
        file=innermost.filename,
        line=innermost.lineno or 0,
        function=innermost.name,
        text=text,
    )


def _format(error: BaseException) -> str:
    """The model's part of the traceback of ``error`` and of the exceptions it was raised
    from or while handling (those with frames of the model's code), as Python prints them."""
    parts: list[str] = []
    for raised in reversed(_chain(error)):
        frames = _frames(raised)
        if not frames:
            continue
        if parts:
            parts.append(_CAUSED if raised.__cause__ is not None else _DURING)
        parts.append("Traceback (most recent call last):\n")
        parts += traceback.format_list(frames)
        parts += traceback.format_exception_only(raised)
    return "".join(parts)
