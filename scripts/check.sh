#!/usr/bin/env bash
# The maintainers' checks beside the tests (run by .ci/run after the test command; the tools come with the `dev`
# extra that scripts/setup.sh installs): ruff (lint + import order), mypy (types) and the documentation site built
# with warnings as errors. Run from anywhere: bash scripts/check.sh
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PY=.venv/bin/python

"$PY" -m ruff check .

# mypy reads modules by their import names, bboxtune.filters ... (pyproject's package-dir maps them onto the top-level
# folders): it checks a view of the package, a temporary folder of links to those folders.
view=$(mktemp -d)
trap 'rm -rf "$view"' EXIT
mkdir "$view/bboxtune"
cp bboxtune/__init__.py "$view/bboxtune/"
for part in filters envs agents; do ln -s "$PWD/$part" "$view/bboxtune/$part"; done
"$PY" -m mypy --config-file pyproject.toml "$view/bboxtune"

"$PY" -m sphinx -W --keep-going -q -b html docs "$view/html"
echo "check.sh: ruff, mypy and the docs build are clean"
