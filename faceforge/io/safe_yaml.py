"""YAML read from users, with limits: YAML 1.2 numbers, no bombs, one-line errors.

Every YAML file or value a user gives (config files, ``--set`` values, landmark files,
``faceforge.yaml``) goes through :func:`load_user_yaml` (or :func:`check_structure` before
a loader of its own), which

* reads numbers the YAML 1.2 way: ``5e-2`` and ``1E3`` are floats (PyYAML's YAML 1.1
  resolver wants a dot, ``5.0e-2``, and read ``5e-2`` as the string ``"5e-2"``);
* refuses, before anything is built, a document nested deeper than :data:`MAX_DEPTH`,
  one whose aliases would expand to more than :data:`MAX_NODES` nodes (an "alias bomb":
  nine levels of ten aliases are a billion strings, and printing one in an error message
  took 20 s and 312 MB) and a file over :data:`MAX_BYTES`;
* turns whatever the parser or constructor raises (``yaml.YAMLError``, ``ValueError`` for
  an integer of more than 4,300 digits, ``OverflowError``, ``RecursionError``,
  ``TypeError`` for an unhashable key) into the caller's
  :class:`~faceforge.exceptions.FaceforgeError` subclass naming the source and line.

Templates shipped with faceforge keep the plain fast loader
(:func:`faceforge.io.stagefiles.yaml_safe_load`).
"""

from __future__ import annotations

import re
from typing import Any

import yaml

from faceforge.exceptions import ConfigError, FaceforgeError

#: deepest nesting of mappings and sequences accepted
MAX_DEPTH = 64
#: most nodes a document may have once its aliases are expanded
MAX_NODES = 1_000_000
#: largest file accepted (characters)
MAX_BYTES = 16 * 1024 * 1024
#: longest integer literal accepted (digits); longer ones are not numbers a user means
MAX_INT_DIGITS = 100

_BASE = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

#: YAML 1.2 core schema floats that YAML 1.1 reads as strings (exponent without a dot)
_FLOAT_12 = re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


def add_yaml12_floats(loader_cls) -> None:
    """Make ``loader_cls`` (a PyYAML loader class) read ``5e-2``/``1E3`` as floats."""
    loader_cls.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789"))


class UserLoader(_BASE):
    """The safe loader (libyaml's parser where PyYAML has it) with YAML 1.2 floats."""


add_yaml12_floats(UserLoader)


def _line(exc) -> int | None:
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    return None if mark is None else mark.line + 1


def check_structure(text: str, source: str, error=ConfigError) -> None:
    """Raise ``error(message, source, line)`` when ``text`` is too big, holds a number of more
    than :data:`MAX_INT_DIGITS` digits, is nested deeper than :data:`MAX_DEPTH` or expands (aliases followed) to more than :data:`MAX_NODES` nodes.
    Walks the parser's events only: nothing is built, so a bomb is refused in milliseconds.
    Syntax errors are raised as ``error`` too."""
    if len(text) > MAX_BYTES:
        raise error(f"YAML file too large ({len(text)} characters, at most {MAX_BYTES})", source)
    _check_ints(text, source, error)
    sizes: dict[str, int] = {}      # anchor -> expanded node count of its node
    stack: list[list] = []          # open collections: [anchor, count so far]
    total = 0
    loader = _BASE(text)
    try:
        while True:
            event = loader.get_event()
            if event is None or isinstance(event, yaml.StreamEndEvent):
                break
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                stack.append([event.anchor, 1])
                if len(stack) > MAX_DEPTH:
                    raise error(f"YAML nested deeper than {MAX_DEPTH} levels", source,
                                event.start_mark.line + 1)
                continue
            if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                anchor, count = stack.pop()
            elif isinstance(event, yaml.ScalarEvent):
                anchor, count = event.anchor, 1
            elif isinstance(event, yaml.AliasEvent):
                anchor, count = None, sizes.get(event.anchor, 1)
            else:
                continue
            if anchor is not None:
                sizes[anchor] = count
            if stack:
                stack[-1][1] += count
            else:
                total += count
            if total + sum(c for _, c in stack) > MAX_NODES:
                raise error(f"YAML aliases expand to more than {MAX_NODES:,} nodes (an alias bomb?)",
                            source, event.start_mark.line + 1)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"not valid YAML: {problem}", source, _line(exc)) from None
    finally:
        loader.dispose()


def _check_ints(text: str, source: str, error) -> None:
    m = re.search(r"(?<![\w.])[-+]?[0-9][0-9_]{%d,}" % MAX_INT_DIGITS, text)
    if m is not None:
        raise error(f"number with more than {MAX_INT_DIGITS} digits", source, text.count("\n", 0, m.start()) + 1)


def construct_guarded(make, source: str, error=ConfigError, what: str = "YAML") -> Any:
    """``make()`` (a YAML construction, or a JSON one: ``what``), its exceptions turned into
    ``error(message, source[, line])``."""
    try:
        return make()
    except FaceforgeError:
        raise
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"not valid YAML: {problem}", source, _line(exc)) from None
    except RecursionError:
        raise error(f"{what} nested too deeply", source) from None
    except (ValueError, OverflowError, TypeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise error(f"cannot read {what}: {first[:200]}", source) from None


def load_user_yaml(text: str, source: str, error=ConfigError, loader=UserLoader) -> Any:
    """``text`` parsed by ``loader`` after :func:`check_structure`; every failure is ``error``."""
    check_structure(text, source, error)
    return construct_guarded(lambda: yaml.load(text, Loader=loader), source, error)
