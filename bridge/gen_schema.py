"""Regenerates clothsr_usd/schemas/generatedSchema.usda and plugInfo.json from schema.usda there.

Run with the project venv (needs jinja2): `.venv/bin/python bridge/gen_schema.py [OUT_DIR]`.
usd-core ships usdGenSchema.py inside the wheel; with skipCodeGeneration it writes only the
codeless files, whose @PLUG_INFO_*@ placeholders we fill for a resource-only plugin.
"""
import os
import pathlib
import subprocess
import sys

import pxr

HERE = pathlib.Path(__file__).resolve().parent
SCHEMAS = HERE / "clothsr_usd" / "schemas"


def main() -> int:
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else SCHEMAS
    out.mkdir(parents=True, exist_ok=True)
    gen = pathlib.Path(pxr.__file__).parent / "Usd" / "usdGenSchema.py"
    subprocess.run([sys.executable, str(gen), str(SCHEMAS / "schema.usda"), str(out)], check=True)
    info = out / "plugInfo.json"
    text = info.read_text()
    for key, value in {
        "@PLUG_INFO_LIBRARY_PATH@": "",
        "@PLUG_INFO_RESOURCE_PATH@": ".",
        "@PLUG_INFO_ROOT@": ".",
    }.items():
        text = text.replace(key, value)
    info.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
