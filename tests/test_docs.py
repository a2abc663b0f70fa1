"""The documentation site builds strictly: a broken link, anchor or API reference fails the suite.

``mkdocs build --strict`` turns every warning into a failure; ``mkdocs.yml``'s ``validation``
makes missing pages, anchors and unlisted pages warnings, and mkdocstrings warns on a
reference it cannot resolve. The build reads the docstrings statically (griffe), so it does
not import the packages.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    # the docs packages are in the [test] extra: missing, they fail here rather than skip the build
    packages = ("mkdocs", "material", "mkdocstrings_handlers")
    missing = [name for name in packages if importlib.util.find_spec(name) is None]
    assert not missing, f"{missing} not installed: pip install -e '.[test]'"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    out = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / "site" / "api" / "coop_gym" / "index.html").is_file()


def test_the_readme_is_a_front_door() -> None:
    """docs/STYLE.md, "The README is a front door": the rest is pages of the site."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines: move the detail to a page in docs/"
