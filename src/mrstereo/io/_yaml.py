"""Python data from a stream of YAML parser events, every value counted (aliases expanded).

What ``yaml.safe_load`` returns, without its node graph: the composer keeps every node of the file as a
Python object (about 9 KB per manifest frame) before the constructor walks it. Here each value is made
when its event arrives, anchors remember their value and their expanded size, and an alias adds that size
to the count, so a "billion laughs" file is refused after a bounded amount of work.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import yaml
from yaml.events import (AliasEvent, DocumentStartEvent, MappingEndEvent, MappingStartEvent, ScalarEvent,
                         SequenceEndEvent, SequenceStartEvent)
from yaml.nodes import ScalarNode

__all__ = ["build", "YamlLimit"]

_MAP, _SEQ, _STR = "tag:yaml.org,2002:map", "tag:yaml.org,2002:seq", "tag:yaml.org,2002:str"
_MERGE = "tag:yaml.org,2002:merge"
_RESOLVER = yaml.resolver.Resolver()
_CONSTRUCTOR = yaml.constructor.SafeConstructor()
_SCALARS = {tag: make for tag, make in yaml.constructor.SafeConstructor.yaml_constructors.items()
            if tag is not None and tag not in (_MAP, _SEQ, "tag:yaml.org,2002:set", "tag:yaml.org,2002:omap",
                                               "tag:yaml.org,2002:pairs")}


class YamlLimit(Exception):
    """More values than allowed (the message says how many were reached)."""


def _error(message: str, event) -> yaml.YAMLError:
    return yaml.constructor.ConstructorError(None, None, message, event.start_mark)


_CACHE: dict = {}
_CACHE_SIZE = 4096


def _scalar(event):
    """``(value, tag)`` of a scalar event; plain scalars seen before (a manifest's keys, repeated values) come
    from a small cache of these immutable values instead of the resolver and the constructor."""
    if event.tag is None:
        key = (event.value, event.implicit, event.style)
        found = _CACHE.get(key)
        if found is None:
            if len(_CACHE) >= _CACHE_SIZE:
                _CACHE.clear()
            found = _CACHE[key] = _resolved(event)
        return found
    return _resolved(event)


def _resolved(event):
    tag = event.tag
    if tag is None or tag == "!":
        tag = _RESOLVER.resolve(ScalarNode, event.value, event.implicit)
    if tag == _STR or tag == _MERGE:
        return event.value, tag
    make = _SCALARS.get(tag)
    if make is None:
        raise _error(f"the tag {tag} is not supported", event)
    return make(_CONSTRUCTOR, ScalarNode(tag, event.value, style=event.style)), tag


class _Collection:
    __slots__ = ("value", "key", "has_key", "merges", "start", "anchor", "key_is_merge")

    def __init__(self, value, start: int, anchor) -> None:
        self.value, self.start, self.anchor = value, start, anchor
        self.key, self.has_key, self.key_is_merge, self.merges = None, False, False, []


def build(events, *, max_nodes: int, tags: frozenset = frozenset()):
    """The single document of ``events`` as dicts, lists and scalars (None for an empty stream).

    Raises :class:`YamlLimit` beyond ``max_nodes`` values, ``yaml.YAMLError`` for invalid YAML, an
    unsupported tag, an unhashable key, an unknown alias or a second document.
    """
    stack: list[_Collection] = []
    anchors: dict[str, tuple[object, int]] = {}
    count, documents, root = 0, 0, None
    for event in events:
        kind = type(event)
        if kind is ScalarEvent:
            count += 1
            value, tag = _scalar(event)
            if event.anchor:
                anchors[event.anchor] = (value, 1)
            is_merge = tag == _MERGE
        elif kind is AliasEvent:
            if event.anchor not in anchors:
                raise _error(f"found undefined alias {event.anchor!r}", event)
            value, size = anchors[event.anchor]
            count += size
            is_merge = False
        elif kind is MappingStartEvent or kind is SequenceStartEvent:
            tag = event.tag
            if tag not in (None, "!", _MAP if kind is MappingStartEvent else _SEQ) and tag not in tags:
                raise _error(f"the tag {tag} is not supported", event)
            count += 1
            stack.append(_Collection({} if kind is MappingStartEvent else [], count, event.anchor))
            if count > max_nodes:
                raise YamlLimit(f"more than {max_nodes:,} values (aliases expanded)")
            continue
        elif kind is MappingEndEvent or kind is SequenceEndEvent:
            done = stack.pop()
            value = done.value
            if done.merges:
                merged = {}
                for extra in reversed(done.merges):
                    merged.update(extra)
                merged.update(value)
                value = merged
            if done.anchor:
                anchors[done.anchor] = (value, count - done.start + 1)
            is_merge = False
        elif kind is DocumentStartEvent:
            documents += 1
            if documents > 1:
                raise _error("expected a single document, found another one", event)
            continue
        else:
            continue
        if count > max_nodes:
            raise YamlLimit(f"more than {max_nodes:,} values (aliases expanded)")
        if not stack:
            root = value
            continue
        top = stack[-1]
        if type(top.value) is list:
            top.value.append(value)
        elif not top.has_key:
            if isinstance(value, (dict, list)):
                raise _error("found an unhashable key (a mapping or list)", event)
            top.key, top.has_key, top.key_is_merge = value, True, is_merge
        else:
            if top.key_is_merge:
                extras = value if isinstance(value, list) else [value]
                if not all(isinstance(extra, dict) for extra in extras):
                    raise _error("a merge key '<<' needs a mapping or a list of mappings", event)
                top.merges.extend(extras)
            else:
                top.value[top.key] = value
            top.has_key = False
    return root
