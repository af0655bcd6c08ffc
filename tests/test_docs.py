"""The documentation: the API pages build by their one command, the README's references resolve."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import casecal

ROOT = Path(__file__).resolve().parent.parent


def test_api_pages_build(tmp_path):
    out = tmp_path / "api"
    subprocess.run(
        [sys.executable, str(ROOT / "docs" / "build_api.py"), "-o", str(out)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    module = casecal.identify.__module__  # casecal.identification.fit
    page = (out / f"{module}.html").read_text("utf-8")
    assert "identify" in page and "Parameters" in page  # the numpy-style docstring
    index = (out / "index.html").read_text("utf-8")
    assert f'href="{module}.html"' in index
    assert not any(p.name.startswith("casecal._") or "._" in p.name for p in out.iterdir())


def test_readme_references_resolve():
    readme = (ROOT / "README.md").read_text("utf-8")
    assert "shared/" not in readme and "DESIGN.md" not in readme
    for target in re.findall(r"\]\(([^)#]+)\)", readme):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), target
    for path in re.findall(r"`((?:docs|examples|studies|tests|casecal)/[\w./-]+)`", readme):
        assert path == "docs/api/" or (ROOT / path).exists(), path  # docs/api/ is built
