"""How `--help` reads: help texts as paragraphs for rich to wrap, and placeholders that name a
value (N, MM,DEG, FILE) instead of a Python type (`<str>`, `<bool>`).

Docstrings and help strings are wrapped in the source; Typer's rich output keeps a
docstring's single line breaks (in the command list and past its first paragraph), so they
are joined here, once for every command.
"""

from __future__ import annotations

import inspect
from typing import Any

import typer.core

# Placeholders by the option's Python type, where the option gives none of its own.
PLACEHOLDERS = {"int": "N", "float": "NUMBER", "Path": "PATH", "str": "TEXT"}


def unwrap(text: str | None) -> str | None:
    """`text` with each paragraph (blank-line separated) on one line."""
    if not text:
        return text
    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join(" ".join(p.split()) for p in paragraphs)


def polish(command: Any) -> None:
    """Unwrap `command`'s help and give its parameters readable placeholders: none after a
    flag, a value's kind (N, NUMBER, PATH, TEXT) where the option names none, and none after
    an argument (its name, PART or PLAN, is the placeholder)."""
    command.help = unwrap(command.help)
    command.short_help = unwrap(command.short_help)
    for param in command.params:
        param.help = unwrap(getattr(param, "help", None))
        if isinstance(param, typer.core.TyperArgument):
            # Typer prints an argument's Python type beside its name and offers no switch.
            param.display_type_rich = _no_type  # type: ignore[method-assign]
        elif param.is_flag:
            param.metavar = ""
        elif param.metavar is None:
            kind = param.bare_type()
            kind = kind[len("list[") : -1] if kind.startswith("list[") else kind
            param.metavar = PLACEHOLDERS.get(kind, "VALUE")


def _no_type(ctx: Any) -> None:
    return None


class ReadableHelp:
    """Mixin of the app's group and commands: polished help, and `--help` itself without a
    placeholder."""

    def get_help_option(self, ctx: Any) -> Any:
        option = super().get_help_option(ctx)  # type: ignore[misc]
        if option is not None:
            option.metavar = ""
        return option


class Command(ReadableHelp, typer.core.TyperCommand):
    """Every `scanplan` command's Click class (`app.command(cls=Command)`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        polish(self)
