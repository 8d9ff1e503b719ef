"""``python -m mrstereo`` runs the command-line interface."""
import sys

from .cli import entry

sys.exit(entry())
