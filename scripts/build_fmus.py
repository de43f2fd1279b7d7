"""Build the example FMUs of models/fmu/ with pythonfmu (``pip install "pcmb[fmu]" pythonfmu``).

    python scripts/build_fmus.py [DEST]

Every ``models/fmu/<Name>.py`` holds one pythonfmu slave class ``<Name>``; it becomes
``DEST/<Name>.fmu`` (default DEST: ``models/fmu/build``, where configs/fmu_oscillator.yaml
looks for it). An FMU built by pythonfmu runs its Python class in the process that loads it,
so the Python that runs pcmb needs pythonfmu too.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

SOURCES = Path(__file__).resolve().parents[1] / "models" / "fmu"


def build(dest: Path) -> list[Path]:
    """Build every slave of models/fmu/ into ``dest``; the FMUs' paths."""
    from pythonfmu import FmuBuilder

    dest.mkdir(parents=True, exist_ok=True)
    return [FmuBuilder.build_FMU(source, dest=dest) for source in sorted(SOURCES.glob("*.py"))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dest", nargs="?", type=Path, default=SOURCES / "build")
    args = parser.parse_args(argv)
    for path in build(args.dest):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
