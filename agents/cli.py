"""One-line usage errors for the tyro command lines of ``agents`` (``python -m agents.dataset``).

tyro reports a bad flag in a box of several lines (the error, the flag's help, a pointer to
``--help``); a script or a log wants one line, ``PROG: error: MESSAGE``, as argparse and this
package's own setting checks print. :func:`one_line_errors` turns the box into that line.
"""

from __future__ import annotations

import contextlib
import io
import sys
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

_FRAME = "│|╭╮╰╯"
_RULE = set("─━═- ")


def condense(text: str) -> str:
    """The message of a tyro error on one line: its title and the lines above its first rule,
    without the flags' help text (the deeper-indented lines). tyro draws it in a box on a
    terminal and without the frame elsewhere; text that is neither is returned with its
    whitespace collapsed."""
    lines = [line.rstrip().strip(_FRAME).rstrip() for line in text.splitlines()]
    lines = [line for line in lines if line.strip()]
    if not lines:
        return ""
    title, body = lines[0].strip("╭╮─- "), lines[1:]
    if body and set(body[0].strip()) <= _RULE:  # frameless: a rule under the title
        body = body[1:]
    parts: list[str] = []
    base = None
    for line in body:
        if set(line.strip()) <= _RULE:
            break
        indent = len(line) - len(line.lstrip())
        base = indent if base is None else base
        if indent - base <= 4:  # the message and flag names, not their help
            parts.append(line.strip())
    if not parts:
        return " ".join(text.split())
    message = " ".join(" ".join(parts).split())
    return message if title.lower() in message.lower() else f"{title.lower()}: {message}"


def one_line_errors(parse: Callable[[], T], prog: str) -> T:
    """``parse()`` (a tyro call) with its usage error printed as the one line ``PROG: error:
    MESSAGE`` on stderr (:func:`condense`), exit status 2. ``--help`` and a successful parse
    print what they always print."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            result = parse()
    except SystemExit as exc:
        if exc.code not in (0, None):
            print(f"{prog}: error: {condense(captured.getvalue())}", file=sys.stderr)
            raise SystemExit(2) from None
        sys.stderr.write(captured.getvalue())
        raise
    except BaseException:
        sys.stderr.write(captured.getvalue())
        raise
    sys.stderr.write(captured.getvalue())
    return result
