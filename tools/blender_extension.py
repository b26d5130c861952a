"""Builds clothsr's Blender extension (Blender 4.2 and later): dcc/blender with the clothsr
wheel bundled, as one zip to install with Edit > Preferences > Get Extensions > Install from
Disk (or ``blender --command extension install-file``).

    python tools/blender_extension.py [--wheel WHEEL] [-o DIR]

Without ``--wheel`` it builds the wheel first (``maturin build --release``, the project's
``.venv``, made by ``bash .ci/setup``). Writes ``DIR/clothsr-VERSION-linux_x64.zip`` (default
DIR: ``dist``) and prints its path.
"""

import argparse
import pathlib
import re
import subprocess
import sys
import tempfile
import zipfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
SOURCE = ROOT / "dcc" / "blender"
PLATFORM = "linux-x64"


def version() -> str:
    text = (ROOT / "Cargo.toml").read_text()
    found = re.search(r'^\[workspace\.package\][^\[]*?^version\s*=\s*"([^"]+)"', text, re.M | re.S)
    if not found:
        found = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
    if not found:
        raise SystemExit(f"{ROOT / 'Cargo.toml'}: no version")
    return found.group(1)


def build_wheel(out: pathlib.Path) -> pathlib.Path:
    maturin = ROOT / ".venv" / "bin" / "maturin"
    python = ROOT / ".venv" / "bin" / "python"
    if not maturin.exists():
        raise SystemExit(f"{maturin} is missing: run `bash .ci/setup`, or pass --wheel")
    subprocess.run(
        [str(maturin), "build", "--release", "-i", str(python), "-o", str(out)], cwd=ROOT, check=True
    )
    wheels = sorted(out.glob("clothsr-*.whl"))
    if len(wheels) != 1:
        raise SystemExit(f"{out}: expected one clothsr wheel, found {[w.name for w in wheels]}")
    return wheels[0]


def build(wheel: pathlib.Path, out_dir: pathlib.Path) -> pathlib.Path:
    if not re.search(r"-abi3-(manylinux[^-]*_x86_64|linux_x86_64)\.whl$", wheel.name):
        raise SystemExit(f"{wheel}: not an abi3 wheel for {PLATFORM}")
    ver = version()
    manifest = (SOURCE / "blender_manifest.toml").read_text()
    manifest = manifest.replace("@VERSION@", ver).replace("@WHEEL@", f"./wheels/{wheel.name}")
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"clothsr-{ver}-{PLATFORM.replace('-', '_')}.zip"
    tmp = target.with_name(f".{target.name}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("blender_manifest.toml", manifest)
        for path in sorted(SOURCE.rglob("*")):
            if path.is_file() and path.name != "blender_manifest.toml" and "__pycache__" not in path.parts:
                z.write(path, path.relative_to(SOURCE).as_posix())
        z.write(wheel, f"wheels/{wheel.name}")
    tmp.replace(target)
    return target


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wheel", type=pathlib.Path, help="the clothsr wheel (default: build it)")
    parser.add_argument("-o", "--out-dir", type=pathlib.Path, default=ROOT / "dist")
    args = parser.parse_args()
    if args.wheel is not None:
        if not args.wheel.is_file():
            print(f"{args.wheel}: no such wheel", file=sys.stderr)
            return 2
        print(build(args.wheel.resolve(), args.out_dir))
        return 0
    with tempfile.TemporaryDirectory(prefix="clothsr-wheel-") as tmp:
        print(build(build_wheel(pathlib.Path(tmp)), args.out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
