"""A griffe extension for the API reference: a Google ``Example:`` section is rendered as code.

The project's docstrings head their doctests ``Example:`` (a section name Google style and
ruff's pydocstyle accept); griffe's Google parser knows only ``Examples:`` as the section
whose ``>>>`` lines are code, and reads ``Example:`` as an admonition of Markdown text, where
``infos[0]["outcome"]`` looks like a broken cross-reference. Renaming the heading before the
docstring is parsed keeps the source as it is.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_EXAMPLE_HEADING = re.compile(r"^(\s*)Example:\s*$", flags=re.MULTILINE)


class ExampleSections(griffe.Extension):
    """Read every ``Example:`` heading of a docstring as ``Examples:``."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        """Rename the heading in ``obj``'s docstring (parsing is lazy, so this comes first)."""
        if obj.docstring is not None:
            obj.docstring.value = _EXAMPLE_HEADING.sub(r"\1Examples:", obj.docstring.value)
