#!/usr/bin/env bash
# Makes samples/models/three_balls/ (this folder) with `clothsr fit` (plan.json, report.md); committed are
# its plan, models, report and data-set manifests (task markers stay local). Delete the folder first to make
# it again (a fit whose tasks are done does nothing). CLOTHSR=path/to/clothsr chooses the binary.
set -euo pipefail
cd "$(dirname "$0")/../../.."
"${CLOTHSR:-clothsr}" fit samples/sheet_three_balls.usda -o samples/models/three_balls --quality preview --frames 90
