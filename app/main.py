"""Entry point of ``corr-studio``.

The studio is built in its own issue; until then this entry point says so
instead of pretending to open a window.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    print("corr-studio: the desktop studio is not built yet; use the `corr` command "
          "(`corr demo`, `corr match`, `corr info`).", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
