"""Build the API reference: one HTML page per public casecal module, from its docstrings.

    python docs/build_api.py            # writes docs/api/ (git-ignored)
    python docs/build_api.py -o DIR     # elsewhere

Uses only the standard library's `pydoc`, so it needs nothing beyond casecal's own
dependencies. A module is public when no part of its dotted name starts with ``_``.
``index.html`` lists them all with the first line of each docstring.
"""

from __future__ import annotations

import argparse
import html
import importlib
import pkgutil
import pydoc
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def public_modules(package: str = "casecal") -> list[str]:
    """Dotted names of the package and its public submodules, sorted."""
    pkg = importlib.import_module(package)
    names = [package]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=package + "."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def build(out: Path, package: str = "casecal") -> list[Path]:
    """Write one page per public module of `package` and an index into `out`; the pages."""
    out.mkdir(parents=True, exist_ok=True)
    doc = pydoc.HTMLDoc()
    pages, rows = [], []
    for name in public_modules(package):
        module = importlib.import_module(name)
        page = out / f"{name}.html"
        page.write_text(doc.page(pydoc.describe(module), doc.document(module, name)), "utf-8")
        pages.append(page)
        summary = (pydoc.getdoc(module).splitlines() or [""])[0]
        rows.append(f'<li><a href="{name}.html">{name}</a> {html.escape(summary)}</li>')
    body = f"<h1>{package} API reference</h1>\n<ul>\n" + "\n".join(rows) + "\n</ul>"
    (out / "index.html").write_text(doc.page(f"{package} API reference", body), "utf-8")
    return pages


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "docs" / "api")
    args = parser.parse_args(argv)
    pages = build(args.output)
    print(f"{len(pages)} module pages and index.html written to {args.output}", file=sys.stderr)


if __name__ == "__main__":
    main()
