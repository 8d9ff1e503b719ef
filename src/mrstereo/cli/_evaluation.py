"""CLI commands (filled by the stage that owns them)."""
COMMANDS: list = []
