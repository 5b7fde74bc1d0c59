#!/bin/bash
# Fails when an option that an app's --help lists is missing from the CLI reference.
# usage: check_cli_doc.sh APPS_DIR CLI_DOC [APP ...]
#   APPS_DIR  the folder holding the built apps (build/release/apps)
#   CLI_DOC   the reference page (docs/CLI.md): one section "## APP" per app, every option
#             written in it as `--option` (or `-q`, `--option VALUE`, …)
#   APP ...   the apps to check (default: every desplat_* executable in APPS_DIR)
# Each option must appear in its own app's section, so an option documented under another app
# does not count. Prints every missing option as "APP: --option" and exits 1 if there is any.
set -uo pipefail
apps_dir=$1 doc=$2
shift 2
if [ ! -d "$apps_dir" ]; then echo "check_cli_doc: no apps folder '$apps_dir': build the apps first" >&2; exit 2; fi
if [ ! -f "$doc" ]; then echo "check_cli_doc: no CLI reference '$doc'" >&2; exit 2; fi
apps=("$@")
if [ ${#apps[@]} -eq 0 ]; then
  for f in "$apps_dir"/desplat_*; do [ -x "$f" ] && [ -f "$f" ] && apps+=("$(basename "$f")"); done
fi
if [ ${#apps[@]} -eq 0 ]; then echo "check_cli_doc: no desplat_* apps in '$apps_dir'" >&2; exit 2; fi

missing=0
for app in "${apps[@]}"; do
  if ! help=$("$apps_dir/$app" --help 2>&1); then
    echo "check_cli_doc: '$app --help' failed:" >&2; echo "$help" >&2; exit 2
  fi
  # The app's section: from its "## app" heading to the next "## " heading.
  section=$(awk -v h="## $app" '$0 == h {on = 1; next} on && /^## / {on = 0} on' "$doc")
  if [ -z "$section" ]; then echo "$app: no section '## $app' in $doc"; missing=1; continue; fi
  # Options are the lines of --help that start (after indentation) with a dash: "-q,--quiet",
  # "--data TEXT …", "--no-escalate{false} …". Every long and short name on such a line counts.
  options=$(echo "$help" | grep -E '^\s+-' | awk '{print $1}' | tr ',' '\n' |
            sed -E 's/\{.*//; s/=.*//' | grep -E '^-{1,2}[A-Za-z]' | grep -vE '^(-h|--help)$' | sort -u)
  for opt in $options; do
    # Written as code: `--opt`, `--opt VALUE`, `-q, --quiet`, … ; not a longer option's prefix.
    if ! grep -qE -- "(^|[^A-Za-z0-9-])${opt}([^A-Za-z0-9-]|$)" <<< "$section"; then
      echo "$app: $opt"
      missing=1
    fi
  done
done
if [ $missing -ne 0 ]; then
  echo "check_cli_doc: the options above are in --help but not in $doc; document them there" >&2
  exit 1
fi
echo "check_cli_doc: every option of ${apps[*]} is in $doc"
