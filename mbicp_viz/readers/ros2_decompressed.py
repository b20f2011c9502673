"""A ROS 2 bag compressed file by file (``ros2 bag record --compression-mode file``), decompressed
once into the cache.

Such a bag's storage files are zstd streams (``x.db3.zstd``, ``x.mcap.zstd``) with no index a
reader can seek in. rosbags decompresses every one of them into a temporary folder at each
opening, and removes it at the close: on an hour of 1081-beam scans at 40 Hz (about 800 MB) every
``match --pair`` and every worker of a run would wait for the whole file. Here they are
decompressed the first time into ``log_cache.cache_root()`` (never beside the bag, which may be
read-only), with a metadata file that names them uncompressed, and that folder is what rosbags
opens from then on: the stamps from the storage's own index (``ros2_index.py``), each scan read
when asked for. The entry is named by every compressed file's path, size and modification time,
and is removed least recently used first with the cache's other entries (``log_cache.prune``).
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

from .log_cache import CACHE_BYTES, entry, prune

_METADATA = "metadata.yaml"
_INFO = "rosbag2_bagfile_information"


def decompressed(bag: Path) -> tuple[Path, str | None]:
    """The folder to open for the ROS 2 bag ``bag``: itself, unless its files are compressed
    whole (then the cache's copy, decompressed here the first time), and what to say of it."""
    info = _file_compressed(bag)
    if info is None:
        return bag, None
    parts = [bag / Path(name).name for name in info["relative_file_paths"]]
    if any(not p.is_file() or p.suffix != ".zstd" for p in parts):
        return bag, None  # rosbags says what is missing or unknown
    stats = tuple((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in parts)
    folder = entry(str(bag / _METADATA), "ros2 file-compressed bag", stats)
    if (folder / _METADATA).is_file() and (folder / "meta.json").is_file():
        (folder / "meta.json").touch()  # used: the last to be removed
        return folder, f"{bag}: its zstd files read from their decompressed copy in {folder}"
    if not _write(bag, folder, info, parts):
        return bag, (
            f"{bag}: its zstd files decompress to more than the cache holds "
            f"({CACHE_BYTES / 1e9:g} GB): decompressed again at each opening, by rosbags"
        )
    prune(folder.parent, CACHE_BYTES, keep=folder)
    return folder, (
        f"{bag}: its files are zstd-compressed whole; decompressed once into {folder}: the next "
        "opening reads them from there"
    )


def _file_compressed(bag: Path) -> dict | None:
    """The bag's metadata when it says its files are compressed whole, else None (a bag that is
    not a folder, or whose metadata cannot be read: rosbags says why)."""
    if not (bag / _METADATA).is_file():
        return None
    from ruamel.yaml import YAML, YAMLError

    try:
        info = YAML(typ="safe").load((bag / _METADATA).read_text())[_INFO]
        mode = str(info.get("compression_mode") or "").lower()
        names = info["relative_file_paths"]
    except (OSError, YAMLError, KeyError, TypeError, AttributeError, UnicodeDecodeError):
        return None
    if mode != "file" or not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        return None
    return info


class _TooLarge(Exception):
    """The decompressed files would hold more than the whole cache may."""


def _write(bag: Path, folder: Path, info: dict, parts: list[Path]) -> bool:
    """The decompressed files and their metadata into ``folder``, whole or not at all; False when
    they would hold more than the whole cache may (nothing written)."""
    from ruamel.yaml import YAML

    from mbicp_viz.errors import InputError
    from mbicp_viz.outputs import written_folder

    try:
        from compression import zstd  # Python 3.14
    except ImportError:
        from backports import zstd

    plain = {p.name: p.stem for p in parts}  # x.db3.zstd -> x.db3
    info = dict(info, compression_mode="", compression_format="")
    info["relative_file_paths"] = [plain[Path(n).name] for n in info["relative_file_paths"]]
    info["files"] = [
        dict(f, path=plain.get(Path(f["path"]).name, f["path"]))
        for f in info.get("files") or []
        if isinstance(f, dict) and isinstance(f.get("path"), str)
    ]
    shutil.rmtree(folder, ignore_errors=True)  # an entry left incomplete
    at = bag
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        with written_folder(folder) as tmp:
            tmp.mkdir()
            room = CACHE_BYTES  # a few bytes may decompress to many: never past this
            for at in parts:
                with at.open("rb") as src, zstd.open(src) as z, (tmp / at.stem).open("wb") as dst:
                    while block := z.read(1 << 20):
                        room -= len(block)
                        if room < 0:
                            raise _TooLarge
                        dst.write(block)
            at = folder
            text = io.StringIO()
            YAML(typ="safe").dump({_INFO: info}, text)
            (tmp / _METADATA).write_text(text.getvalue())
            (tmp / "meta.json").write_text(json.dumps({"bag": str(bag)}))
    except _TooLarge:
        return False
    except (zstd.ZstdError, EOFError) as e:
        raise InputError(f"not a whole zstd stream ({e})", str(at)) from None
    except OSError as e:
        raise InputError(f"could not be decompressed into {folder}: {e}", str(at)) from None
    return True
