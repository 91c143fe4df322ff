"""Full-page screenshot of a report in headless Chromium (the README's docs/report.png):

python -m opfbench.report.screenshot reports/run/report.html docs/report.png [--width 1400]
"""

from __future__ import annotations

import argparse
import subprocess
import sys

from opfbench.errors import OpfbenchError
from opfbench.report.browser import screenshot


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.report.screenshot", description=__doc__.splitlines()[0])
    parser.add_argument("html")
    parser.add_argument("png")
    parser.add_argument("--width", type=int, default=1400, help="window width in px (default 1400)")
    parser.add_argument("--max-height", type=int, default=30000, help="cap on the page height in px (default 30000)")
    args = parser.parse_args(argv)
    try:
        print(screenshot(args.html, args.png, args.width, args.max_height))
    except (OpfbenchError, OSError) as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    except (subprocess.TimeoutExpired, RuntimeError) as exc:
        print(f"{parser.prog}: Chromium failed: {str(exc).splitlines()[0][:300]}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
