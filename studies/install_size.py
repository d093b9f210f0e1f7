"""What installing robstiff-drake downloads and takes on disk, for the
README: the drake wheel, every wheel `pip install .` (and `.[test]`)
fetches, and the virtual environment each makes.

Downloads from PyPI with this machine's pip (its index and cache
settings), into a temporary folder; installs from the downloaded wheels
into fresh virtual environments and measures them (apparent size of every
file, as `du --apparent-size` counts).  A few minutes and about 300 MB of
network.  Run from the clone: python3 studies/install_size.py
"""

import platform
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def size_bytes(path):
    path = Path(path)
    if path.is_file():
        return path.stat().st_size
    return sum(p.lstat().st_size for p in path.rglob("*") if p.is_file() or p.is_symlink())


def pip(*args, python=sys.executable):
    subprocess.run([str(python), "-m", "pip", "-q", *map(str, args)], check=True)


def main():
    print(f"platform: {platform.system()} {platform.machine()}, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        pip("wheel", "--no-deps", "-w", tmp / "own", REPO)  # the project's own wheel (pure Python)
        (own,) = (tmp / "own").glob("robstiff_drake-*.whl")
        rows = []
        for label, extras in (("pip install .", ""), ("pip install '.[test]'", "[test]")):
            dl = tmp / f"dl_{len(rows)}"
            pip("download", "--no-cache-dir", "-d", dl, f"{own}{extras}")
            wheels = sorted(p for p in dl.iterdir() if not p.name.startswith("robstiff_drake-"))
            drake = next(p for p in wheels if p.name.startswith("drake-"))
            venv = tmp / f"venv_{len(rows)}"
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
            pip("install", "--no-index", "--find-links", dl, f"robstiff-drake{extras}", python=venv / "bin" / "python")
            rows.append((label, drake, len(wheels), sum(size_bytes(p) for p in wheels), size_bytes(venv)))
        print(f"drake wheel: {rows[0][1].name}, {size_bytes(rows[0][1]) / 1e6:.1f} MB")
        print("| command | wheels downloaded | download (MB) | virtual environment (MB) |")
        print("|---|---|---|---|")
        for label, _, n, download, env in rows:
            print(f"| `{label}` | {n} | {download / 1e6:.0f} | {env / 1e6:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
