"""YAML reading that remembers line numbers, and a small typed field reader.

Every user-facing loader (catalogue, scenario) goes through :class:`Fields`, so that every
error names the file, the line, the key path and what was expected.
"""

from __future__ import annotations

import difflib
import math
import os
import re
import stat
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal, TypeVar, overload

import yaml

from .exceptions import InputError, InputWarning, shorten

_MISSING = object()
#: A getter's ``default``: returned as given when the key is absent, so it is part of the result's type.
_D = TypeVar("_D")
_S = TypeVar("_S", bound=str)
#: The largest magnitude a number may have (SI units): beyond it, products overflow.
MAX_MAGNITUDE = 1e9
#: The largest file read as a scenario or catalogue [bytes].
MAX_FILE_BYTES = 10_000_000


class _Map(dict):
    """A mapping that knows the line of each of its keys (1-based)."""

    line: int = 0
    key_lines: dict[str, int]


class _Seq(list):
    line: int = 0
    item_lines: list[int]


class _LongNumber:
    """A number written with more than :data:`MAX_DIGITS` digits: more than any value of a
    scenario or catalogue may have (and Python converts at most 4300), kept as its text so that
    the key that holds it reports it."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return self.text


class _NodeKey:
    """A list or mapping used as a key (allowed by YAML, unhashable in Python): kept as what it
    was, so that the mapping reports it as a key that is not a name."""

    def __init__(self, kind: str):
        self.kind = kind

    def __repr__(self) -> str:
        return self.kind


#: The most digits of an integer literal read as a number (see :class:`_LongNumber`).
MAX_DIGITS = 100

#: YAML 1.2's core schema, which the docs promise, instead of PyYAML's YAML 1.1: ``010`` is ten
#: (not octal eight), ``1e6`` a number; ``1:30`` (base 60), ``1_0``, ``on``, ``yes`` and
#: ``2024-01-01`` are strings. Per tag: the pattern and the characters a match may start with.
_CORE_SCHEMA = (
    ("tag:yaml.org,2002:bool", r"true|True|TRUE|false|False|FALSE", "tTfF"),
    ("tag:yaml.org,2002:int", r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+", "-+0123456789"),
    (
        "tag:yaml.org,2002:float",
        r"[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN)",
        "-+0123456789.",
    ),
    ("tag:yaml.org,2002:null", r"~|null|Null|NULL|", ["~", "n", "N", ""]),
    ("tag:yaml.org,2002:merge", r"<<", "<"),
)
_INTEGER = re.compile(_CORE_SCHEMA[1][1])


class _LineLoader(yaml.SafeLoader):
    yaml_implicit_resolvers: dict = {}  # noqa: RUF012 (PyYAML's class-level table, filled below)


for _tag, _pattern, _first in _CORE_SCHEMA:
    _LineLoader.add_implicit_resolver(_tag, re.compile(f"^(?:{_pattern})$"), list(_first))


def _construct_int(loader: _LineLoader, node: yaml.ScalarNode) -> int | _LongNumber:
    """A YAML 1.2 integer: decimal (leading zeros and all), ``0o`` octal or ``0x`` hexadecimal."""
    text = loader.construct_scalar(node)
    if not _INTEGER.fullmatch(text):  # an explicit ``!!int`` on other text
        raise yaml.constructor.ConstructorError(
            None, None, f"expected an integer, got {shorten(text)}", node.start_mark
        )
    if len(text) > MAX_DIGITS:
        return _LongNumber(text)
    base = {"0o": 8, "0x": 16}.get(text[:2], 10)
    return int(text[2:] if base != 10 else text, base)


def _construct_float(loader: _LineLoader, node: yaml.ScalarNode) -> float:
    """A YAML 1.2 float, ``.inf`` and ``.nan`` included (no base 60, no underscores)."""
    text = loader.construct_scalar(node)
    special = {".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, ".nan": math.nan}.get(text.lower())
    if special is not None:
        return special
    if "_" in text:  # Python's float() would read 1_0 as 10
        raise yaml.constructor.ConstructorError(None, None, f"expected a number, got {shorten(text)}", node.start_mark)
    try:
        return float(text)
    except ValueError:
        raise yaml.constructor.ConstructorError(
            None, None, f"expected a number, got {shorten(text)}", node.start_mark
        ) from None


def _construct_map(loader: _LineLoader, node: yaml.MappingNode) -> _Map:
    out = _Map()
    out.line = node.start_mark.line + 1
    out.key_lines = {}
    own = sum(1 for key_node, _ in node.value if key_node.tag != "tag:yaml.org,2002:merge")
    loader.flatten_mapping(node)  # merged pairs first, then the mapping's own: own keys override
    merged = len(node.value) - own
    for index, (key_node, value_node) in enumerate(node.value):
        if isinstance(key_node, yaml.ScalarNode):
            key = loader.construct_object(key_node, deep=True)
        else:
            key = _NodeKey("a list" if isinstance(key_node, yaml.SequenceNode) else "a mapping")
        if index >= merged and key in out and out.key_lines[key] > 0:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {shorten(key)}", key_node.start_mark)
        out[key] = loader.construct_object(value_node, deep=True)
        out.key_lines[key] = key_node.start_mark.line + 1 if index >= merged else -(key_node.start_mark.line + 1)
    out.key_lines = {k: abs(v) for k, v in out.key_lines.items()}
    return out


def _construct_seq(loader: _LineLoader, node: yaml.SequenceNode) -> _Seq:
    out = _Seq(loader.construct_object(child, deep=True) for child in node.value)
    out.line = node.start_mark.line + 1
    out.item_lines = [child.start_mark.line + 1 for child in node.value]
    return out


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_map)
_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_seq)
_LineLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_LineLoader.add_constructor("tag:yaml.org,2002:float", _construct_float)


def load_yaml(path: Path, error: type[InputError]) -> Fields:
    """Parse a YAML file whose top level is a mapping; return its :class:`Fields`."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block, /dev/zero never ends
            raise error(f"{path}: expected a regular file (a scenario or catalogue), got a device, pipe or folder")
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read file: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise error(f"{path}: the file has more than {MAX_FILE_BYTES} bytes; a scenario or catalogue is smaller")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(
            f"{path}:{line}: expected UTF-8 text, got the byte 0x{data[exc.start]:02x} (is it a YAML file?)"
        ) from None
    try:
        data = yaml.load(text, Loader=_LineLoader)
    except RecursionError:
        raise error(f"{path}: the YAML is nested too deeply to be a scenario or catalogue") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        problem = getattr(exc, "problem", None) or str(exc)
        if problem == "but found another document":
            raise error(f"{where}: expected one YAML document, found a second one here (after '---')") from None
        raise error(f"{where}: malformed YAML: {shorten(problem, 200, quote=False)}") from None
    if not isinstance(data, _Map):
        raise error(f"{path}:1: expected a mapping at the top level, got {_kind(data)}")
    return Fields(data, path, "", error)


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, _LongNumber):
        return f"a number of {len(value.text)} characters"
    if isinstance(value, _NodeKey):
        return value.kind
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, (int, float)):
        return f"the number {value}"
    if isinstance(value, str):
        return f"the string {shorten(value)}"
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


