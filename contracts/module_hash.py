"""The integrity rule of a generated controller module, shared by its producer and its consumer.

``codegen`` stamps every module it writes with ``MODULE_SHA256 = '<hex>'``: the sha256 of the
module's text with that value blanked. The runtime recomputes it before executing the module, so an
edited, truncated or appended file is refused. Both sides import this one definition.
"""

from __future__ import annotations

import hashlib
import re

#: the line prefix codegen writes and the runtime looks for
MODULE_SHA_PREFIX = "MODULE_SHA256 = "
#: the stamped self-hash line, and the line naming the artifact the module was generated from
MODULE_SHA_LINE = re.compile(r"^MODULE_SHA256 = '([0-9a-f]{64})'", re.MULTILINE)
ARTIFACT_SHA_LINE = re.compile(r"^ARTIFACT_SHA256 = '([0-9a-f]{64})'", re.MULTILINE)


def module_text_sha256(text: str) -> str:
    """sha256 (hex) of a generated module's text with its ``MODULE_SHA256`` value blanked.

    Parameters
    ----------
    text
        The module's full text (UTF-8, ``\\n`` line ends as codegen writes them).

    Returns
    -------
    str
        64 lowercase hex digits.
    """
    lines = text.split("\n")
    for k, line in enumerate(lines):
        if line.startswith(MODULE_SHA_PREFIX):
            lines[k] = MODULE_SHA_PREFIX + "''"
            break
    return hashlib.sha256("\n".join(lines).encode("utf-8")).hexdigest()
