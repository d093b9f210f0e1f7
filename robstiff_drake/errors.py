"""The one error type that the command line turns into a one-line message
and exit status 2 (bad input: a file, a value, a key)."""


class InputError(Exception):
    """Bad input from the user. The message says what is wrong and where."""


class OutputError(InputError):
    """An output that cannot be written (one line, exit status 2)."""


class SingularPoseError(ValueError):
    """A stiffness-form quantity was asked for where J is not invertible.

    Attributes:
        joints: 1-based joint numbers that take part in the lost direction.
    """

    def __init__(self, message, joints):
        super().__init__(message)
        self.joints = tuple(joints)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every cleanup runs (a
    temporary file or folder removed, a worker pool stopped); a long-running
    command (compensate) ends its run on it as on Ctrl-C."""


# Characters that would break a one-line message or hide text in a terminal:
# line and paragraph separators, the other C0 and C1 controls (tab stays).
_BREAKING = {c: f"\\x{c:02x}" for c in (*range(0x00, 0x09), *range(0x0a, 0x20), 0x7f, *range(0x80, 0xa0))}
_BREAKING.update({0x0a: "\\n", 0x0d: "\\r", 0x0b: "\\v", 0x0c: "\\f", 0x2028: "\\u2028", 0x2029: "\\u2029",
                  0x85: "\\x85"})


def one_line(text):
    """``text`` with every character that would start a new line (or
    control the terminal) escaped: a file name with a newline in it stays
    one line in an error or a warning."""
    return str(text).translate(_BREAKING)


def excerpt(value, limit=60):
    """A short, escaped excerpt of a value read from a file (at most about
    ``limit`` characters), for error messages: a file's content is never
    echoed beyond this, whatever its size or nesting."""
    if isinstance(value, str):
        text = one_line(value)
        return "'" + (text[:limit] + "..." if len(text) > limit else text) + "'"
    parts = []
    _repr_into(value, parts, [limit])
    return one_line("".join(parts))


def _repr_into(value, parts, budget):
    """repr of ``value`` into ``parts`` until ``budget[0]`` characters are
    spent (a huge or deeply nested list is never turned into text whole)."""
    if budget[0] <= 0:
        parts.append("...")
        return
    if isinstance(value, (list, tuple, dict)):
        items = list(value.items()) if isinstance(value, dict) else value
        opening, closing = ("{", "}") if isinstance(value, dict) else ("[", "]")
        parts.append(opening)
        budget[0] -= 1
        for i, item in enumerate(items):
            if budget[0] <= 0:
                parts.append("...")
                break
            if i:
                parts.append(", ")
                budget[0] -= 2
            if isinstance(value, dict):
                _repr_into(item[0], parts, budget)
                parts.append(": ")
                item = item[1]
            _repr_into(item, parts, budget)
        parts.append(closing)
        return
    text = repr(value)
    if len(text) > budget[0]:
        text = text[:max(budget[0], 8)] + "..."
    budget[0] -= len(text)
    parts.append(text)


INTERRUPTED = 130  # the exit status of a Ctrl-C (128 + SIGINT)


def interrupted(exc):
    """Whether ``exc`` is, or was raised while handling, a KeyboardInterrupt."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False
