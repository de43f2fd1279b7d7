"""``docs/architecture.md``: its design list generated from the registry and current, its
package table complete."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from pcmb.designs import DESIGNS
from pcmb.designs.reference import BEGIN, END, design_list, with_design_list

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "architecture.md"
REGENERATE = "python -m pcmb.designs.reference docs/architecture.md"


def test_the_design_list_is_current():
    page = PAGE.read_text(encoding="utf-8")
    assert with_design_list(page) == page, f"the design list is out of date: run `{REGENERATE}`"


def test_the_page_says_how_the_list_is_made():
    assert REGENERATE in BEGIN and BEGIN in PAGE.read_text(encoding="utf-8")


def test_every_registered_design_has_a_row_naming_its_class():
    rows = [line for line in design_list().splitlines() if line.startswith("| `")]
    assert [row.split("`")[1] for row in rows] == list(DESIGNS)
    for row, design in zip(rows, DESIGNS.values(), strict=True):
        assert f".{design.__name__}`" in row


def test_the_list_replaces_only_the_text_between_its_markers():
    page = f"before\n{BEGIN}\nstale\n{END}\nafter\n"
    assert with_design_list(page) == f"before\n{BEGIN}\n{design_list()}{END}\nafter\n"


def test_the_module_rewrites_the_page_it_is_given(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(f"# Page\n{BEGIN}\n{END}\n", encoding="utf-8")
    command = [sys.executable, "-m", "pcmb.designs.reference", str(page)]
    subprocess.run(command, check=True, cwd=ROOT)
    assert page.read_text(encoding="utf-8") == f"# Page\n{BEGIN}\n{design_list()}{END}\n"


def test_the_package_table_has_a_row_for_every_package_and_module():
    page = PAGE.read_text(encoding="utf-8")
    package = ROOT / "pcmb"
    parts = [f"pcmb/{p.name}/" for p in package.iterdir() if (p / "__init__.py").is_file()]
    parts += [f"pcmb/{p.name}" for p in package.glob("*.py") if p.name != "__init__.py"]
    missing = [part for part in sorted(parts) if f"\n| `{part}` |" not in page]
    assert not missing, f"docs/architecture.md's package table lacks {missing}"
