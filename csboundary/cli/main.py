"""Command-line entry point: the commands, registered in the order a user meets them, and the
one place where errors become messages.

Input problems surface as ``error: <file>: <problem>`` on one line with exit status 2;
documented fallbacks (no CRS, 3-band RGB) as ``warning: ...`` lines; an interruption removes
every temporary before it exits. Each command lives in a module of its kind (data_commands,
training_commands, predict_commands, evaluate_commands) and is a thin shell over a library
function.
"""

from __future__ import annotations

import inspect
import os
import signal
import sys
import warnings

import typer

from csboundary.cli import data_commands, evaluate_commands, predict_commands, training_commands
from csboundary.data.atomic import is_disk_full
from csboundary.errors import InputError, InputWarning

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help="City-scale road-boundary graphs from aerial imagery."
)

COMMANDS = (  # (name, function)
    ("demo", predict_commands.demo),
    ("predict", predict_commands.predict),
    ("predict-patch", predict_commands.predict_patch),
    ("export-lanelet2", predict_commands.export_lanelet2),
    ("review", predict_commands.review),
    ("apply-review", predict_commands.apply_review),
    ("qgis-plugin", predict_commands.qgis_plugin),
    ("evaluate", evaluate_commands.evaluate),
    ("evaluate-model", evaluate_commands.evaluate_model),
    ("evaluate-set", evaluate_commands.evaluate_set_cmd),
    ("benchmark", evaluate_commands.benchmark),
    ("synth", data_commands.synth),
    ("import-topo-boundary", data_commands.import_topo_boundary_cmd),
    ("import-masks", data_commands.import_masks_cmd),
    ("make-city", data_commands.make_city_cmd),
    ("labels", data_commands.labels),
    ("show", data_commands.show),
    ("train", training_commands.train),
    ("bundle-weights", training_commands.bundle_weights),
    ("fit-confidence", training_commands.fit_confidence),
    ("finetune", training_commands.finetune),
    ("evaluate-finetune", training_commands.evaluate_finetune),
    ("adapt", training_commands.adapt),
)
for _name, _command in COMMANDS:
    app.command(_name)(_command)


def _print_version(asked: bool) -> None:
    if asked:
        from csboundary import __version__

        typer.echo(f"csboundary {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: bool = typer.Option(
        False,
        "--version",
        is_eager=True,
        callback=_print_version,
        help="Print the version and exit (the QGIS plugin's check of the environment).",
    ),
) -> None:
    pass


def command_line():
    """The app as the click command ``main`` runs, its help tidied (:func:`help_as_read`)."""
    return help_as_read(typer.main.get_command(app))


def help_as_read(group):
    """The help screens tidied: each command's text re-flowed to the terminal (its docstring's
    line breaks dropped, paragraphs kept) and summed up in the command list by its first
    sentence; flags without a value shown bare (typer writes ``<bool>``), arguments by name in
    capitals (``IMAGERY...``, not ``{inputs}... <list[Path]>``). Typer has no setting for the last
    two, so its help methods are replaced on these objects alone."""
    for command in (group, *group.commands.values()):
        if command is not group and command.help:
            paragraphs = inspect.cleandoc(command.help).split("\n\n")
            command.help = "\n\n".join(" ".join(p.split()) for p in paragraphs)
            command.short_help = first_sentence(command.help)
        for param in command.params:
            if param.param_type_name == "option" and param.is_flag:
                param.metavar = ""
            elif param.param_type_name == "option" and param.metavar is None:
                param.display_type_rich = lambda ctx, shown=param.display_type_rich: value_name(shown(ctx))
            elif param.param_type_name == "argument":
                name = param.metavar or param.name.upper() + ("..." if param.nargs != 1 else "")
                param.metavar = name
                param.display_type_rich = lambda ctx: None
                param.get_usage_pieces = lambda ctx, name=name, required=param.required: [
                    name if required else f"[{name}]"
                ]
        command.get_help_option = _bare_flag(command.get_help_option)
    return group


VALUE_NAMES = {
    "<path>": "PATH",
    "<int>": "N",
    "<int range>": "N",
    "<float>": "NUMBER",
    "<float range>": "NUMBER",
    "<str>": "TEXT",
}


