"""Opening text files, plain or gzip-compressed, with decoding errors reported as InputError."""

from __future__ import annotations

import gzip
import io
from contextlib import contextmanager

from ..errors import InputError


@contextmanager
def open_text(path: str):
    try:
        with open(path, "rb") as raw:
            magic = raw.read(2)
        stream = gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")
    except FileNotFoundError:
        raise InputError("no such file", str(path)) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a file", str(path)) from None
    except PermissionError:
        raise InputError("permission denied", str(path)) from None
    with stream:
        text = io.TextIOWrapper(stream, encoding="utf-8", errors="strict")
        try:
            yield text
        except UnicodeDecodeError as e:
            raise InputError(f"not UTF-8 text ({e.reason})", str(path)) from None
        except (OSError, EOFError) as e:  # truncated or corrupt gzip stream
            raise InputError(f"cannot read: {e}", str(path)) from None
