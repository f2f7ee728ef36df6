"""The ``mdaug`` command: one verb per job.

Each layer registers its own verbs (``<layer>/commands.py``); heavy libraries load
only inside the verb that needs them, so ``mdaug --help`` is fast.
"""
from __future__ import annotations

import argparse
import os
import sys

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def default_threads() -> int:
    return int(os.environ.get("MDAUG_THREADS", "1"))


def apply_threads(n: int) -> None:
    """Pin BLAS, OpenMP and torch to ``n`` threads (scipy.fft uses 1 worker unless asked).

    The default is 1: on these shared 2-core machines a 2-thread run collapses when
    the second core is busy; ask for 2 with ``--threads 2`` or MDAUG_THREADS=2.
    """
    if n < 1:
        raise ValueError(f"--threads must be >= 1, got {n}")
    for var in THREAD_VARS:
        os.environ[var] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)
    os.environ["MDAUG_THREADS"] = str(n)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    from .classify import commands as classify_commands
    from .generator import commands as generator_commands
    from .inference import commands as inference_commands
    from .generator import scene_commands
    from .radar import commands as radar_commands
    from .reports import commands as reports_commands

    parser = argparse.ArgumentParser(prog="mdaug", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"mdaug {__version__}")
    parser.add_argument("--threads", type=int, default=default_threads(),
                        help="threads for BLAS / FFT / torch (default $MDAUG_THREADS or 1)")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for module in (generator_commands, inference_commands, radar_commands, scene_commands, reports_commands,
                   classify_commands):
        module.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from .radar import DataFileError

    try:
        apply_threads(args.threads)
        return int(args.func(args) or 0)
    except (ValueError, DataFileError, FileNotFoundError, KeyError) as exc:
        print(f"mdaug {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mdaug {args.verb}: interrupted; completed outputs are kept, rerun to resume", file=sys.stderr)
        return 130
