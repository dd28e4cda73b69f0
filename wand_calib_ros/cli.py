"""The offline command ``wand-calib``: simulate rigs and calibrate recorded observations.

Each subcommand is a module of :mod:`wand_calib_ros.commands`. Errors a user can cause end the command
with exit code 2 and one line on stderr naming the problem; progress goes to stderr, results to files.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Sequence
from types import ModuleType

from wand_calib_ros.commands import (
    calibrate,
    detect,
    export,
    imports,
    mask,
    refine,
    render,
    report,
    simulate,
    sweep,
)
from wand_calib_ros.errors import WandCalibError

#: The subcommands in the order ``--help`` lists them.
COMMANDS: dict[str, ModuleType] = {
    "calibrate": calibrate,
    "render": render,
    "detect": detect,
    "mask": mask,
    "report": report,
    "export": export,
    "refine": refine,
    "import": imports,
    "sweep": sweep,
    "simulate": simulate,
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wand-calib", description="Wand calibration of fisheye, conventional and mixed camera rigs."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug output on stderr")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors on stderr")
    commands = parser.add_subparsers(dest="command", required=True)
    for name, module in COMMANDS.items():
        module.add_arguments(commands.add_parser(name, help=module.HELP))
    return parser


def check_numbers(args: argparse.Namespace) -> None:
    """Every number option finite (argparse's float takes 'nan' and 'inf').

    Raises:
        WandCalibError: naming the option.
    """
    for name, value in vars(args).items():
        for number in value if isinstance(value, list) else [value]:
            if isinstance(number, float) and not math.isfinite(number):
                raise WandCalibError(f"--{name.replace('_', '-')} must be a finite number, got {number}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``wand-calib``."""
    args = _parser().parse_args(argv)
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    logging.basicConfig(level=level, format="wand-calib: %(message)s", stream=sys.stderr)
    try:
        check_numbers(args)
        code: int = COMMANDS[args.command].run(args)
        return code
    except WandCalibError as error:
        print(f"wand-calib: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        if error.filename:
            print(f"wand-calib: error: {error.filename}: {error.strerror or error}", file=sys.stderr)
        else:  # (a library's write: the command's output is what failed)
            target = getattr(args, "output", None) or getattr(args, "out", None) or "an output"
            print(f"wand-calib: error: cannot write {target}: {error.strerror or error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
