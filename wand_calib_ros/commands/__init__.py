"""The subcommands of ``wand-calib``, one module each: its help line (``HELP``), its arguments
(``add_arguments``) and what it does (``run``, the exit code). :mod:`wand_calib_ros.cli` builds the parser
from them."""
