#!/usr/bin/env bash
# The Python package: build it into a virtual environment (.venv, or $GRIN_VENV) with
# maturin from this checkout, on the workspace's own build (the dev profile, sharing
# target/ with cargo). `bash scripts/python.sh test` also runs its pytest tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
venv="${GRIN_VENV:-$PWD/.venv}"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q --disable-pip-version-check \
  "maturin>=1.9,<2" "numpy>=1.21" "pytest>=7" "OpenEXR>=3.3" "ray>=2.9" openjd-cli
(cd crates/grin-py && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --locked -q)
echo "python: grin $("$venv/bin/python" -c 'import grin; print(grin.__version__)') in $venv" >&2
if [ "${1:-}" = test ]; then
  # The tests compare with the CLI: the binary of this build ($GRIN_BIN: scripts/test.sh
  # passes the one its cargo test built, which a plain `cargo build` would build again
  # with other features).
  if [ -z "${GRIN_BIN:-}" ]; then
    cargo build --locked -p grin-cli
    export GRIN_BIN="$PWD/target/debug/grin"
  fi
  export NODEVICE_SELECT="${NODEVICE_SELECT:-1}"
  export GRIN_CACHE_DIR="${GRIN_CACHE_DIR:-$(mktemp -d)}"
  "$venv/bin/python" -m pytest -q crates/grin-py/tests
fi
