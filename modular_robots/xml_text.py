"""Text put into XML files (the URDF): one escaping function per context, so that a name from a
catalogue (``paper--v2``, ``x --><robot ...``) stays text and the file stays well-formed."""

from __future__ import annotations

import re
from xml.sax.saxutils import escape

__all__ = ["xml_attribute", "xml_comment"]

#: Characters XML 1.0 does not allow at all (control characters but tab, newline, return).
_NOT_XML = re.compile(r"[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_attribute(text: str) -> str:
    """``text`` for an attribute value between double quotes: ``&``, ``<``, ``>`` and ``"``
    escaped, characters XML cannot hold replaced by ``?``."""
    return escape(_NOT_XML.sub("?", text), {'"': "&quot;"})


def xml_comment(text: str) -> str:
    """``text`` for the inside of a comment, which may hold neither ``--`` nor end with ``-``:
    each ``-`` followed by another gets a space after it (``a--b`` becomes ``a- -b``)."""
    text = re.sub(r"-(?=-)", "- ", _NOT_XML.sub("?", text))
    return text + " " if text.endswith("-") else text
