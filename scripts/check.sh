#!/usr/bin/env bash
# The whole test suite, from a fresh clone: sets up a virtualenv with the Python tools, builds the
# wheel once (release), and runs every check. Usage: bash scripts/check.sh
# Environment: VENV (default .venv) chooses the virtualenv; SKIP_SETUP=1 skips pip installs.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${VENV:-.venv}
step() { printf '\n==> %s\n' "$*"; }

step "python environment ($VENV)"
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
fi
# Absolute, so VENV may be relative or absolute (PYO3_PYTHON and pytest run from other dirs).
VENV=$(cd "$VENV" && pwd)
PY="$VENV/bin/python"
if [ "${SKIP_SETUP:-0}" != 1 ]; then
    "$PY" -m pip install --quiet --upgrade pip
    "$PY" -m pip install --quiet "maturin>=1.7,<2" "numpy>=1.22" "scipy>=1.9" "pytest>=7" "ruff>=0.6" "mypy>=1.10" "click>=8" "matplotlib>=3.6" "rosbags>=0.10" "pyyaml>=6" "types-PyYAML" "hypothesis>=6" "dask[distributed]>=2024.1" "pyarrow>=14" "tqdm>=4.60" "types-tqdm" "mkdocs-material>=9.5" "mkdocstrings[python]>=0.26"
fi

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, all features)"
PYO3_PYTHON="$PY" cargo clippy --all-targets --all-features --quiet -- -D warnings

step "cargo test"
cargo test --quiet

step "cargo doc (warnings are errors: broken intra-doc links)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --quiet

step "no default features (embedded: no rayon, file formats or simulator)"
# Every target must build and lint clean without the defaults (tests and benches that need the
# simulator or the file formats are gated on them), and the rest of the suite must pass on the
# sequential code paths. The crate and its tests are rebuilt for these features (about 75 s on
# two cores); the dependencies are the default build's.
cargo clippy --no-default-features --all-targets --quiet -- -D warnings
cargo test --no-default-features --quiet
if cargo tree --no-default-features -e normal --prefix none | grep -Eq '^(pyo3|numpy|rayon|lzf|rand_distr) '; then
    echo "error: the no-default-features build pulls in pyo3, numpy, rayon, lzf or rand_distr" >&2
    exit 1
fi

step "build and install the wheel (release)"
rm -rf target/wheels
"$VENV/bin/maturin" build --release --quiet --interpreter "$PY" --out target/wheels
"$PY" -m pip install --quiet --force-reinstall --no-deps target/wheels/lidarcal-*.whl

step "ruff"
"$VENV/bin/ruff" check python tests/python benches
"$VENV/bin/ruff" format --check python tests/python benches

step "mypy"
"$VENV/bin/mypy"

step "stubtest (the stubs against the installed wheel)"
# Compares python/lidarcal/_lidarcal.pyi (and the typed .py modules) with what the built extension
# really exports: names, signatures, defaults, @final. Run from the repository root, where
# `import lidarcal` finds the installed wheel (the source tree is under python/).
"$PY" -m mypy.stubtest lidarcal --allowlist stubtest_allowlist.txt

step "docs (mkdocs build --strict)"
# Warnings are errors: a broken link or an API reference that does not resolve fails. The API
# page is read from python/lidarcal (sources and stubs), not from the installed wheel. The site
# goes to a temporary directory, so the tree stays clean. (No --quiet: it hides the warnings from
# --strict, which then passes a broken link.)
SITE=$(mktemp -d)
NO_MKDOCS_2_WARNING=1 "$VENV/bin/mkdocs" build --strict --site-dir "$SITE"
rm -rf "$SITE"

step "pytest"
# Run from tests/ so `import lidarcal` resolves to the installed wheel, not the source tree.
(cd tests/python && "$PY" -m pytest -q -c ../../pyproject.toml --rootdir ../..)
