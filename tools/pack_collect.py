"""Pack ``icrsumo collect`` folders for a machine that takes little data per transfer, and unpack
them there (how the shipped checkpoints' data reached the lent GPU machine, 64 MiB a call).

    python tools/pack_collect.py pack OUT.tar.xz DATA [DATA ...]
    python tools/pack_collect.py unpack OUT.tar.xz DEST

``pack`` writes ``collect.json`` and ``episodes/`` of each folder (not ``scenarios/``) into one
tar compressed with xz, each episode's ``.npz`` re-stored without its zlib compression first:
xz then packs the bit-packed frames about twice as small as the ``.npz`` files (91 MB of
episodes -> 53 MB). ``unpack`` restores ``DEST/<folder name>/`` with uncompressed ``.npz``
files, which ``icrsumo train --data`` reads as they are.
"""

from __future__ import annotations

import argparse
import io
import lzma
import tarfile
import zipfile
from pathlib import Path


def _stored(data: bytes) -> bytes:
    """The same ``.npz`` members, stored without compression."""
    src = zipfile.ZipFile(io.BytesIO(data))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as dst:
        for name in src.namelist():
            dst.writestr(name, src.read(name))
    return buf.getvalue()


def pack(out: Path, folders: list[Path]) -> None:
    with lzma.open(out, "wb", preset=3) as xz, tarfile.open(fileobj=xz, mode="w|") as tar:
        for d in folders:
            files = [d / "collect.json", *sorted((d / "episodes").glob("*.npz"))]
            for p in files:
                data = p.read_bytes()
                if p.suffix == ".npz":
                    data = _stored(data)
                info = tarfile.TarInfo(f"{d.name}/{p.relative_to(d).as_posix()}")
                info.size = len(data)
                tar.addfile(info, io.BytesIO(data))


def unpack(archive: Path, dest: Path) -> None:
    with lzma.open(archive, "rb") as xz, tarfile.open(fileobj=xz, mode="r|") as tar:
        tar.extractall(dest, filter="data")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("pack")
    p.add_argument("out", type=Path)
    p.add_argument("data", type=Path, nargs="+")
    u = sub.add_parser("unpack")
    u.add_argument("archive", type=Path)
    u.add_argument("dest", type=Path)
    args = ap.parse_args()
    if args.cmd == "pack":
        pack(args.out, args.data)
    else:
        unpack(args.archive, args.dest)


if __name__ == "__main__":
    main()
