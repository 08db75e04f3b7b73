#!/usr/bin/env bash
# Fails when a tracked C++ file differs from .clang-format (Google style, 100 columns).
# estimators/forbidden/ holds the poison headers of the include boundary; they are not code.
# Usage: scripts/check_format.sh [--fix]
set -euo pipefail
cd "$(dirname "$0")/.."
fmt=$(command -v clang-format || command -v clang-format-14 || true)
if [ -z "$fmt" ]; then
  echo "check_format: error: clang-format not found (apt-get install clang-format)" >&2
  exit 1
fi
mapfile -t files < <(git ls-files '*.cc' '*.h' | grep -v '^estimators/forbidden/')
if [ "${1:-}" = "--fix" ]; then
  "$fmt" -i "${files[@]}"
  exit 0
fi
if ! "$fmt" --dry-run --Werror "${files[@]}" 2>/tmp/check_format.$$; then
  grep -E '^[^ ].*(warning|error):' /tmp/check_format.$$ | cut -d: -f1 | sort -u |
    sed 's/^/check_format: differs from .clang-format: /' >&2
  echo "check_format: run scripts/check_format.sh --fix" >&2
  rm -f /tmp/check_format.$$
  exit 1
fi
rm -f /tmp/check_format.$$
echo "check_format: ${#files[@]} files match .clang-format ($("$fmt" --version | grep -o '[0-9][0-9.]*' | head -1))"
