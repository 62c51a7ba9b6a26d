"""Locating the project's real recordings (``../shared/eval_data`` beside the checkout).

Tests that read them skip with a clear reason in a user's clone, and fail in CI (``CI`` set),
where ``../shared`` must be present.
"""

import os
from pathlib import Path

import pytest

EVAL = Path(__file__).resolve().parents[3] / "shared" / "eval_data"


def require(*parts: str) -> Path:
    """The path under ``eval_data``, or skip (outside CI) / fail (in CI) when it is missing."""
    path = EVAL.joinpath(*parts)
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{path} is missing: CI must run with ../shared beside the checkout")
        pytest.skip(f"{path} not present (it ships in the project's shared/ folder)")
    return path
