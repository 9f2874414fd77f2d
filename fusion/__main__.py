"""``python -m fusion SUBCOMMAND ...``: the fusion package's commands.

* ``merge MAP MAP [MAP ...] --out DIR``: merge robots' saved maps (:func:`fusion.mapmerge.main`).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

COMMANDS = {"merge": "merge robots' saved occupancy maps into one (fusion.mapmerge)"}


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``argv[0]`` to its subcommand; returns the exit code (2 for an unknown one)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        listing = "\n".join(f"  {name:<8}{what}" for name, what in COMMANDS.items())
        usage = f"usage: python -m fusion COMMAND ...\ncommands:\n{listing}"
        if argv and argv[0] not in ("-h", "--help"):
            print(f"{usage}\npython -m fusion: error: unknown command {argv[0]!r}; expected "
                  f"one of {sorted(COMMANDS)}", file=sys.stderr)
            return 2
        print(usage, file=sys.stderr if not argv else sys.stdout)
        return 2 if not argv else 0
    from fusion.mapmerge import main as merge_main

    return merge_main(argv[1:], prog="python -m fusion merge")


if __name__ == "__main__":
    sys.exit(main())
