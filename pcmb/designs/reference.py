"""The list of node designs in ``docs/architecture.md``, generated from :data:`DESIGNS`.

``python -m pcmb.designs.reference docs/architecture.md`` rewrites the list between its two
markers and ``tests/test_architecture_docs.py`` checks that it is current. Each row is read
from the registry: the design key, the class and its module, whether it runs nodes, and the
first paragraph of the class's docstring. Nothing imports this module at start-up.
"""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

from pcmb.designs import DESIGNS
from pcmb.wording import markdown

__all__ = ["BEGIN", "END", "design_list", "main", "with_design_list"]

#: The markers around the generated list in the page.
BEGIN = (
    "<!-- The design list below is generated from pcmb.designs.DESIGNS: "
    "python -m pcmb.designs.reference docs/architecture.md -->"
)
END = "<!-- End of the generated design list. -->"


def _runs(design: type) -> str:
    if hasattr(design, "solve"):
        return "none (intrusive)"
    if hasattr(design, "more"):
        return "nodes, in rounds"
    return "nodes"


def design_list() -> str:
    """The Markdown table of every registered design, in registry order."""
    lines = ["| design key | class | runs | what it does |", "|---|---|---|---|"]
    for key, design in DESIGNS.items():
        module = design.__module__.removeprefix("pcmb.designs.")
        summary = markdown(inspect.getdoc(design).split("\n\n")[0]).replace("|", "\\|")
        lines.append(f"| `{key}` | `{module}.{design.__name__}` | {_runs(design)} | {summary} |")
    return "\n".join(lines) + "\n"


def with_design_list(page: str) -> str:
    """``page`` with the text between :data:`BEGIN` and :data:`END` replaced by the list.

    Raises
    ------
    ValueError
        The page lacks either marker.
    """
    start, stop = page.find(BEGIN), page.find(END)
    if start < 0 or stop < start:
        raise ValueError(f"the page lacks the markers {BEGIN!r} ... {END!r}")
    return f"{page[: start + len(BEGIN)]}\n{design_list()}{page[stop:]}"


def main() -> None:
    """Rewrite the design list of the page named by the first argument."""
    page = Path(sys.argv[1])
    page.write_text(with_design_list(page.read_text(encoding="utf-8")), encoding="utf-8")


if __name__ == "__main__":
    main()
