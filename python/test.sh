#!/usr/bin/env bash
# The Python half of README's test command: builds the package (maturin, release profile,
# the repository's target folder) into a virtual environment this script creates, then
# runs the Python tests. Needs python3 3.11 or newer (the pinned JAX's minimum; the package
# itself runs on 3.9) with venv and pip reaching PyPI; the versions are pinned in
# python/requirements.txt.
#
# The environment lives in target/python-venv and is made anew when requirements.txt
# changes. Tests that need ../shared/data (or $DIFFSVG_DATA) skip with a printed reason
# when it is absent, or fail with DIFFSVG_REQUIRE_DATA=1.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV="$PWD/target/python-venv"

SECONDS=0
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    echo "python/test.sh: $PYTHON is missing or older than 3.11 (set PYTHON=...)" >&2
    exit 2
fi
if ! cmp -s python/requirements.txt "$VENV/requirements.txt" 2>/dev/null; then
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
        -r python/requirements.txt
    cp python/requirements.txt "$VENV/requirements.txt"
fi

venv_s=$SECONDS
# The command-line binary the tests compare with. `cargo test --release` (run first by
# README's test command) leaves it fresh; built here when it is missing or older than the
# sources (a plain build would compile the library again: the tests' dev-dependencies
# turn on features of shared crates, so the two builds differ).
bin=target/release/diffsvg
if [ ! -x "$bin" ] || [ -n "$(find src Cargo.toml Cargo.lock -newer "$bin" -print -quit)" ]; then
    cargo build --release --quiet
fi
# The wheel, as `pip install` would get it; installed over any earlier one.
rm -rf target/wheels
"$VENV/bin/maturin" build --release --quiet -m python/Cargo.toml \
    --interpreter "$VENV/bin/python" -o target/wheels
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
    --force-reinstall target/wheels/diffsvg-*.whl
wheel_s=$((SECONDS - venv_s))
# From the tests' folder, so that `import diffsvg` finds the installed wheel, not python/.
cd python/tests
# A test still running after 120 s prints every thread's Python stack (not stopped).
"$VENV/bin/python" -m pytest -q -p no:cacheprovider -o faulthandler_timeout=120 "$@"
echo "python/test.sh: environment ${venv_s}s, wheel ${wheel_s}s, tests $((SECONDS - venv_s - wheel_s))s"
