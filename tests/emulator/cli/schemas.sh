#!/usr/bin/env bash
# docs/schemas/*.schema.json are what `wheelhil schema` makes from the loaders today (else:
# regenerate them with `wheelhil schema --out-dir docs/schemas` and commit), and Debian's
# python3-jsonschema finds every shipped file valid against them and misspelt keys invalid
# (schema_validation.py).
# Usage: schemas.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$wheelhil" schema --out-dir "$work" || { echo "FAIL: wheelhil schema --out-dir"; exit 1; }
status=0
for f in "$work"/*.schema.json; do
  name=$(basename "$f")
  if ! cmp -s "$f" "$src/docs/schemas/$name"; then
    echo "FAIL: docs/schemas/$name is not what the loaders make today; regenerate:"
    echo "  wheelhil schema --out-dir docs/schemas"
    diff "$src/docs/schemas/$name" "$f" | head -20
    status=1
  fi
done
[ "$(ls "$src/docs/schemas" | wc -l)" -eq "$(ls "$work" | wc -l)" ] ||
  { echo "FAIL: docs/schemas has other files than wheelhil schema writes"; status=1; }
if ! /usr/bin/python3 -c "import jsonschema, yaml" 2>/dev/null; then
  echo "FAIL: python3-jsonschema is not installed (./hil setup installs it)"
  exit 1
fi
/usr/bin/python3 "$src/tests/emulator/cli/schema_validation.py" "$src/docs/schemas" "$src" || status=1
exit $status
