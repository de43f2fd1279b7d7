"""Where one run of a study journals: the journal beside its output, a folder of it for each
later set of runs (an adaptive design's rounds, the held-out runs' batches), and the journal
of a set of runs, removed when the run is rejected before it began."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

from pcmb.errors import ModelDefinitionError, UsageError
from pcmb.run.fingerprint import Fingerprint
from pcmb.run.journal import FRESH, Journal

__all__ = ["Journaling", "removed_if_rejected"]


@dataclasses.dataclass(frozen=True)
class Journaling:
    """Where a run journals (``directory``: ``<output>.journal``, or a folder of it) and the
    digests of the model's files that every journal of the run records
    (``Study.fingerprint``), taken once."""

    directory: Path
    files: Mapping[str, str]

    @classmethod
    def start(
        cls, output: str | Path, files: Mapping[str, str], *, resume: bool, fresh: bool
    ) -> Journaling:
        """The journaling of a run writing ``output``, in ``<output>.journal``: discarded
        first when ``fresh``, refused while another run writes it, or when it holds an
        interrupted run's nodes and the run does not ``resume``; ``files``: the digests of
        the model's files."""
        directory = Path(f"{output}.journal")
        if fresh:
            Journal.discard(directory)
        Journal.check_free(directory)  # another run writing it: refuse, touch nothing
        if Journal.exists(directory) and not resume:
            raise UsageError(
                f"{directory} holds the finished nodes of an interrupted run: "
                f"continue with --resume, or delete it or {FRESH} (which discards them)"
            )
        return cls(directory, files)

    def folder(self, name: str) -> Journaling:
        """The journaling of a folder of this journal (a round's, the held-out runs')."""
        return dataclasses.replace(self, directory=self.directory / name)

    def open(
        self, digest: str, size: int, outputs: Sequence[str], widths: Sequence[int]
    ) -> tuple[Journal, bool]:
        """The journal of ``size`` runs whose settings hash to ``digest``, and whether it is
        new."""
        fresh = not Journal.exists(self.directory)
        fingerprint = Fingerprint(digest, self.files)
        return Journal(self.directory, fingerprint, size, outputs, widths), fresh


@contextlib.contextmanager
def removed_if_rejected(journal: Journal | None, fresh: bool) -> Iterator[None]:
    """Remove a ``fresh`` journal when its campaign is rejected before any node ran, or the
    model is broken at every node: leave nothing behind (a journal would block a rerun)."""
    try:
        yield
    except (UsageError, ModelDefinitionError):
        if journal is not None and fresh:
            journal.remove()
        raise
