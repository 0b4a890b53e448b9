"""MkDocs hook: Sphinx cross-reference roles in docstrings become links.

The docstrings use Sphinx roles (``:func:`bayescal.pipeline.run` ``), which
mkdocstrings leaves as text (``:func:<code>...</code>``). This hook turns each
into an optional mkdocs-autorefs reference: a link where the target is
documented, plain code otherwise (no warning). ``~`` shows the last name only.
"""

from __future__ import annotations

import re
from typing import Any

_ROLE = re.compile(r":(?:mod|func|class|meth|attr|data|exc|obj):<code>(~?)([\w.]+)(\(\))?</code>")


def _replace(match: re.Match[str]) -> str:
    short, identifier, call = match.group(1), match.group(2), match.group(3) or ""
    title = identifier.rsplit(".", 1)[-1] if short else identifier
    return f'<autoref identifier="{identifier}" optional><code>{title}{call}</code></autoref>'


def on_page_content(html: str, **kwargs: Any) -> str:
    """Rewrite the roles of one rendered page (runs before autorefs resolves links)."""
    return _ROLE.sub(_replace, html)
