#!/usr/bin/env bash
# Makes samples/models/table/ (this folder) with `clothsr fit` (plan.json, report.md); committed are
# its plan, models, report and data-set manifests (task markers stay local). Delete the folder first to make
# it again (a fit whose tasks are done does nothing). CLOTHSR=path/to/clothsr chooses the binary.
set -euo pipefail
cd "$(dirname "$0")/../../.."
"${CLOTHSR:-clothsr}" fit samples/sheet_table.usda -o samples/models/table --quality preview --frames 90
