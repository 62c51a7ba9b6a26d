"""Prints the table of malformed point-cloud files and the error each gives (issue 7's must-show).

The cases are the ones ``tests/python/test_io.py`` asserts on (``MALFORMED``); this script writes
each to a temporary file, reads it with ``lidarcal.read_points`` and prints the exception type and
message as a Markdown table. Usage: ``python benches/malformed_files.py``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "python"))

import lidarcal
from test_io import MALFORMED


def main() -> None:
    print("| case | exception | message |")
    print("|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, filename, content, _, _ in MALFORMED:
            path = Path(tmp) / filename
            path.write_bytes(content)
            try:
                lidarcal.read_points(path)
            except Exception as e:  # the point is to show whatever is raised
                message = str(e).replace(tmp + "/", "").replace("|", "\\|")
                print(f"| {name} | `{type(e).__name__}` | {message} |")
            else:
                print(f"| {name} | (none: read without error) | |")
        missing = Path(tmp) / "missing.pcd"
        try:
            lidarcal.read_points(missing)
        except Exception as e:
            print(f"| missing file | `{type(e).__name__}` | {str(e).replace(tmp + '/', '')} |")


if __name__ == "__main__":
    main()
