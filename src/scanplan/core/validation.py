"""A file's first bad field as one line: the path pydantic found it at (`views[0].swaths[2].u`;
a key that is not a name quoted, so a key holding a newline cannot break the line) and the
message without pydantic's prefixes or its private model names.
"""

from __future__ import annotations

from collections.abc import Collection

from pydantic import ValidationError

# Longest key shown (a key of a megabyte is still one short line).
_MAX_KEY = 40


def first_error(
    exc: ValidationError, drop: Collection[str] = (), record: str = "a JSON object"
) -> tuple[str, str]:
    """(path, message) of the first error; `drop`: location parts that name a union's
    branch rather than a field; `record`: what a nested record is called in the file."""
    err = exc.errors()[0]
    path = ""
    for part in err["loc"]:
        if part in drop:
            continue
        if isinstance(part, int):
            path += f"[{part}]"
        elif part.isidentifier():
            path += f".{part}"
        else:
            path += f".{part[:_MAX_KEY]!r}"
    if err["type"] in ("model_type", "model_attributes_type", "dict_type"):
        return path.lstrip("."), f"expected {record}"
    return path.lstrip("."), str(err["msg"]).removeprefix("Value error, ")


def error_line(where: str, exc: ValidationError, drop: Collection[str] = ()) -> str:
    """'where.path: message' ('where: message' for an error of the whole record)."""
    path, message = first_error(exc, drop)
    sep = "" if not path or path.startswith("[") else "."
    return f"{where}{sep}{path}: {message}"


def field_line(exc: ValidationError) -> str:
    """'path: message' of a file's first bad field ('file: message' for the whole file)."""
    path, message = first_error(exc)
    return f"{path or 'file'}: {message}"
