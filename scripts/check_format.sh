#!/usr/bin/env bash
# Checks C++ files against the package's .clang-format without changing them: prints the files
# clang-format would change and exits 1 if there are any, 0 if none, 2 on a usage error or when
# clang-format is missing. Arguments: files or folders (default: src include test); --diff also
# prints what would change. CLANG_FORMAT picks the binary (default: clang-format).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
STYLE="$ROOT/.clang-format"
CLANG_FORMAT="${CLANG_FORMAT:-clang-format}"

show_diff=0
paths=()
for arg in "$@"; do
  case "$arg" in
    --diff) show_diff=1 ;;
    -h|--help) sed -n '2,5p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "check_format: unknown option '$arg'" >&2; exit 2 ;;
    *) paths+=("$arg") ;;
  esac
done
[[ ${#paths[@]} -gt 0 ]] || paths=("$ROOT/src" "$ROOT/include" "$ROOT/test")

if ! command -v "$CLANG_FORMAT" >/dev/null 2>&1; then
  echo "check_format: '$CLANG_FORMAT' not found (Debian package clang-format)" >&2
  exit 2
fi

files=()
for path in "${paths[@]}"; do
  if [[ -d "$path" ]]; then
    while IFS= read -r -d '' f; do files+=("$f"); done < <(
      find "$path" -type f \( -name '*.cpp' -o -name '*.h' -o -name '*.hpp' -o -name '*.cc' \) -print0 | sort -z)
  elif [[ -f "$path" ]]; then
    files+=("$path")
  else
    echo "check_format: no such file or folder: $path" >&2
    exit 2
  fi
done

formatted="$(mktemp)"
trap 'rm -f "$formatted"' EXIT
differ=0
for f in "${files[@]}"; do
  if ! "$CLANG_FORMAT" --style="file:$STYLE" "$f" >"$formatted"; then
    echo "check_format: clang-format failed on $f" >&2
    exit 2
  fi
  if ! cmp -s "$formatted" "$f"; then
    echo "${f#"$ROOT"/}"
    differ=$((differ + 1))
    if [[ $show_diff -eq 1 ]]; then diff -u "$f" "$formatted" || true; fi
  fi
done

if [[ $differ -gt 0 ]]; then
  echo "check_format: $differ of ${#files[@]} files differ from .clang-format (fix: clang-format -i FILE)" >&2
  exit 1
fi
echo "check_format: ${#files[@]} files follow .clang-format"
