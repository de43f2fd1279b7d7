"""How messages word counts and suggestions, and how docstrings read in generated docs."""

from __future__ import annotations

import difflib
import re
import signal
from collections.abc import Iterable

__all__ = ["did_you_mean", "markdown", "plural", "signal_name"]


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """``"did you mean 'uniform'?"`` for the choice closest to a misspelt name, or ``""``."""
    close = difflib.get_close_matches(name, list(choices), n=1)
    return f"did you mean {close[0]!r}?" if close else ""


def plural(count: int, noun: str, nouns: str | None = None) -> str:
    """``"1 figure"``, ``"3 figures"``; ``nouns`` for an irregular plural."""
    return f"{count} {noun if count == 1 else nouns or noun + 's'}"


def markdown(doc: str | None) -> str:
    """Docstring or description text as one Markdown line: ``code`` and :role:`target` become
    code."""
    if not doc:
        return ""
    text = re.sub(r":[a-z]+:`~([^`]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", doc)
    text = re.sub(r":[a-z]+:`([^`]+)`", r"`\1`", text)
    text = re.sub(r"``([^`]+)``", r"`\1`", text)
    return " ".join(text.split())


def signal_name(number: int) -> str:
    """``SIGSEGV`` for 11; ``SIGRT35`` and the like for a signal Python has no name for."""
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"SIGRT{number}" if signal.SIGRTMIN <= number <= signal.SIGRTMAX else "unnamed"
