"""``python -m mrstereo`` runs the command-line interface.

Conventions: docs/conventions.md.
"""
import sys

from .cli import entry

sys.exit(entry())
