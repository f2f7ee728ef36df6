"""The ``mdaug`` command: one verb per job, the front end on top of the library.

Modules, one per group of verbs (each defines its verbs once, in ``VERBS``):

* :mod:`.data`: ``simulate``, ``process``;
* :mod:`.augment`: ``augment``;
* :mod:`.calibrate`: ``calibrate``;
* :mod:`.estimator`: ``train-estimator``, ``sbc``;
* :mod:`.classify`: ``train``, ``evaluate``, ``sweep``, ``baseline``;
* :mod:`.study`: ``run``;
* :mod:`.common`: what several verbs share (argument types, the global options,
  option groups, checks before any work, the size bound);
* :mod:`.guard`: the one output guard every verb calls first (no output may be an
  input or another output, formats, folders, UTF-8 names).

``--threads`` and ``--quiet`` are accepted before and after the verb. Every bad input
ends in one line ``mdaug VERB: error: ...`` naming the file and field, or the option,
and exit status 2, before any output is written; an interrupt ends in one line and
exit status 130 (SIGTERM: 143). Only the verb being run builds its full parser, and heavy libraries
load inside the verb, so ``mdaug --help`` is fast.
"""
from __future__ import annotations

import importlib
import sys

from .common import HelpFormatter, Parser, UsageError, global_options

GROUPS = ("data", "augment", "calibrate", "estimator", "classify", "sweep", "study")
ORDER = ("simulate", "process", "calibrate", "train-estimator", "sbc", "augment", "train", "evaluate", "sweep", "baseline", "run")
"""Verbs in the order ``mdaug --help`` lists them."""

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143  # 128 + SIGTERM


def verbs() -> dict:
    """{verb: (one-line help, add function)} of every group module."""
    table = {}
    for group in GROUPS:
        table.update(importlib.import_module(f".{group}", __name__).VERBS)
    return {v: table[v] for v in ORDER if v in table} | {v: t for v, t in table.items() if v not in ORDER}


def build_parser(full=None) -> Parser:
    """The parser; ``full``: the verbs whose options are built (None = all), the others
    get a stub that only lists them in ``mdaug --help``."""
    from ..radar.version import package_version

    parser = Parser(prog="mdaug", formatter_class=HelpFormatter, parents=[global_options(top=True)],
                    description="Model-based augmentation of 77 GHz FMCW radar micro-Doppler range profiles "
                                "for drone classification. Run 'mdaug VERB --help' for a verb's options.")
    parser.add_argument("--version", action="version", version=f"mdaug {package_version()}",
                        help="print the version and exit")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=Parser,
                                help="the job to run (each has its own --help)")
    parents = [global_options(top=False)]
    for name, (text, add) in verbs().items():
        if full is None or name in full:
            add(sub, parents, text)
        else:
            sub.add_parser(name, help=text, add_help=False)
    return parser


def _find_verb(argv: list[str]) -> str | None:
    """The verb of a command line (the first word that is not an option or its value)."""
    skip = False
    for tok in argv:
        if skip:
            skip = False
            continue
        if tok == "--threads":
            skip = True
            continue
        if tok.startswith("-"):
            continue
        return tok
    return None


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:  # name the path, once
        from .guard import shown

        extra = f" -> {shown(exc.filename2)}" if exc.filename2 is not None else ""
        return f"{shown(exc.filename)}{extra}: {exc.strerror}"
    return " ".join(str(exc).split()) or type(exc).__name__


def main(argv=None) -> int:
    """Run one command line (``argv`` without the program name); returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    verb = _find_verb(argv)
    parser = build_parser(full={verb} if verb else set())
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        print(f"{exc.prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # --help and --version
        return exc.code if isinstance(exc.code, int) else 0
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    from ..radar import DataFileError
    from ..radar.progress import QUIET_ENV, set_quiet
    from .common import apply_threads

    import os

    quiet_before = os.environ.get(QUIET_ENV)
    set_quiet(args.quiet or (quiet_before or "").strip().lower() in ("1", "true", "yes", "on"))
    from ..radar.workers import terminate_as_interrupt, was_terminated

    prog = f"mdaug {args.verb}"
    try:
        with terminate_as_interrupt():  # SIGTERM ends the command like Ctrl-C: its workers stopped, one line
            apply_threads(args.threads)
            return int(args.func(args) or 0)
    except UsageError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
    except (ValueError, DataFileError, OSError, MemoryError) as exc:  # not KeyError: that is a bug, with its traceback
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (Terminated, perhaps wrapped by a sampler)
        if was_terminated(exc):
            print(f"{prog}: terminated; {args.interrupted(args)}", file=sys.stderr)
            return EXIT_TERMINATED
        print(f"{prog}: interrupted; {args.interrupted(args)}", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        if quiet_before is None:
            os.environ.pop(QUIET_ENV, None)
        else:
            os.environ[QUIET_ENV] = quiet_before
    return EXIT_BAD_INPUT
