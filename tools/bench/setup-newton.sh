#!/usr/bin/env bash
# Create (or reuse) a private virtual environment for the Newton peer benchmark
# (tools/bench/newton_peer.py) and install Newton 1.8 with its CPU dependencies.
#
#   bash tools/bench/setup-newton.sh            # idempotent; safe to re-run
#   tools/bench/.venv-newton/bin/python tools/bench/newton_peer.py --res 3k,40k
#
# Only PyPI is needed. The venv lives in tools/bench/.venv-newton and carries its own
# .gitignore ("*") so git never sees it. Override the interpreter with PYTHON=...
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="${NEWTON_VENV:-$here/.venv-newton}"
python="${PYTHON:-python3}"
newton_spec="${NEWTON_SPEC:-newton==1.8.*}"

if [ ! -x "$venv/bin/python" ]; then
    echo "setup-newton: creating venv $venv" >&2
    "$python" -m venv "$venv"
fi
# Keep the venv out of git without touching the repository's .gitignore.
[ -f "$venv/.gitignore" ] || printf '*\n' > "$venv/.gitignore"

vpy="$venv/bin/python"
if "$vpy" - "$newton_spec" <<'PY' 2>/dev/null
import sys
from importlib.metadata import version
import warp, newton  # noqa: F401  (import check only)
v = version("newton")
spec = sys.argv[1]
want = spec.split("==", 1)[1].rstrip(".*") if "==" in spec else ""
sys.exit(0 if v.startswith(want) else 1)
PY
then
    echo "setup-newton: already installed: newton $("$vpy" -c 'from importlib.metadata import version as v; print(v("newton"), "warp-lang", v("warp-lang"))')" >&2
    exit 0
fi

echo "setup-newton: installing $newton_spec into $venv" >&2
"$vpy" -m pip install --quiet --upgrade pip
"$vpy" -m pip install --quiet "$newton_spec" warp-lang numpy
"$vpy" -c 'from importlib.metadata import version as v; print("setup-newton: installed newton", v("newton"), "warp-lang", v("warp-lang"))' >&2
