"""How the benchmark scripts end: a splatgl error as one line (exit 2), Ctrl-C as one line
(exit 130), as the ``splatgl`` commands do, instead of a traceback.

    if __name__ == "__main__":
        run(main)
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

from splatgl.errors import SplatglError


def run(main: Callable[[], object]) -> None:
    name = Path(sys.argv[0]).name
    try:
        main()
    except SplatglError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        sys.exit(130)