class Fields:
    """Typed access to one YAML mapping; records which keys were read.

    Call :meth:`done` after reading, so that unknown (e.g. misspelt) keys are errors.
    """

    def __init__(self, data: _Map, path: Path, prefix: str, error: type[InputError]):
        self._data = data
        self.path = Path(path)
        self._prefix = prefix
        self._error = error
        self._read: set[str] = set()
        #: Keys asked about with :meth:`has` (optional keys: named in an unknown key's hint).
        self._asked: set[str] = set()

    def reporting(self, error: type[InputError]) -> Fields:
        """The same mapping, reporting its errors as ``error`` (once the file's kind is known)."""
        return Fields(self._data, self.path, self._prefix, error)

    # -- error reporting -------------------------------------------------------------------
    def key_path(self, key: str | int | None = None) -> str:
        if key is None:
            return self._prefix or "(top level)"
        if isinstance(key, int):
            return f"{self._prefix}[{key}]"
        name = shorten(key, quote=False)
        return f"{self._prefix}.{name}" if self._prefix else name

    def line_of(self, key: str | None = None) -> int:
        if key is not None and key in self._data.key_lines:
            return self._data.key_lines[key]
        return self._data.line

    def warn(self, key: str | None, message: str) -> None:
        """Warn (:class:`~modular_robots.exceptions.InputWarning`) that ``key``'s value looks wrong:
        ``file:line: key.path: message``."""
        warnings.warn(InputWarning(f"{self.path}:{self.line_of(key)}: {self.key_path(key)}: {message}"), stacklevel=3)

    def fail(self, key: str | None, message: str) -> InputError:
        """Build (not raise) the error for ``key``: ``file:line: key.path: message``."""
        return self._error(f"{self.path}:{self.line_of(key)}: {self.key_path(key)}: {message}")

    # -- typed getters ---------------------------------------------------------------------
    def has(self, key: str) -> bool:
        self._asked.add(key)
        return key in self._data

    def names(self) -> list[str]:
        """The mapping's keys, as written."""
        return [str(key) for key in self._data]

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        self._read.add(key)
        if key not in self._data:
            if default is _MISSING:
                raise self._error(
                    f"{self.path}:{self._data.line}: {self.key_path(key)}: missing required key{self._near(key)}"
                )
            return default
        return self._data[key]

    # With ``choices``, the string is one of them (e.g. a ``Literal`` type's values).
    @overload
    def string(self, key: str) -> str: ...
    @overload
    def string(self, key: str, *, choices: tuple[_S, ...]) -> _S: ...
    @overload
    def string(self, key: str, default: _D) -> str | _D: ...
    @overload
    def string(self, key: str, default: _D, choices: tuple[_S, ...]) -> _S | _D: ...
    def string(self, key: str, default: Any = _MISSING, choices: tuple[str, ...] = ()) -> Any:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"expected a non-empty string, got {_kind(value)}")
        if choices and value not in choices:
            raise self.fail(key, f"expected one of {', '.join(choices)}; got {shorten(value)}")
        return value

    @overload
    def number(
        self,
        key: str,
        *,
        minimum: float | None = None,
        exclusive_minimum: float | None = None,
        maximum: float | None = None,
        why: str = "",
    ) -> float: ...
    @overload
    def number(
        self,
        key: str,
        default: _D,
        *,
        minimum: float | None = None,
        exclusive_minimum: float | None = None,
        maximum: float | None = None,
        why: str = "",
    ) -> float | _D: ...
    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        minimum: float | None = None,
        exclusive_minimum: float | None = None,
        maximum: float | None = None,
        why: str = "",
    ) -> Any:
        """A number in the bounds given; ``why`` says why the maximum (in the error)."""
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        value = self._check_number(key, value, minimum, exclusive_minimum)
        if maximum is not None and value > maximum:
            raise self.fail(key, f"expected a number <= {maximum:g}{why and f' ({why})'}, got {value:g}")
        return value

    @overload
    def integer(self, key: str, *, minimum: int | None = None, maximum: int | None = None, why: str = "") -> int: ...
    @overload
    def integer(
        self, key: str, default: _D, *, minimum: int | None = None, maximum: int | None = None, why: str = ""
    ) -> int | _D: ...
    def integer(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
        why: str = "",
    ) -> Any:
        """An integer in ``[minimum, maximum]``; ``why`` says why the maximum (in the error)."""
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if isinstance(value, _LongNumber):
            bound = maximum if maximum is not None else f"{MAX_MAGNITUDE:g}"
            raise self.fail(key, f"expected an integer <= {bound}{why and f' ({why})'}, got {_long(value)}")
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected an integer, got {_kind(value)}")
        if minimum is not None and value < minimum:
            raise self.fail(key, f"expected an integer >= {minimum}, got {shorten(value)}")
        if maximum is not None and value > maximum:
            raise self.fail(key, f"expected an integer <= {maximum}{why and f' ({why})'}, got {shorten(value)}")
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, f"expected true or false, got {_kind(value)}")
        return value

    # The sizes read (2, 3, 6) give tuples of that length, which the dataclasses' fields expect.
    @overload
    def vector(self, key: str, size: Literal[2], default: tuple[float, float] = ...) -> tuple[float, float]: ...
    @overload
    def vector(
        self, key: str, size: Literal[3], default: tuple[float, float, float] = ...
    ) -> tuple[float, float, float]: ...
    @overload
    def vector(
        self, key: str, size: Literal[6], default: tuple[float, float, float, float, float, float] = ...
    ) -> tuple[float, float, float, float, float, float]: ...
    @overload
    def vector(self, key: str, size: int, default: tuple[float, ...] = ...) -> tuple[float, ...]: ...
    def vector(self, key: str, size: int, default: Any = _MISSING) -> tuple[float, ...]:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if not isinstance(value, list) or len(value) != size:
            got = f"{len(value)}" if isinstance(value, list) else _kind(value)
            raise self.fail(key, f"expected {size} numbers, got {got}")
        return tuple(self._check_number(key, v, None, None, f"item {i}: ") for i, v in enumerate(value))

    def rpy(self, key: str = "rpy", default: Any = _MISSING) -> tuple[float, float, float]:
        """Roll, pitch and yaw [rad]: three numbers, none more than a turn either way (a larger
        one is degrees in all likelihood, and says so)."""
        angles = self.vector(key, 3, default)
        if any(abs(a) > 2.0 * math.pi for a in angles):
            radians = ", ".join(f"{math.radians(a):.4g}" for a in angles)
            raise self.fail(
                key,
                f"{[float(a) for a in angles]} rad is more than a turn: degrees? Expected radians ([{radians}] rad "
                "if they are degrees)",
            )
        return angles

    def interval(self, key: str, default: Any = _MISSING) -> tuple[float, float]:
        """A ``[low, high]`` pair with low <= high."""
        low, high = self.vector(key, 2, default)
        if low > high:
            raise self.fail(key, f"expected [low, high] with low <= high, got [{low:g}, {high:g}]")
        return low, high

    @overload
    def mapping(self, key: str) -> Fields: ...
    @overload
    def mapping(self, key: str, default: _D) -> Fields | _D: ...
    def mapping(self, key: str, default: Any = _MISSING) -> Any:
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return value
        if not isinstance(value, _Map):
            raise self.fail(key, f"expected a mapping, got {_kind(value)}")
        return Fields(value, self.path, self.key_path(key), self._error)

    def mappings(self, key: str, default: Any = _MISSING) -> Iterator[Fields]:
        """Each item of a list of mappings, as :class:`Fields` named ``key[i]``."""
        value = self.raw(key, default)
        if value is default and default is not _MISSING:
            return
        if not isinstance(value, _Seq):
            raise self.fail(key, f"expected a list, got {_kind(value)}")
        for i, item in enumerate(value):
            if not isinstance(item, _Map):
                raise self._error(
                    f"{self.path}:{value.item_lines[i]}: {self.key_path(key)}[{i}]: "
                    f"expected a mapping, got {_kind(item)}"
                )
            yield Fields(item, self.path, f"{self.key_path(key)}[{i}]", self._error)

    def _near(self, key: str) -> str:
        """For a missing ``key``: the written key that looks like it (a misspelling), if any."""
        written = [str(k) for k in self._data if isinstance(k, str) and k not in self._read]
        close = difflib.get_close_matches(key, written, n=1, cutoff=0.6)
        if not close:
            return ""
        line = self._data.key_lines.get(close[0], self._data.line)
        return f" (line {line} has {shorten(close[0])}: a misspelling of {key}?)"

    def done(self) -> None:
        """Raise for the first key that no getter read (an unknown or misspelt key, or a key that
        is not a name: a number, a boolean, nothing, a list or a mapping)."""
        for key in self._data:
            if not isinstance(key, str):
                line = self._data.key_lines.get(key, self._data.line)
                raise self._error(
                    f"{self.path}:{line}: {self.key_path()}: expected keys that are names, got {_kind(key)} as a key"
                )
            if key not in self._read:
                expected = ", ".join(sorted(str(k) for k in self._read | self._asked))
                raise self.fail(key, f"unknown key (expected one of: {expected})")

    def check(self, key: str, ok: bool, message: str) -> None:
        if not ok:
            raise self.fail(key, message)

    def _check_number(self, key, value, minimum, exclusive_minimum, what: str = "") -> float:
        if isinstance(value, _LongNumber):
            raise self.fail(key, f"{what}expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {_long(value)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"{what}expected a number, got {_kind(value)}")
        if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:  # before float(), which may overflow
            raise self.fail(
                key, f"{what}expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {shorten(value)}"
            )
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(key, f"{what}expected a finite number, got {value}")
        if abs(value) > MAX_MAGNITUDE:
            raise self.fail(key, f"{what}expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {value:g}")
        if minimum is not None and value < minimum:
            raise self.fail(key, f"{what}expected a number >= {minimum:g}, got {value:g}")
        if exclusive_minimum is not None and value <= exclusive_minimum:
            raise self.fail(key, f"{what}expected a number > {exclusive_minimum:g}, got {value:g}")
        return value


def _long(value: _LongNumber) -> str:
    """A too long number as a message shows it: cut, with its length."""
    return shorten(value.text, quote=False)
