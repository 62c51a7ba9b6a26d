"""Prints the bad-input battery of tests/python/test_bad_input.py as a markdown table.

Usage: python benches/bad_input_table.py  (with the lidarcal wheel installed)

Each row runs one case and shows the exception raised and its message, as a user would see them.
A row marked "UNEXPECTED" raised something other than what the test expects.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "python"))

from test_bad_input import CASES, run_case


def main() -> int:
    print("| case | exception | message |")
    print("|---|---|---|")
    unexpected = 0
    for case in CASES:
        kind, message = run_case(case)
        ok = kind == case.exception.__name__ and case.fragment in message
        unexpected += not ok
        flag = "" if ok else " **UNEXPECTED**"
        message = message.replace("|", "\\|").replace("\n", " ")
        if len(message) > 240:
            message = message[:237] + "..."
        print(f"| {case.name} | `{kind}`{flag} | {message} |")
    print(f"\n{len(CASES)} cases, {unexpected} unexpected", file=sys.stderr)
    return 1 if unexpected else 0


if __name__ == "__main__":
    raise SystemExit(main())
