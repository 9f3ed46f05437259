#!/usr/bin/env bash
# Regenerate every picture README.md and docs/ embed, from the code of this checkout:
#
#   docs/img/trial-report-envelopes.png  the first figure of the report.html of
#   docs/img/trial-report-metrics.png    the second one   (docs/COMMANDS.md, "Trial reports")
#       pressor trial --controller lpv,pi,smith --patients 20 --seed 2026
#                     --scenario paper-disturbance --report --out DIR
#   docs/img/viewer.png  the whole hour of `pressor sil --rrd sil.rrd` in rerun's web viewer,
#       photographed by scripts/viewer_screenshot.py (docs/VIEWER.md)
#
# Usage, from anywhere, with the project installed (pip install -e ".[test]"):
#
#   scripts/docs_images.sh                 # all three (about 5 minutes on 2 cores)
#   scripts/docs_images.sh --no-viewer     # the trial-report figures only
#
# The viewer screenshot needs Chromium at /usr/bin/chromium (Debian: apt-get install chromium;
# CHROMIUM=PATH for another one) and Playwright's Python package (pip install -e ".[screenshot]").
# This script installs nothing: it checks both before it starts and stops, exit 2, naming what is
# missing. PYTHON=PATH picks the interpreter (default: python3 on PATH).
set -euo pipefail

cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
CHROMIUM="${CHROMIUM:-/usr/bin/chromium}"
viewer=1
case "${1:-}" in
"") ;;
--no-viewer) viewer=0 ;;
*)
    echo "usage: scripts/docs_images.sh [--no-viewer]" >&2
    exit 2
    ;;
esac

missing=()
"$PYTHON" -c "import pressor, matplotlib" 2>/dev/null ||
    missing+=("the project in $PYTHON (pip install -e \".[test]\")")
if ((viewer)); then
    [[ -x "$CHROMIUM" ]] ||
        missing+=("Chromium at $CHROMIUM (Debian: apt-get install chromium; or CHROMIUM=PATH)")
    "$PYTHON" -c "import playwright" 2>/dev/null ||
        missing+=("Playwright in $PYTHON (pip install -e \".[screenshot]\")")
fi
if ((${#missing[@]})); then
    echo "scripts/docs_images.sh: missing, nothing was regenerated:" >&2
    printf '  - %s\n' "${missing[@]}" >&2
    ((viewer)) && echo "  (--no-viewer makes the trial-report figures without a browser)" >&2
    exit 2
fi

# rerun (the viewer's server) and pressor from the same environment as the interpreter
PATH="$(dirname "$("$PYTHON" -c 'import sys; print(sys.executable)')"):$PATH"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export CI=1 # the rerun CLI writes analytics files otherwise

echo "trial report: docs/img/trial-report-envelopes.png, docs/img/trial-report-metrics.png" >&2
"$PYTHON" -m pressor trial --controller lpv,pi,smith --patients 20 --seed 2026 \
    --scenario paper-disturbance --report --out "$work/trial" >/dev/null
"$PYTHON" - "$work/trial/report.html" docs/img/trial-report-envelopes.png \
    docs/img/trial-report-metrics.png <<'EOF'
import base64
import re
import sys
from pathlib import Path

report, *outs = sys.argv[1:]
figures = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', Path(report).read_text())
if len(figures) < len(outs):
    sys.exit(f"{report}: {len(figures)} figures, expected at least {len(outs)}")
for out, figure in zip(outs, figures, strict=False):
    Path(out).write_bytes(base64.b64decode(figure))
EOF

if ((viewer)); then
    echo "viewer: docs/img/viewer.png (the recording loads for about 3 minutes)" >&2
    "$PYTHON" -m pressor sil --rrd "$work/sil.rrd" >/dev/null
    "$PYTHON" scripts/viewer_screenshot.py "$work/sil.rrd" docs/img/viewer.png \
        --chromium "$CHROMIUM" --wait-s 200
fi
echo "regenerated; git diff --stat docs/img shows what changed" >&2
