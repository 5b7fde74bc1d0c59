#!/usr/bin/env bash
# Fails when a C++ file of the tree differs from what clang-format makes of it (.clang-format).
# Usage: scripts/check_format.sh [--fix]   (from anywhere; --fix rewrites the files instead)
# The layout is that of clang-format 14 (Debian 12's package, scripts/install_deps.sh); another
# major version formats differently, so with one the check is skipped (exit 77), not failed.
set -euo pipefail
cd "$(dirname "$0")/.."
cf=${CLANG_FORMAT:-clang-format}
if ! command -v "$cf" > /dev/null; then
  echo "clang-format not found: install it with scripts/install_deps.sh" >&2; exit 1
fi
major=$("$cf" --version | sed -n 's/.*version \([0-9]*\).*/\1/p')
if [ "$major" != 14 ]; then echo "clang-format $major is not 14: layout check skipped" >&2; exit 77; fi
mapfile -t files < <(find src include apps tests bench fuzz examples -type f \
  \( -name '*.cpp' -o -name '*.hpp' -o -name '*.inl' \) | sort)
if [ "${1:-}" = --fix ]; then "$cf" -i "${files[@]}"; exit 0; fi
log=$(mktemp)
if "$cf" --dry-run --Werror "${files[@]}" 2> "$log"; then
  rm -f "$log"; echo "${#files[@]} files follow .clang-format"; exit 0
fi
grep -o '^[^:]*:[0-9]*' "$log" | sort -u | head -40 >&2
echo "these lines differ from .clang-format; run scripts/check_format.sh --fix" >&2
rm -f "$log"; exit 1
