"""The generated blocks of the docs: the text between ``<!-- generated:
NAME -->`` and ``<!-- end NAME -->`` replaced by a study's output (the
studies that write docs/diagnosis.md's tables with ``--docs``)."""

import re
import sys


def replace_block(text, name, body, doc="docs/diagnosis.md"):
    """``text`` with block ``name``'s contents replaced by ``body`` (one
    newline after it); exits naming ``doc`` when the block is not there."""
    new, n = re.subn(rf"(<!-- generated: {re.escape(name)} -->\n)(?:.*?\n)?(<!-- end {re.escape(name)} -->)",
                     lambda m: m.group(1) + body + "\n" + m.group(2), text, flags=re.S)
    if n != 1:
        sys.exit(f"{doc} has no {name} block")
    return new


def write_block(path, name, body):
    """Replace block ``name`` of the file ``path`` by ``body`` and say so."""
    path.write_text(replace_block(path.read_text(), name, body, doc=f"docs/{path.name}"))
    print(f"wrote {path}")
