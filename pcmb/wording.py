"""How messages word counts and suggestions."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["did_you_mean", "plural"]


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """``"did you mean 'uniform'?"`` for the choice closest to a misspelt name, or ``""``."""
    close = difflib.get_close_matches(name, list(choices), n=1)
    return f"did you mean {close[0]!r}?" if close else ""


def plural(count: int, noun: str, nouns: str | None = None) -> str:
    """``"1 figure"``, ``"3 figures"``; ``nouns`` for an irregular plural."""
    return f"{count} {noun if count == 1 else nouns or noun + 's'}"
