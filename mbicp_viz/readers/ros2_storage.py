"""Which storage a ROS 2 bag is read from: its folder, one of its files, or a copy in the cache.

A bag recorded with ``ros2 bag record --compression-mode file`` has zstd streams for storage files
(``x.db3.zstd``, ``x.mcap.zstd``), with no index a reader can seek in. rosbags decompresses every
one of them into a temporary folder at each opening, and removes it at the close: on an hour of
1081-beam scans at 40 Hz (about 800 MB) every ``match --pair`` and every worker of a run would
wait for the whole file. Here they are decompressed the first time into
``log_cache.cache_root()`` (never beside the bag, which may be read-only), with a metadata file
that names them uncompressed, and that folder is what rosbags opens from then on: the stamps from
the storage's own index (``ros2_index.py``), each scan read when asked for. The entry is named by
every compressed file's path, size and modification time, and is removed least recently used first
with the cache's other entries (``log_cache.write_entry``).

With ``--compression-mode message`` each message is compressed and only the folder's metadata says
so: one of its storage files opened alone reads as undecodable messages, so its folder is opened
instead. A recording stopped before its metadata was written (the recorder killed) is a folder of
one storage file and no metadata: that file is opened alone.
"""

from __future__ import annotations

import io
from pathlib import Path

from mbicp_viz.errors import InputError

from .log_cache import CACHE_BYTES, entry, used, write_entry

_METADATA = "metadata.yaml"
_INFO = "rosbag2_bagfile_information"


def storage_to_open(bag: Path) -> tuple[Path, str | None]:
    """The bag to open for the ROS 2 bag ``bag`` (a folder, or a storage file), and what to say
    of it: itself; its folder when its messages are compressed; the cache's copy of a folder whose
    files are compressed whole (decompressed here the first time); a folder's one storage file
    when it has no metadata."""
    if bag.is_dir() and not (bag / _METADATA).exists():
        files = [f for f in bag.iterdir() if f.suffix in (".db3", ".mcap") and f.is_file()]
        if len(files) == 1:
            return files[0], (
                f"{bag}: no {_METADATA} (a recording stopped before it was written): its one "
                f"storage file {files[0].name} read alone"
            )
        return bag, None
    if bag.is_file():
        info = _metadata(bag.parent)
        if info is None or _mode(info) != "message" or bag.name not in _names(info):
            return bag, None
        return bag.parent, (
            f"{bag}: its messages are zstd-compressed, as its folder's {_METADATA} says: read "
            f"through its folder {bag.parent}"
        )
    info = _metadata(bag)
    if info is None or _mode(info) != "file":
        return bag, None
    parts = [bag / name for name in _names(info)]
    if any(not p.is_file() or p.suffix != ".zstd" for p in parts):
        return bag, None  # rosbags says what is missing or unknown
    stats = tuple((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in parts)
    folder = entry(str(bag / _METADATA), "ros2 file-compressed bag", stats)
    if not used(folder):
        try:
            write_entry(folder, lambda tmp: _decompress(parts, info, tmp), {"bag": str(bag)})
        except _TooLarge:
            return bag, (
                f"{bag}: its zstd files decompress to more than the cache holds "
                f"({CACHE_BYTES / 1e9:g} GB): decompressed again at each opening, by rosbags"
            )
        except OSError as e:
            raise InputError(f"could not be decompressed into {folder}: {e}", str(bag)) from None
        return folder, (
            f"{bag}: its files are zstd-compressed whole; decompressed once into {folder}: the "
            "next opening reads them from there"
        )
    return folder, f"{bag}: its zstd files read from their decompressed copy in {folder}"


def _metadata(folder: Path) -> dict | None:
    """The bag information of ``folder``'s metadata file; None without one, or when it cannot be
    read (rosbags says why)."""
    if not (folder / _METADATA).is_file():
        return None
    from ruamel.yaml import YAML, YAMLError

    try:
        info = YAML(typ="safe").load((folder / _METADATA).read_text())[_INFO]
        names = info["relative_file_paths"]
    except (OSError, YAMLError, KeyError, TypeError, UnicodeDecodeError):
        return None
    ok = (
        isinstance(info, dict)
        and isinstance(names, list)
        and all(isinstance(n, str) for n in names)
    )
    return info if ok else None


def _mode(info: dict) -> str:
    return str(info.get("compression_mode") or "").lower()


def _names(info: dict) -> list[str]:
    """The storage files' names (a name only: never a path out of the folder)."""
    return [Path(n).name for n in info["relative_file_paths"]]


class _TooLarge(Exception):
    """The decompressed files would hold more than the whole cache may."""


def _decompress(parts: list[Path], info: dict, tmp: Path) -> None:
    """The decompressed storage files and a metadata file naming them into ``tmp``."""
    from ruamel.yaml import YAML

    try:
        from compression import zstd  # Python 3.14
    except ImportError:
        from backports import zstd

    room = CACHE_BYTES  # a few bytes may decompress to many: never past this
    for part in parts:
        try:
            with part.open("rb") as src, zstd.open(src) as z, (tmp / part.stem).open("wb") as dst:
                while block := z.read(1 << 20):
                    room -= len(block)
                    if room < 0:
                        raise _TooLarge
                    dst.write(block)
        except (zstd.ZstdError, EOFError) as e:
            raise InputError(f"not a whole zstd stream ({e})", str(part)) from None
    plain = {p.name: p.stem for p in parts}  # x.db3.zstd -> x.db3
    info = dict(info, compression_mode="", compression_format="")
    info["relative_file_paths"] = [plain[Path(n).name] for n in info["relative_file_paths"]]
    info["files"] = [
        dict(f, path=plain.get(Path(f["path"]).name, f["path"]))
        for f in info.get("files") or []
        if isinstance(f, dict) and isinstance(f.get("path"), str)
    ]
    text = io.StringIO()
    YAML(typ="safe").dump({_INFO: info}, text)
    (tmp / _METADATA).write_text(text.getvalue())