def value_name(typed: str | None) -> str | None:
    """``PATH`` for typer's ``<path>``, ``N`` for ``<int range>`` and the like."""
    return VALUE_NAMES.get(typed, typed)


def _bare_flag(get_option):
    def bare(ctx):
        option = get_option(ctx)
        if option is not None:
            option.metavar = ""
        return option

    return bare


def first_sentence(text: str) -> str:
    """Up to the first full stop that ends a sentence (not one inside ``0.03`` or ``e.g.``)."""
    for k in range(len(text) - 1):
        if text[k] == "." and text[k + 1] == " " and not text[max(0, k - 3) : k + 1].endswith(("e.g.", "i.e.", "Fig.")):
            return text[: k + 1]
    return text


def _format_warning(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


class Interrupted(BaseException):
    """SIGINT or SIGTERM. A BaseException that is not KeyboardInterrupt, so that click does not
    turn Ctrl-C into its own exit before the temporaries are cleared and the user told."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


# what an interrupted command keeps, by subcommand (the message the interruption ends with)
RESUMES = {
    "predict": "a predict run keeps its finished patches: the same command continues it",
    "finetune": "fine-tuning keeps its runs in its work folder: the same command continues them",
    "adapt": "adapting keeps its runs in its work folder: the same command continues them",
    "evaluate-finetune": "the finished folds are kept: the same command continues with the next",
    "train": "training keeps its last checkpoint (RUN-last.pt): --resume it to continue",
}


def _subcommand() -> str | None:
    """The subcommand this process runs (the first argument that is not an option)."""
    return next((arg for arg in sys.argv[1:] if not arg.startswith("-")), None)


def _on_signal(signum, frame) -> None:
    raise Interrupted(signum)


def main() -> None:
    """Console entry point: run the app, turning input errors into one line and exit status 2,
    and Ctrl-C / SIGTERM into a message and exit 130 / 143 after every temporary is removed."""
    warnings.formatwarning = _format_warning
    warnings.simplefilter("always", InputWarning)
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    if hasattr(signal, "SIGBREAK"):  # Windows: Ctrl-Break, which the QGIS plugin's cancel sends there
        signal.signal(signal.SIGBREAK, _on_signal)
    try:
        code = command_line()(standalone_mode=False)
    except typer.Abort:
        typer.echo("aborted", err=True)
        sys.exit(1)
    except typer.TyperException as exc:  # click's usage errors (typer vendors click): one line too
        if type(exc).__name__ == "NoArgsIsHelpError":
            exc.show()
            sys.exit(2)
        ctx = getattr(exc, "ctx", None)
        where = f" (see csboundary {ctx.info_name} --help)" if ctx is not None and ctx.parent is not None else ""
        typer.echo(f"error: {' '.join(exc.format_message().split())}{where}", err=True)
        sys.exit(getattr(exc, "exit_code", 2))
    except InputError as exc:
        typer.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except (
        OSError,
        MemoryError,
    ) as exc:  # a full disk, a vanished file, no memory: the system's problem, said in one line
        name = getattr(exc, "filename", None)
        typer.echo(
            f"error: {name + ': ' if name else ''}{exc.strerror or exc if isinstance(exc, OSError) else 'out of memory'}",
            err=True,
        )
        sys.exit(1)
    except Exception as exc:  # a bug, not the user's input: one line, the traceback on request
        if os.environ.get("CSBOUNDARY_DEBUG"):
            raise
        message = " ".join(str(exc).split())[:300]
        if is_disk_full(exc):  # GDAL and SQLite say a full disk with their own exception types, naming no file
            typer.echo(
                f"error: no space left on device ({type(exc).__name__}: {message}): free some space and run the same "
                "command again",
                err=True,
            )
            sys.exit(1)
        typer.echo(
            f"error: internal error ({type(exc).__name__}: {message}); please report it, with the traceback "
            "that CSBOUNDARY_DEBUG=1 prints",
            err=True,
        )
        sys.exit(1)
    except (Interrupted, KeyboardInterrupt) as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        typer.echo(
            f"interrupted ({signal.Signals(signum).name}): temporaries removed; no partial file was left under a final name "
            f"({RESUMES.get(_subcommand(), 'run the command again to redo it')})",
            err=True,
        )
        sys.exit(128 + signum)
    sys.exit(code if isinstance(code, int) else 0)
