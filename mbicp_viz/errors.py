"""The one error type users see: where (file, line, field) and what."""

from __future__ import annotations


class InputError(Exception):
    """Bad input, reported as one line ``file:line: field: message`` and exit code 2."""

    def __init__(
        self,
        message: str,
        path: str | None = None,
        line: int | None = None,
        field: str | None = None,
    ):
        # one line, whatever a library's text it quotes holds
        message = " ".join(message.split("\n"))
        self.path, self.line, self.field, self.message = path, line, field, message
        where = ":".join(_printable(str(p)) for p in (path, line) if p is not None)
        text = f"{_printable(field)}: {message}" if field else message
        super().__init__(f"{where}: {text}" if where else text)

    def __reduce__(self):  # worker processes send errors back pickled; keep the arguments
        return type(self), (self.message, self.path, self.line, self.field)


def _printable(name: str) -> str:
    """A file name or a key taken from a file, as one printable line (quoted and escaped when it
    holds a newline or another control character)."""
    return name if name.isprintable() else repr(name)
