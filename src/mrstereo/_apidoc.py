"""docs/api.md from the docstrings of the public objects (:data:`mrstereo.__all__`).

``python -m mrstereo._apidoc > docs/api.md`` regenerates it; tests/test_mapper.py checks it is up to date.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import importlib
import inspect

import mrstereo

_HEADER = """# API reference

The public objects of `import mrstereo` (`dir(mrstereo)`), each with its signature and the summary of its
docstring; the full docstrings (parameters, examples) are in the source and in `help()` of each object. Generated
from the docstrings by `python -m mrstereo._apidoc > docs/api.md` (tests/test_mapper.py checks it is up to date).
"""


def _summary(doc: str | None) -> str:
    """The docstring's first paragraph, on one line."""
    text = inspect.cleandoc(doc or "")
    return " ".join(text.split("\n\n")[0].split()) if text else "(no docstring)"


def _examples(doc: str | None) -> str | None:
    """The docstring's numpydoc ``Examples`` section, as a Python block."""
    text = inspect.cleandoc(doc or "")
    marker = "Examples\n--------\n"
    if marker not in text:
        return None
    body = text.split(marker, 1)[1].split("\n\n\n")[0].rstrip()
    return "```python\n" + body + "\n```"


def _signature(obj) -> str:
    try:
        return str(inspect.signature(obj))
    except (TypeError, ValueError):
        return ""


def api_markdown() -> str:
    """The text of docs/api.md."""
    parts = [_HEADER]
    by_module: dict[str, list[str]] = {}
    for name in mrstereo.__all__:
        by_module.setdefault(mrstereo._LAZY[name], []).append(name)
    for module in sorted(by_module):
        parts.append(f"## `{module}`\n")
        mod = importlib.import_module(module)
        for name in sorted(by_module[module]):
            obj = getattr(mod, name)
            kind = "class" if inspect.isclass(obj) else "function"
            parts.append(f"### `mrstereo.{name}{_signature(obj)}`\n\n{kind}. {_summary(obj.__doc__)}\n")
            examples = _examples(obj.__doc__)
            if examples:
                parts.append(examples + "\n")
    return "\n".join(parts)


if __name__ == "__main__":
    print(api_markdown(), end="")
