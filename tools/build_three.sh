#!/usr/bin/env bash
# Rebuild src/meshmocap/apps/report/assets/three.min.js, the three.js build inlined in HTML
# reports: the classes listed in tools/three_entry.js, GLTFLoader and OrbitControls, bundled
# and minified by esbuild into one classic script that defines window.MMTHREE. Needs node and
# npm (the npm registry); the project itself needs neither.
#   bash tools/build_three.sh            # three@0.187.0, esbuild@0.28.2
set -euo pipefail
cd "$(dirname "$0")/.."
THREE="${THREE_VERSION:-0.187.0}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cp tools/three_entry.js "$work/entry.js"
(cd "$work" && npm init -y >/dev/null && npm install --silent --no-audit --no-fund \
    "three@$THREE" esbuild@0.28.2)
assets=src/meshmocap/apps/report/assets
cp "$work/node_modules/three/LICENSE" "$assets/three.LICENSE.txt"
{
    printf '/*! three.js %s (npm three@%s): GLTFLoader, OrbitControls and the core classes\n' \
        "r$(echo "$THREE" | cut -d. -f2)" "$THREE"
    printf ' * the meshmocap report player uses, bundled by tools/build_three.sh.\n *\n'
    sed 's/^/ * /; s/ *$//' "$work/node_modules/three/LICENSE"
    printf ' */\n'
} > "$work/banner.txt"
"$work/node_modules/.bin/esbuild" "$work/entry.js" --bundle --minify --format=iife \
    --global-name=MMTHREE --legal-comments=none --banner:js="$(cat "$work/banner.txt")" \
    --outfile="$assets/three.min.js"
echo "wrote $assets/three.min.js ($(wc -c < "$assets/three.min.js") bytes)"
