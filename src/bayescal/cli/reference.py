"""The command-line reference, generated from the click commands of :mod:`bayescal.cli.main`.

``python -m bayescal.cli.reference > docs/cli.md`` writes it; a test checks
that the committed file equals the generated text, so the reference cannot
drift from the code.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import click

from bayescal.cli.main import main

_TYPE_NAMES = {
    "text": "text",
    "integer": "integer",
    "float": "number",
    "boolean": "flag",
    "path": "path",
}


def _cell(text: str) -> str:
    """One Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _paragraphs(help_text: str | None) -> list[str]:
    """A click help text as Markdown paragraphs (``\\b`` blocks kept verbatim)."""
    text = inspect.cleandoc((help_text or "").split("\f")[0])
    out = []
    for block in text.split("\n\n"):
        if block.startswith("\b"):
            body = "\n".join(f"    {line}" for line in block[1:].strip("\n").splitlines())
            out.append(body)
        elif block.strip():
            out.append(" ".join(block.split()))
    return out


def _type_name(param: click.Parameter) -> str:
    """Readable type of a parameter: ``path``, ``integer ≥ 1``, `` `a` | `b` ``."""
    kind = param.type
    if isinstance(param, click.Option) and param.is_flag:
        return "flag"
    if isinstance(kind, click.Choice):
        return " \\| ".join(f"`{choice}`" for choice in kind.choices)
    if isinstance(kind, click.IntRange | click.FloatRange):
        base = "integer" if isinstance(kind, click.IntRange) else "number"
        bounds = []
        if kind.min is not None:
            bounds.append(f"≥ {kind.min}" if not kind.min_open else f"> {kind.min}")
        if kind.max is not None:
            bounds.append(f"≤ {kind.max}" if not kind.max_open else f"< {kind.max}")
        return " ".join([base, ", ".join(bounds)]).strip()
    name = _TYPE_NAMES.get(kind.name, kind.name)
    if param.multiple:
        name += ", repeatable"
    return name


def _default(param: click.Parameter, ctx: click.Context) -> str:
    """The default shown in the tables; empty where there is none to show."""
    value = param.get_default(ctx, call=False)
    if isinstance(param, click.Option) and param.secondary_opts and isinstance(value, bool):
        # an on/off pair (--x/--no-x): the one in force without either
        return f"`{(param.opts if value else param.secondary_opts)[0]}`"
    if isinstance(value, bool) or not isinstance(value, str | int | float | Path):
        return ""
    return f"`{value}`"


def _option_name(param: click.Option) -> str:
    names = sorted(param.opts, key=lambda o: (not o.startswith("--"), o))
    text = ", ".join(f"`{n}`" for n in names)
    if param.secondary_opts:
        text += " / " + ", ".join(f"`{n}`" for n in param.secondary_opts)
    if param.metavar:
        text += f" `{param.metavar}`"
    return text


def _options_table(command: click.Command, ctx: click.Context) -> list[str]:
    options = [p for p in command.get_params(ctx) if isinstance(p, click.Option) and not p.hidden]
    if not options:
        return []
    lines = ["| option | type | default | description |", "|---|---|---|---|"]
    for opt in options:
        lines.append(
            f"| {_option_name(opt)} | {_type_name(opt)} | {_cell(_default(opt, ctx))} | "
            f"{_cell(opt.help or '')} |"
        )
    return lines


def _arguments_table(command: click.Command, ctx: click.Context) -> list[str]:
    arguments = [p for p in command.get_params(ctx) if isinstance(p, click.Argument)]
    if not arguments:
        return []
    lines = ["| argument | type | required |", "|---|---|---|"]
    for arg in arguments:
        lines.append(
            f"| `{arg.human_readable_name}` | {_type_name(arg)} | "
            f"{'yes' if arg.required else 'no'} |"
        )
    return lines


def command_markdown(command: click.Command, ctx: click.Context, level: int = 2) -> str:
    """The reference section of one command: usage, description, arguments, options.

    Parameters
    ----------
    command
        A click command.
    ctx
        Its context (``click.Context(command, info_name=..., parent=...)``),
        which gives the full command path for the usage line.
    level
        Heading level of the section.

    Returns
    -------
    str
        Markdown text, without a trailing newline.
    """
    lines = [f"{'#' * level} `{ctx.command_path}`", ""]
    usage = " ".join(command.collect_usage_pieces(ctx))
    lines += ["```text", f"{ctx.command_path} {usage}".rstrip(), "```", ""]
    for paragraph in _paragraphs(command.help):
        lines += [paragraph, ""]
    for table in (_arguments_table(command, ctx), _options_table(command, ctx)):
        if table:
            lines += [*table, ""]
    return "\n".join(lines).rstrip("\n")


def cli_reference_markdown(group: click.Group = main, name: str = "bayescal") -> str:
    """The whole command-line reference: the group's options, then every command.

    Parameters
    ----------
    group
        The click group (``bayescal.cli.main``).
    name
        The program name shown in usage lines.

    Returns
    -------
    str
        Markdown text ending with one newline.
    """
    root = click.Context(group, info_name=name, **group.context_settings)
    head = [
        "# Command-line reference",
        "",
        "Generated from `bayescal.cli` by `python -m bayescal.cli.reference`; do not edit.",
        "Every command takes `-h` / `--help`. An error the user can cause (a study file",
        "that does not validate, missing data, a failed simulator) is printed as one line",
        "`error: ...` with exit status 2; `bayescal --debug COMMAND` shows the traceback.",
        "",
        command_markdown(group, root, level=2),
        "",
        "## Commands",
        "",
    ]
    rows = ["| command | what it does |", "|---|---|"]
    for cmd_name, command in group.commands.items():
        rows.append(
            f"| [`{cmd_name}`](#{name}-{cmd_name}) | {_cell(command.get_short_help_str(200))} |"
        )
    sections = []
    for cmd_name, command in group.commands.items():
        ctx = click.Context(command, info_name=cmd_name, parent=root, **command.context_settings)
        sections.append(command_markdown(command, ctx, level=3))
    return "\n".join(head + rows) + "\n\n" + "\n\n".join(sections) + "\n"


if __name__ == "__main__":
    print(cli_reference_markdown(), end="")
