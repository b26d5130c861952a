#!/usr/bin/env bash
# Makes samples/models/skirt/ (this folder) with `clothsr fit` (plan.json, report.md): the pencil
# skirt dressed on the walking avatar. Committed are its plan, models, report and
# data-set manifests (task markers stay local). Delete the folder first to make it again (a fit whose tasks are done does
# nothing). CLOTHSR=path/to/clothsr chooses the binary.
set -euo pipefail
cd "$(dirname "$0")/../../.."
"${CLOTHSR:-clothsr}" fit tests/data/patterns/mh_pencil_skirt/mh_pencil_skirt_specification.json --avatar tests/data/avatars/mh_walk_train_baked_2s.usdc -o samples/models/skirt --quality preview
