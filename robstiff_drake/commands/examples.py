"""``robstiff examples [--copy DIR]``: what the package ships to start
from (the scenarios with their G-code programs, the robot library, example
measurement campaigns), listed, or copied into a folder to edit.

The copy never overwrites anything: every target is checked first (one
line, exit status 2, nothing written, if one exists), the files are written
into a temporary folder and then moved into place, a new folder by one
rename, an existing one file by file with links that cannot replace a file
(a file that appears in between stops the copy, and what was moved is taken
back).  Standard library only: the listing and the copy need no numpy."""

import os
import shutil
import tempfile
from pathlib import Path

from robstiff_drake.errors import InputError
from robstiff_drake.paths import DIAGRAMS_DIR, MODELS_DIR, docs_dir, examples_dir
from robstiff_drake.progress import info

# (folder in the copy, packaged folder, file patterns)
GROUPS = (("scenarios", lambda: DIAGRAMS_DIR, ("*.yaml", "*.nc")),
          ("robots", lambda: MODELS_DIR, ("*.yaml",)),
          ("campaigns", examples_dir, ("*.csv",)),
          ("docs", docs_dir, ("*.md", "*.png")))


def packaged_files():
    """{path in the copy (relative): packaged file}, README.md first."""
    files = {"README.md": examples_dir() / "README.md"}
    for folder, where, patterns in GROUPS:
        for pattern in patterns:
            for p in sorted(where().glob(pattern)):
                files[f"{folder}/{p.name}"] = p
    return files


def _first_line(path):
    """A scenario's description (its `description:` key) or a file's first comment."""
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("description:"):
            return line.split(":", 1)[1].strip()
    return ""


def listing(files):
    lines = []
    for folder, _, _ in GROUPS:
        names = [rel for rel in files if rel.startswith(folder + "/")]
        if folder == "docs":
            pages = [rel for rel in names if rel.endswith(".md")]
            lines.append(f"docs ({len(pages)} pages, {len(names) - len(pages)} figures): "
                         + ", ".join(files[rel].name for rel in pages))
            continue
        if folder == "scenarios":  # the scenarios, then the G-code programs they read
            programs = [rel for rel in names if rel.endswith(".nc")]
            names = [rel for rel in names if not rel.endswith(".nc")]
        lines.append(f"{folder} ({len(names)}):")
        for rel in names:
            src = files[rel]
            what = _first_line(src) if folder == "scenarios" and src.suffix == ".yaml" else ""
            lines.append(f"  {src.name:34s} {what}".rstrip())
        if folder == "scenarios":
            lines.append(f"G-code programs the scenarios read ({len(programs)}, in scenarios/):")
            lines += [f"  {files[rel].name}" for rel in programs]
    lines.append("a packaged scenario runs by its name (`robstiff simulate block_milling`), a robot by its name "
                 "(`--robot kr240_r2900`); `robstiff examples --copy DIR` copies them all to edit")
    return "\n".join(lines)


def _linked_folder(dest, files):
    """The first folder inside ``dest`` that a copied file would go through
    and that is a symbolic link (or not a folder), or None: the copy writes
    only inside DIR, never where a link inside it points."""
    for rel in files:
        for parent in reversed(Path(rel).parents[:-1]):
            p = dest / parent
            if os.path.islink(p) or (os.path.lexists(p) and not p.is_dir()):
                return p
    return None


def _check_target(dest, files):
    if not str(dest).strip():
        raise InputError("examples --copy '': an empty folder name; give the folder to copy into (e.g. "
                         "`--copy robstiff-examples`)")
    if dest.exists() and not dest.is_dir():
        raise InputError(f"examples --copy {dest}: is a file, not a folder")
    if os.path.lexists(dest) and not dest.exists():
        raise InputError(f"examples --copy {dest}: a symbolic link to {os.readlink(dest)}, which does not exist")
    linked = _linked_folder(dest, files) if dest.exists() else None
    if linked is not None:
        what = f"a symbolic link to {os.readlink(linked)}" if os.path.islink(linked) else "not a folder"
        raise InputError(f"examples --copy {dest}: {linked} is {what}; the copy writes only inside {dest}: remove it "
                         "or choose another folder")
    clash = [rel for rel in files if os.path.lexists(dest / rel)]
    if clash:
        more = f" (and {len(clash) - 1} more)" if len(clash) > 1 else ""
        raise InputError(f"examples --copy {dest}: {dest / clash[0]} already exists{more}; nothing is overwritten: "
                         "choose another folder")
    anc = dest
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"examples --copy {dest}: cannot write in {anc}")


def _copy_into(tmp, files):
    for rel, src in files.items():
        (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, tmp / rel)


def _move_in(tmp, dest, files):
    """Move the files of ``tmp`` into the existing folder ``dest`` without
    replacing anything; on a failure take back what was moved."""
    moved, made = [], []
    try:
        if _linked_folder(dest, files) is not None:  # (a link made since the check)
            raise NotADirectoryError(0, "a symbolic link inside the folder; the copy writes only inside it",
                                     str(_linked_folder(dest, files)))
        for rel in files:
            target = dest / rel
            for parent in reversed(target.relative_to(dest).parents[:-1]):
                if not (dest / parent).exists():
                    (dest / parent).mkdir()
                    made.append(dest / parent)
            os.link(tmp / rel, target)  # FileExistsError rather than a replacement
            moved.append(target)
    except OSError as e:
        for target in moved:
            target.unlink(missing_ok=True)
        for folder in reversed(made):
            try:
                folder.rmdir()
            except OSError:
                pass
        what = "already exists; nothing is overwritten" if isinstance(e, FileExistsError) else e.strerror
        raise InputError(f"examples --copy {dest}: {e.filename or dest}: {what}") from None


def copy_files(dest, files):
    """Copy ``files`` ({relative path: source}) into the folder ``dest``."""
    if not str(dest).strip():
        _check_target(dest, files)
    dest = Path(dest)
    _check_target(dest, files)
    new = not dest.exists()
    parent = dest.parent if new else dest
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name or 'examples'}.", suffix=".tmp", dir=parent))
    except OSError as e:
        raise InputError(f"examples --copy {dest}: cannot write ({e.strerror})") from None
    try:
        _copy_into(tmp, files)
        if new:
            os.chmod(tmp, 0o777 & ~_umask())
            try:
                os.rename(tmp, dest)  # the whole folder at once
            except OSError as e:
                raise InputError(f"examples --copy {dest}: cannot create it ({e.strerror})") from None
        else:
            _move_in(tmp, dest, files)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def run(*, copy=None):
    files = packaged_files()
    if copy is None:
        print(listing(files))
        return 0
    copy_files(copy, files)
    dest = copy
    counts = {folder: sum(rel.startswith(folder + "/") for rel in files) for folder, _, _ in GROUPS}
    programs = sum(rel.endswith(".nc") for rel in files)
    pages = sum(rel.startswith("docs/") and rel.endswith(".md") for rel in files)
    shown = Path(dest)
    info(f"wrote {shown}/: README.md, scenarios/ ({counts['scenarios'] - programs} scenarios, {programs} G-code "
         f"program{'s' if programs != 1 else ''}), robots/ ({counts['robots']} robot files), campaigns/ "
         f"({counts['campaigns']} campaigns), docs/ ({pages} pages)")
    info(f"next: robstiff simulate {shown / 'scenarios' / 'block_milling.yaml'} --out run1")
    return 0
