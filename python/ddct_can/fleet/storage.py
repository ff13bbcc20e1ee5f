"""Where logs and findings live: a local path, or any URL fsspec opens (s3://, gs://, abfs://,
file://, ...). ddct reads local files, so a task copies a remote log into its temporary directory
and puts its findings file at the remote destination; local paths are used as they are."""

from __future__ import annotations

import os
import shutil
from pathlib import Path


def is_url(path: str) -> bool:
    return "://" in str(path)


def join(base: str, *parts: str) -> str:
    if is_url(base):
        return "/".join([str(base).rstrip("/"), *parts])
    return str(Path(base, *parts))


def exists(path: str) -> bool:
    if is_url(path):
        import fsspec

        fs, p = fsspec.core.url_to_fs(path)
        return fs.exists(p)
    return Path(path).exists()


def local_copy(path: str, tmp: Path) -> str:
    """A local file with the content of `path` (the path itself when it is local)."""
    if not is_url(path):
        return path
    import fsspec

    dest = tmp / f"in-{len(list(tmp.iterdir()))}-{Path(str(path).split('://', 1)[1]).name}"
    with fsspec.open(path, "rb") as src, open(dest, "wb") as out:
        shutil.copyfileobj(src, out, 1 << 20)
    return str(dest)


def put_atomically(local: Path, dest: str) -> None:
    """`local` at `dest`, never half-written: a rename on a local disk; an object store's put is
    atomic per object."""
    if is_url(dest):
        import fsspec

        fs, p = fsspec.core.url_to_fs(dest)
        fs.makedirs(p.rsplit("/", 1)[0], exist_ok=True)
        fs.put_file(str(local), p)
        return
    final = Path(dest)
    final.parent.mkdir(parents=True, exist_ok=True)
    part = final.with_name(f".{final.name}.part")
    shutil.copyfile(local, part)
    os.replace(part, final)
