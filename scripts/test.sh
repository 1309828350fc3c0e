#!/usr/bin/env bash
# Run the lint and the whole test suite inside the project venv.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# shellcheck disable=SC1091
. "${COLORGLOVE_VENV:-$repo/.venv}/bin/activate"
cd "$repo"
ruff check .
python -m pytest "$@"
